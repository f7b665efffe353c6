"""The simulator's compiled hot path: which modules are compiled, and whether they are in use.

Why: the physics loop (engine, board, sensors) runs hundreds of small float computations per
simulated millisecond; compiled with mypyc (mypy's compiler: the same annotated Python source,
turned into a C extension at install time) it runs about twice as fast, which is what lets a
lockstep run go 50x faster than real time on a 2-core machine. The source stays the one truth:
the ``.py`` files are what is compiled, and the pure-Python modules give the same results bit
for bit (tests/sim/test_native.py compares the two).

How this works: ``setup.py`` compiles :data:`COMPILED_MODULES` when the package is installed
(``make run``/``make test``, or ``pip install -e .``); an editable install leaves the extension
next to each source file. ``import skeye`` calls :func:`install` before any of those modules is
imported, which decides once per process whether to use the compiled modules:

- ``SKEYE_PURE_PYTHON=1`` in the environment: use the ``.py`` sources (debugging, profiling);
- a source edited after it was compiled: use the ``.py`` sources, with a warning saying how to
  rebuild - an edit always takes effect, never silently shadowed by a stale extension;
- no extension (built with ``SKEYE_PURE_PYTHON=1``, or no C compiler): the ``.py`` sources.

The decision is all-or-nothing: compiled modules call each other directly, so a mix of compiled
and source modules would run stale code. This module must import only the standard library:
``setup.py`` reads :data:`COMPILED_MODULES` from it before anything is installed.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import importlib.util
import os
import sys
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

COMPILED_MODULES: tuple[str, ...] = (
    "skeye.robots.params",
    "skeye.sim.state",
    "skeye.sim.frames",
    "skeye.sim.controller",
    "skeye.sim.estimator",
    "skeye.sim.vehicle",
    "skeye.sim.wind",
    "skeye.sim.robot",
    "skeye.sim.sensors.base",
    "skeye.sim.sensors.inertial",
    "skeye.sim.sensors.navigation",
    "skeye.sim.sensors.ranging",
    "skeye.sim.sensors.vibration",
    "skeye.sim.readings",
    "skeye.sim.raycast",
    "skeye.sim.engine",
)
"""Modules compiled by mypyc at install time (dotted names)."""

GROUP_LIBRARY = "skeye_native__mypyc"
"""The shared library the compiled modules live in (mypyc's group; beside the package)."""

PURE_PYTHON_ENV = "SKEYE_PURE_PYTHON"
# A source counts as edited after compilation only when it is this much newer than its
# extension: an install writes both within a moment, in either order.
_STALE_SLACK_S = 2.0
_ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class NativeStatus:
    """Whether the compiled modules are used in this process, and why (or why not)."""

    compiled: bool
    reason: str

    def describe(self) -> str:
        """One line for start-up messages and benchmark output."""
        if self.compiled:
            return f"simulator hot path: compiled (mypyc, {len(COMPILED_MODULES)} modules)"
        return f"simulator hot path: pure Python ({self.reason})"


def source_path(module: str, root: Path = _ROOT) -> Path:
    """The ``.py`` file of a module in :data:`COMPILED_MODULES` (``root`` holds ``skeye/``)."""
    return root.joinpath(*module.split(".")).with_suffix(".py")


def extension_path(module: str, root: Path = _ROOT) -> Path | None:
    """The compiled extension beside a module's source, or None when there is none."""
    return _extension(source_path(module, root).with_suffix(""))


def _extension(stem: Path) -> Path | None:
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        candidate = stem.with_name(stem.name + suffix)
        if candidate.exists():
            return candidate
    return None


def decide(root: Path = _ROOT, environ: Mapping[str, str] = os.environ) -> NativeStatus:
    """Whether the compiled modules under ``root`` may be used (see the module doc)."""
    if environ.get(PURE_PYTHON_ENV, "") not in ("", "0"):
        return NativeStatus(False, f"{PURE_PYTHON_ENV} is set")
    if _extension(root / GROUP_LIBRARY) is None:
        return NativeStatus(False, "not compiled; run `make` (or `pip install -e .`) to build it")
    for module in COMPILED_MODULES:
        ext = extension_path(module, root)
        if ext is None:
            return NativeStatus(False, f"no compiled extension for {module}; run `make`")
        src = source_path(module, root)
        if src.exists() and src.stat().st_mtime > ext.stat().st_mtime + _STALE_SLACK_S:
            return NativeStatus(
                False,
                f"{src.relative_to(root)} changed since it was compiled; rebuild with `make` "
                "or `pip install -e .`",
            )
    return NativeStatus(True, "compiled extensions up to date")


def stray_extensions(root: Path = _ROOT) -> dict[str, Path]:
    """Compiled extensions left beside a source that is not in :data:`COMPILED_MODULES` (a
    module taken off the list after a build), by module name: never loaded."""
    found = {}
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        for ext in (root / "skeye").rglob("*" + suffix):
            source = ext.with_name(ext.name[: -len(suffix)] + ".py")
            module = ".".join(source.relative_to(root).with_suffix("").parts)
            if source.exists() and module not in COMPILED_MODULES:
                found[module] = ext
    return found


class _SourceFinder(importlib.abc.MetaPathFinder):
    """Loads the given modules from their ``.py`` sources, never from an extension."""

    def __init__(self, modules: set[str]) -> None:
        self.modules = modules

    def find_spec(
        self, fullname: str, path: object = None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname not in self.modules:
            return None
        return importlib.util.spec_from_file_location(fullname, source_path(fullname))


_status: NativeStatus | None = None


def install() -> NativeStatus:
    """Decide (once per process) whether to use the compiled modules; see the module doc."""
    global _status
    if _status is not None:
        return _status
    _status = decide()
    from_source = set(stray_extensions())
    if from_source:
        warnings.warn(
            f"skeye: ignoring compiled modules no longer compiled: {', '.join(sorted(from_source))}"
            " (`make` removes them)", RuntimeWarning, stacklevel=2,
        )
    if not _status.compiled and any(extension_path(m) for m in COMPILED_MODULES):
        from_source.update(COMPILED_MODULES)
        if not _status.reason.startswith(PURE_PYTHON_ENV):
            warnings.warn(f"skeye: {_status.describe()}", RuntimeWarning, stacklevel=2)
    if from_source:
        sys.meta_path.insert(0, _SourceFinder(from_source))
    return _status


def status() -> NativeStatus:
    """What :func:`install` decided, checked against the modules actually imported."""
    decided = install()
    for module in COMPILED_MODULES:
        loaded = sys.modules.get(module)
        if loaded is None:
            continue
        is_extension = not str(getattr(loaded, "__file__", "")).endswith(".py")
        if is_extension != decided.compiled:
            return NativeStatus(is_extension, f"{module} was loaded from {loaded.__file__}")
    return decided


if __name__ == "__main__":
    # `python skeye/native.py --sources` lists the compiled sources (the Makefile's rebuild rule).
    if sys.argv[1:] == ["--sources"]:
        print(" ".join(str(source_path(m).relative_to(_ROOT)) for m in COMPILED_MODULES))
    else:
        print(status().describe())
