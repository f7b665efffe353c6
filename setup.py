"""Build skeye, compiling the simulator's hot path with mypyc (see skeye/native.py).

Everything else is declared in pyproject.toml. The compiled modules are optional speed-ups of
the same source: with ``SKEYE_PURE_PYTHON=1`` in the environment, or when compiling fails (no C
compiler, say), the package installs as pure Python and says so.

Progress: every step prints a ``skeye setup: [step n/2] ...`` line on stderr (flushed, so
``pip install -v`` and ``make``'s progress filter, skeye/buildprogress.py, show it as it
happens): mypyc translating the modules to C, then each C file as the compiler starts it. The C
files (one per module: mypyc's ``multi_file`` mode) compile in parallel, one compiler per core
(``SKEYE_BUILD_JOBS=N`` to choose).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from importlib.util import module_from_spec, spec_from_file_location
from pathlib import Path
from typing import Any

from setuptools import setup
from setuptools.command.build_ext import build_ext

HERE = Path(__file__).resolve().parent


def _native() -> Any:
    """skeye/native.py, loaded without importing the skeye package (nothing is installed yet)."""
    spec = spec_from_file_location("_skeye_native_for_setup", HERE / "skeye" / "native.py")
    assert spec is not None and spec.loader is not None
    module = module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the file runs
    spec.loader.exec_module(module)
    return module


def _warn(text: str) -> None:
    print(f"skeye setup: {text}; installing the pure-Python simulator (slower)", file=sys.stderr,
          flush=True)


_SAY_LOCK = threading.Lock()


def _say(text: str) -> None:
    # One write per line under a lock: compiler threads report at the same moment, and print()
    # writes the text and its newline separately, so their lines would run together.
    with _SAY_LOCK:
        sys.stderr.write(f"skeye setup: {text}\n")
        sys.stderr.flush()


def _jobs() -> int:
    try:
        return max(1, int(os.environ.get("SKEYE_BUILD_JOBS", "") or (os.cpu_count() or 1)))
    except ValueError:
        return os.cpu_count() or 1


def _parallel_compile(compiler: Any, counter: list[int], total: int) -> None:
    """Make ``compiler.compile`` run one compiler process per source, ``_jobs()`` at a time,
    saying which file each one compiles (distutils compiles an extension's files one by one)."""

    def compile(sources: list[str], output_dir: str | None = None, macros: Any = None,
                include_dirs: Any = None, debug: bool = False, extra_preargs: Any = None,
                extra_postargs: Any = None, depends: Any = None) -> list[str]:
        macros, objects, extra_postargs, pp_opts, build = compiler._setup_compile(
            output_dir, macros, include_dirs, sources, depends, extra_postargs)
        cc_args = compiler._get_cc_args(pp_opts, debug, extra_preargs)

        def one(obj: str) -> None:
            src, ext = build[obj]
            with _SAY_LOCK:
                counter[0] += 1
                number = counter[0]
            _say(f"[step 2/2] compiling C ({number}/{total}): {Path(src).name}")
            compiler._compile(obj, src, ext, cc_args, extra_postargs, pp_opts)

        todo = [obj for obj in objects if obj in build]
        with ThreadPoolExecutor(max_workers=_jobs()) as pool:
            for _ in pool.map(one, todo):  # re-raises the first failure
                pass
        return list(objects)

    compiler.compile = compile


class OptionalBuildExt(build_ext):
    """Compile the extensions, or fall back to pure Python when any of them fails."""

    failed = False

    def run(self) -> None:
        if self.inplace:  # an editable install: drop extensions of modules taken off the list
            for ext in _native().stray_extensions(HERE).values():
                ext.unlink()
        started = time.monotonic()
        total = sum(len(ext.sources) for ext in self.extensions)
        if total:
            _say(f"[step 2/2] compiling {total} C files, {_jobs()} at a time "
                 f"(SKEYE_BUILD_JOBS to change)")
        self._counter = [0]
        self._total = total
        try:
            super().run()
        except Exception as exc:  # no compiler, missing headers: the .py sources still work
            self.failed = True
            _warn(f"could not compile the simulator's hot path ({exc})")
        if self.failed:  # all or nothing: the compiled modules call each other directly
            for ext in self.extensions:
                Path(self.get_ext_fullpath(ext.name)).unlink(missing_ok=True)
        elif total:
            _say(f"[step 2/2] compiled in {time.monotonic() - started:.0f} s")

    def build_extension(self, ext: Any) -> None:
        if not getattr(self.compiler, "_skeye_parallel", False):
            _parallel_compile(self.compiler, self._counter, self._total)
            self.compiler._skeye_parallel = True
        try:
            super().build_extension(ext)
        except Exception as exc:
            self.failed = True
            _warn(f"could not compile {ext.name} ({exc})")


# The PEP 517 hooks run this file once per hook (requirements, metadata, then the build): only
# the commands that build need the extensions, so only they run mypyc (it took ~10 s a time).
_BUILD_COMMANDS = ("build", "build_ext", "bdist_wheel", "editable_wheel", "install", "develop",
                   "bdist_egg")


def _ext_modules() -> list[Any]:
    if not any(arg in _BUILD_COMMANDS for arg in sys.argv[1:]):
        return []
    native = _native()
    if os.environ.get(native.PURE_PYTHON_ENV, "") not in ("", "0"):
        _warn(f"{native.PURE_PYTHON_ENV} is set")
        # Extensions an earlier editable build left beside the sources would still be used.
        for module in native.COMPILED_MODULES:
            ext = native.extension_path(module, HERE)
            if ext is not None:
                ext.unlink()
        return []
    try:
        from mypyc.build import mypycify

        paths = [str(native.source_path(m).relative_to(HERE)) for m in native.COMPILED_MODULES]
        started = time.monotonic()
        _say(f"[step 1/2] mypyc: type-checking {len(paths)} simulator modules and translating "
             "them to C (one step with no per-module output: 10-30 s on a busy 2-core "
             "machine)")
        ext = list(mypycify(paths, opt_level="3", group_name="skeye_native", multi_file=True))
        _say(f"[step 1/2] mypyc done in {time.monotonic() - started:.0f} s")
        return ext
    except (Exception, SystemExit) as exc:  # mypyc missing or refusing the code
        _warn(f"mypyc could not compile the simulator's hot path ({exc!r})")
        return []


setup(ext_modules=_ext_modules(), cmdclass={"build_ext": OptionalBuildExt})
