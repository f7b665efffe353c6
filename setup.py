"""Build skeye, compiling the simulator's hot path with mypyc (see skeye/native.py).

Everything else is declared in pyproject.toml. The compiled modules are optional speed-ups of
the same source: with ``SKEYE_PURE_PYTHON=1`` in the environment, or when compiling fails (no C
compiler, say), the package installs as pure Python and says so.
"""

from __future__ import annotations

import os
import sys
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
    print(f"skeye setup: {text}; installing the pure-Python simulator (slower)", file=sys.stderr)


class OptionalBuildExt(build_ext):
    """Compile the extensions, or fall back to pure Python when any of them fails."""

    failed = False

    def run(self) -> None:
        if self.inplace:  # an editable install: drop extensions of modules taken off the list
            for ext in _native().stray_extensions(HERE).values():
                ext.unlink()
        try:
            super().run()
        except Exception as exc:  # no compiler, missing headers: the .py sources still work
            self.failed = True
            _warn(f"could not compile the simulator's hot path ({exc})")
        if self.failed:  # all or nothing: the compiled modules call each other directly
            for ext in self.extensions:
                Path(self.get_ext_fullpath(ext.name)).unlink(missing_ok=True)

    def build_extension(self, ext: Any) -> None:
        try:
            super().build_extension(ext)
        except Exception as exc:
            self.failed = True
            _warn(f"could not compile {ext.name} ({exc})")


def _ext_modules() -> list[Any]:
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
        return list(mypycify(paths, opt_level="3", group_name="skeye_native"))
    except (Exception, SystemExit) as exc:  # mypyc missing or refusing the code
        _warn(f"mypyc could not compile the simulator's hot path ({exc!r})")
        return []


setup(ext_modules=_ext_modules(), cmdclass={"build_ext": OptionalBuildExt})
