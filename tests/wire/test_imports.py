"""skeye.wire imports only the standard library (no sockets, threads or clocks), numpy and
skeye.errors (and itself)."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import skeye.wire

WIRE = Path(skeye.wire.__file__).resolve().parent


def _imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, f"{path.name}: relative import"
            names.add(node.module or "")
    return names


SANS_IO_FORBIDDEN = frozenset({"socket", "selectors", "threading", "asyncio", "serial", "time"})
"""Standard modules a sans-IO codec has no business with (no sockets, threads or clocks)."""


def _allowed(module: str) -> bool:
    top = module.split(".")[0]
    return (
        (top in sys.stdlib_module_names and top not in SANS_IO_FORBIDDEN)
        or top == "numpy"
        or module == "skeye.errors"
        or module == "skeye.wire"
        or module.startswith("skeye.wire.")
    )


def test_wire_imports_only_the_standard_library_numpy_and_errors() -> None:
    files = sorted(WIRE.glob("*.py"))
    assert any(p.name == "sim.py" for p in files)
    bad = {p.name: sorted(m for m in _imports(p) if not _allowed(m)) for p in files}
    assert not {k: v for k, v in bad.items() if v}


def test_the_check_can_fail() -> None:
    assert not _allowed("skeye.sim.engine")
    assert not _allowed("skeye")
    assert not _allowed("socket")
    assert not _allowed("mujoco")
    assert _allowed("dataclasses") and _allowed("numpy") and _allowed("skeye.wire.sim_lines")
