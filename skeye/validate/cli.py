"""``skeye validate [E1|E2|all] --seeds N --out DIR [--quick]``: the paper's experiments."""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from skeye.errors import LocalProtocolError, SkeyeError
from skeye.sweep.backends import LocalBackend
from skeye.sweep.cli import run_trials
from skeye.sweep.spec import SweepSpec, Trial
from skeye.validate.experiments import E1Series, E2Series, RunSettings
from skeye.validate.report import PAPER, median_summary, write_e1, write_e2, write_report


def validate(which: str, seeds: int, out: Path, quick: bool, first_seed: int = 1,
             workers: int | None = None, keep_recordings: bool = False) -> dict[str, Any]:
    """Run the experiments for ``seeds`` seeds on the sweep's local pool; write the report.

    Each (experiment, seed) is one trial of :mod:`skeye.sweep` (its own processes, in parallel
    up to ``workers``); the series come back from the trials and the report is built here.
    """
    which = which.upper()
    if which not in ("E1", "E2", "ALL"):
        raise LocalProtocolError(f"unknown experiment {which!r}: E1, E2 or all")
    if seeds < 1:
        raise LocalProtocolError(f"--seeds must be >= 1, got {seeds}")
    experiments = ("E1", "E2") if which == "ALL" else (which,)
    out.mkdir(parents=True, exist_ok=True)
    seed_list = list(range(first_seed, first_seed + seeds))
    settings = {s: RunSettings(seed=s, quick=quick) for s in seed_list}
    trials = [Trial(e, {}, s, quick, timeout_s=900.0 if quick else 7200.0)
              for s in seed_list for e in experiments]
    spec = SweepSpec(which, trials, [])
    with tempfile.TemporaryDirectory(prefix="skeye-validate-") as tmp:

        def keep(trial: dict[str, Any]) -> dict[str, str]:
            t = Trial.from_json(trial)
            extra = {"series_file": str(Path(tmp) / f"{t.key}.series.json")}
            if keep_recordings:
                extra["workdir"] = str(out / f"recordings_seed{t.seed}")
            return extra

        backend = LocalBackend(workers or max(1, min(len(trials), (os.cpu_count() or 2) // 2)),
                               keep)
        result = run_trials(spec, Path(tmp), backend,
                            f"validate {'/'.join(experiments)} x {seeds} seed(s)")
        failed = [r for r in result.rows if r.get("error")]
        if failed:
            raise SkeyeError("; ".join(f"{r['experiment']} seed {r['seed']}: {r['error']}"
                                       for r in failed))
        series = {(t.experiment, t.seed): json.loads(
            (Path(tmp) / f"{t.key}.series.json").read_text()) for t in trials}
    summary: dict[str, Any] = {"paper": PAPER}
    if "E1" in experiments:
        e1 = {s: E1Series(**series["E1", s]["E1"]) for s in seed_list}
        summary["E1"] = median_summary(write_e1(out, e1))
    if "E2" in experiments:
        e2 = {s: (E2Series(**series["E2", s]["E2"]), E2Series(**series["E2", s]["E2_baseline"]))
              for s in seed_list}
        summary["E2"] = median_summary(write_e2(out, e2, settings))
    write_report(out, summary, quick, seed_list)
    return summary


def cmd_validate(args: argparse.Namespace) -> int:
    summary = validate(args.experiment, args.seeds, Path(args.out), args.quick, args.first_seed,
                       args.workers, args.keep_recordings)
    print((Path(args.out) / "report.md").read_text())
    del summary
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("validate", help="reproduce the paper's experiments and report them")
    p.add_argument("experiment", nargs="?", default="all", help="E1, E2 or all")
    p.add_argument("--seeds", type=int, default=1, help="number of seeds (run in parallel)")
    p.add_argument("--first-seed", type=int, default=1)
    p.add_argument("--out", default="validation", help="output folder")
    p.add_argument("--quick", action="store_true", help="shortened runs (CI)")
    p.add_argument("--workers", type=int, default=None, help="worker processes")
    p.add_argument("--keep-recordings", action="store_true",
                   help="keep the simulator recordings in the output folder")
    p.set_defaults(func=cmd_validate)
