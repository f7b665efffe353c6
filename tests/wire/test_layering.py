"""``skeye.wire`` is the sans-IO bottom layer: it imports only the standard library, numpy and
``skeye.errors`` (and itself), so servers, clients and tools can all share it."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import skeye.wire

WIRE = Path(skeye.wire.__file__).parent
ALLOWED = ("numpy", "skeye.errors", "skeye.wire")


def _imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
    return names


def test_wire_imports_only_stdlib_numpy_and_errors() -> None:
    modules = sorted(WIRE.glob("*.py"))
    assert len(modules) >= 5  # packet_defs, packets, crc, scales, packet_units (and more)
    bad = {
        f"{path.name}: {name}"
        for path in modules
        for name in _imports(path)
        if name.split(".")[0] not in sys.stdlib_module_names
        and not any(name == a or name.startswith(a + ".") for a in ALLOWED)
    }
    assert not bad, sorted(bad)
