"""Sweep specifications (``SPEC.toml``) and the trials they expand to.

How this works: a spec names an experiment (``E1``, ``E2`` or a flight script) and parameters:
``[grid]`` values are crossed (every combination), ``[[trials]]`` tables are listed as they are,
and every parameter set runs once per seed. A :class:`Trial` is plain data (JSON-able, so it
travels to a worker process or a Ray node); its ``key`` hashes the experiment, parameters, seed,
quick flag and the code version, so a rerun recognises the results it already has and a code
change runs everything again. Bad specs raise :class:`LocalProtocolError` naming the problem.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import re
import tomllib
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import skeye
from skeye.errors import ConfigError, LocalProtocolError
from skeye.validate.experiments import SETTING_NAMES, RunSettings, check_disturbance, check_setting
from skeye.values import is_finite_number

EXPERIMENTS = ("E1", "E2")
MAX_TRIALS = 100_000
"""The most trials one spec may make (parameter sets x seeds): each is a flight in processes of
its own, seconds to minutes of a core, so more is a mistake (or a sweep to split); checked
before any list is built (seeds = 1e11 used to end in MemoryError)."""
_DEFAULTS = {f.name: f.default for f in dataclasses.fields(RunSettings)}
ROW_FIXED = ("key", "experiment", "seed", "quick")
ROW_TAIL = ("wall_s", "host", "skeye_version", "code_version", "error")
"""The columns every row has besides its parameters and figures (results.csv's first and last)."""
_SPEC_KEYS = {"experiment", "script", "seeds", "quick", "timeout_s", "grid", "trials",
              "resources", "name"}


@cache
def code_version() -> str:
    """skeye's version plus a hash of its Python sources (what a trial's result depends on)."""
    root = Path(skeye.__file__).parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return f"{skeye.__version__}+{h.hexdigest()[:12]}"


@dataclass(frozen=True)
class Trial:
    """One run: an experiment with one parameter set and one seed."""

    experiment: str  # E1, E2 or script
    params: dict[str, Any]
    seed: int
    quick: bool = False
    script: str | None = None  # absolute path of the flight script (experiment "script")
    timeout_s: float = 1800.0
    code: str = field(default_factory=code_version)

    @property
    def key(self) -> str:
        ident = {"experiment": self.experiment, "params": self.params, "seed": self.seed,
                 "quick": self.quick, "script": self.script, "code": self.code}
        if self.script:
            ident["script_sha"] = hashlib.sha256(Path(self.script).read_bytes()).hexdigest()
        blob = json.dumps(ident, sort_keys=True, default=str).encode()
        return hashlib.sha256(blob).hexdigest()[:16]

    def settings(self) -> RunSettings:
        known = {k: v for k, v in self.params.items() if k in SETTING_NAMES}
        return RunSettings(seed=self.seed, quick=self.quick, **known)

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Trial:
        return cls(**data)


@dataclass(frozen=True)
class SweepSpec:
    experiment: str
    trials: list[Trial]
    param_names: list[str]
    cpus: float = 1.0
    gpus: float = 0.0
    name: str = "sweep"


def _seeds(value: Any) -> list[int]:
    if isinstance(value, bool):
        raise LocalProtocolError(f"seeds must be a count or a list of integers, got {value!r}")
    if isinstance(value, int):
        if value < 1:
            raise LocalProtocolError(f"seeds must be >= 1, got {value}")
        if value > MAX_TRIALS:
            raise LocalProtocolError(f"seeds = {value}: a sweep makes at most {MAX_TRIALS} "
                                     "trials")
        return list(range(1, value + 1))
    if isinstance(value, list) and value and all(
            isinstance(s, int) and not isinstance(s, bool) for s in value):
        if len(set(value)) != len(value):
            raise LocalProtocolError(f"seeds repeat: {value}")
        if min(value) < 0:  # skeye sim --seed takes none: every trial would fail
            raise LocalProtocolError(f"seeds must be >= 0, got {min(value)}")
        return list(value)
    raise LocalProtocolError(f"seeds must be a count or a list of integers, got {value!r}")


def _number(name: str, value: Any) -> float:
    """A finite number (TOML integer or float), or LocalProtocolError naming ``name``."""
    if not is_finite_number(value):
        raise LocalProtocolError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def _check_value(name: str, value: Any, where: str) -> None:
    if not isinstance(value, str | int | float | bool):
        raise LocalProtocolError(f"{where}: parameter {name!r} must be a number, string or "
                                 f"boolean, got {value!r}")


def _check_setting(name: str, value: Any, where: str) -> None:
    """A value of a RunSettings field, by the rule the trial applies
    (:func:`skeye.validate.experiments.check_setting`); other names are a script's own."""
    if name not in SETTING_NAMES:
        return
    try:
        check_setting(name, value)
    except ConfigError as exc:
        raise LocalProtocolError(f"{where}: {exc}") from None  # exc names it and its value


def parse_spec(data: dict[str, Any], base_dir: Path, quick: bool | None = None) -> SweepSpec:
    """Expand a spec (already parsed TOML) into trials; ``quick`` overrides the spec's."""
    unknown = set(data) - _SPEC_KEYS
    if unknown:
        raise LocalProtocolError(f"unknown spec keys {sorted(unknown)}; known: "
                                 f"{sorted(_SPEC_KEYS)}")
    if "experiment" not in data:
        raise LocalProtocolError('the spec names no experiment: give experiment = "E1", "E2" '
                                 'or "script"')
    experiment = str(data["experiment"]).upper()
    script: str | None = None
    if experiment == "SCRIPT":
        experiment = "script"
        if "script" not in data:
            raise LocalProtocolError("experiment = \"script\" needs script = \"path/to/file.py\"")
        path = (base_dir / str(data["script"])).resolve()
        if path.is_dir():
            raise LocalProtocolError(f"flight script {path} is a folder, not a Python file "
                                     "(give the .py file with trial(settings, params, workdir))")
        if not path.is_file():
            raise LocalProtocolError(f"flight script {path} does not exist")
        script = str(path)
    elif experiment not in EXPERIMENTS:
        raise LocalProtocolError(f"experiment must be E1, E2 or script, got "
                                 f"{data.get('experiment')!r}")
    seeds = _seeds(data.get("seeds", 1))
    grid = data.get("grid", {})
    listed = data.get("trials", [])
    if not isinstance(grid, dict) or not isinstance(listed, list):
        raise LocalProtocolError("[grid] must be a table and [[trials]] a list of tables")
    for name, values in grid.items():
        if not isinstance(values, list) or not values:
            raise LocalProtocolError(f"[grid] {name} must be a non-empty list of values")
        for v in values:
            _check_value(name, v, "[grid]")
            _check_setting(name, v, "[grid]")
    for i, entry in enumerate(listed):
        if not isinstance(entry, dict):
            raise LocalProtocolError(f"[[trials]] entry {i + 1} must be a table")
        for name, v in entry.items():
            _check_value(name, v, f"[[trials]] entry {i + 1}")
            _check_setting(name, v, f"[[trials]] entry {i + 1}")
    names = sorted(set(grid) | {k for entry in listed for k in entry})
    if "seed" in names:
        raise LocalProtocolError("seeds are set with seeds = N or [..], not as a parameter")
    odd = [n for n in names if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.-]*", n)]
    if odd:  # it names a column and the report's plot_<name>.png: "a/b" ended the sweep, after
        # every trial, in "No such file or directory: plot_a/b.png"; "../x" wrote outside it
        raise LocalProtocolError(f"parameter name(s) {odd}: a parameter's name is letters, "
                                 "digits, _ . or -, starting with a letter or _ (it names a "
                                 "column and the report's plot_<name>.png)")
    taken = [n for n in names if n in ROW_FIXED + ROW_TAIL]
    if taken:  # the row's own value replaced it (a parameter "key" stored every row under its
        # value, so none was found again), or it replaced the row's
        raise LocalProtocolError(f"parameter(s) {taken} name columns every row has already "
                                 f"({', '.join(c for c in ROW_FIXED + ROW_TAIL if c != 'seed')})"
                                 ": rename them")
    if experiment != "script":
        bad = [n for n in names if n not in SETTING_NAMES]
        if bad:
            raise LocalProtocolError(f"{experiment} has no parameter {bad}; it takes "
                                     f"{sorted(SETTING_NAMES)} (a flight script takes any)")
    count = max(1, (math.prod(len(v) for v in grid.values()) if grid else 0) + len(listed))
    if count * len(seeds) > MAX_TRIALS:  # before the grid's product is built
        raise LocalProtocolError(f"{count} parameter set(s) x {len(seeds)} seed(s) make "
                                 f"{count * len(seeds)} trials; a sweep makes at most "
                                 f"{MAX_TRIALS}: split it")
    sets: list[dict[str, Any]] = []
    if grid:
        keys = sorted(grid)
        sets += [dict(zip(keys, combo, strict=True))
                 for combo in itertools.product(*(grid[k] for k in keys))]
    sets += [dict(entry) for entry in listed]
    if not sets:
        sets = [{}]
    seen: set[str] = set()
    for params in sets:  # the same set twice is the same trials (one key) run twice
        ident = json.dumps(params, sort_keys=True, default=str)
        if ident in seen:
            raise LocalProtocolError(f"parameter set {params} repeats (a value given twice in a "
                                     "[grid] list, or a [[trials]] entry the grid makes "
                                     "already): each of its trials would run twice")
        seen.add(ident)
    if not isinstance(data.get("quick", False), bool):
        raise LocalProtocolError(f"quick must be true or false, got {data['quick']!r}")
    is_quick = bool(data.get("quick", False)) if quick is None else quick
    timeout_s = _number("timeout_s", data.get("timeout_s", 900.0 if is_quick else 3600.0))
    if not timeout_s > 0:
        raise LocalProtocolError(f"timeout_s must be > 0, got {timeout_s}")
    resources = data.get("resources", {})
    if not isinstance(resources, dict) or set(resources) - {"cpus", "gpus"}:
        raise LocalProtocolError("[resources] takes cpus and gpus")
    for key, value in resources.items():
        if _number(f"[resources] {key}", value) < 0:
            raise LocalProtocolError(f"[resources] {key} must be >= 0, got {value!r}")
    trials = [Trial(experiment, params, seed, is_quick, script, timeout_s)
              for params in sets for seed in seeds]
    for params in sets:  # each set's disturbance as a whole (each value is checked above)
        given = {**_DEFAULTS, **params}
        try:
            check_disturbance(given["wind"], given["wind_params"], given["f_max_n"])
        except ConfigError as exc:
            raise LocalProtocolError(f"parameter set {params}: {exc}") from None
    return SweepSpec(experiment, trials, names, float(resources.get("cpus", 1.0)),
                     float(resources.get("gpus", 0.0)), str(data.get("name", "sweep")))


def load_spec(path: Path, quick: bool | None = None) -> SweepSpec:
    """Read and expand ``SPEC.toml``."""
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise LocalProtocolError(f"sweep spec {path} does not exist") from None
    except IsADirectoryError:
        raise LocalProtocolError(f"sweep spec {path} is a folder, not a spec file (give its "
                                 ".toml file)") from None
    except tomllib.TOMLDecodeError as exc:
        raise LocalProtocolError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise LocalProtocolError(f"{path}: not valid TOML (not UTF-8 text): {exc}") from None
    return parse_spec(data, path.parent, quick)
