"""The package layout's import rules, checked on the source (ast), not by importing it.

The rules (docs/architecture.md; every import counts: module level, inside functions, and under
``TYPE_CHECKING``):

1. **Only the simulator's own entry points import ``skeye.sim``**: ``skeye.cli`` (``skeye sim``
   starts the simulator in-process), ``skeye.gym`` (the Gymnasium environments step it
   in-process, as ``skeye sim`` does) and the modules of ``skeye.sim`` itself. Nothing else runs
   a simulator in-process: ``skeye.validate`` and ``skeye.sweep`` start ``skeye sim`` as a child
   process (``skeye.processes.start_skeye``), and every client (control, pilot, ground, vision,
   recording) talks to it over its ports. Importing any of them neither loads MuJoCo nor sets
   ``MUJOCO_GL`` (only :mod:`skeye.sim.gl` does, imported by the modules that load MuJoCo).
2. **``skeye.wire`` is sans-IO and self-contained**: its modules import only the standard
   library, numpy, ``skeye.errors`` and each other.
3. **No package imports another package's private names**: ``from skeye.a import _x`` and
   ``a_module._x`` are allowed only inside the package that defines ``_x`` (a top-level module
   such as ``skeye.cli`` counts as its own package).
4. **No import circle** between modules of ``skeye``.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "skeye"
SIM = "skeye.sim"
SIM_IMPORTERS = {"skeye.cli", "skeye.gym"}  # a module, or a package with its modules
WIRE = "skeye.wire"
WIRE_MAY_IMPORT = {"numpy", "skeye.errors"}

@dataclass(frozen=True)
class Import:
    """One import statement's target, as the module that makes it names it."""

    importer: str
    target: str  # the module imported (``from a.b import c``: ``a.b.c`` if that is a module)
    names: tuple[str, ...]  # names taken from the target (``from`` imports)
    line: int


def module_names(root: Path, package: str) -> dict[str, Path]:
    """Every module of ``package`` under ``root``: dotted name -> file."""
    found = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


def _resolve(importer: str, is_package: bool, level: int, module: str | None) -> str:
    if level == 0:
        return module or ""
    base = importer.split(".")
    if not is_package:
        base = base[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> Iterator[Import]:
    """The imports ``name`` makes, anywhere in the file."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    is_package = path.name == "__init__.py"
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield Import(name, alias.name, (), node.lineno)
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(name, is_package, node.level, node.module)
            plain = [a.name for a in node.names if f"{base}.{a.name}" not in modules]
            if plain:
                yield Import(name, base, tuple(plain), node.lineno)
            for alias in node.names:
                if f"{base}.{alias.name}" in modules:
                    yield Import(name, f"{base}.{alias.name}", (), node.lineno)


def all_imports(root: Path, package: str) -> list[Import]:
    modules = module_names(root, package)
    return [imp for name, path in modules.items() for imp in imports_of(name, path, modules)]


def _top(module: str, package: str) -> str:
    """The package a module belongs to for the private-name rule: ``skeye.x``."""
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 else module


def _within(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


def sim_violations(imports: list[Import], package: str = PACKAGE,
                   ) -> list[str]:
    sim = f"{package}.sim"
    importers = {f"{package}{name.removeprefix(PACKAGE)}" for name in SIM_IMPORTERS}
    bad = []
    for imp in imports:
        if not _within(imp.target, sim) or _within(imp.importer, sim):
            continue
        if any(_within(imp.importer, allowed) for allowed in importers):
            continue
        bad.append(f"{imp.importer}:{imp.line} imports {imp.target}")
    return bad


def wire_violations(imports: list[Import], package: str = PACKAGE) -> list[str]:
    wire = f"{package}.wire"
    allowed = {f"{package}.errors", "numpy"}
    bad = []
    for imp in imports:
        if not _within(imp.importer, wire):
            continue
        top = imp.target.split(".")[0]
        if (top in sys.stdlib_module_names or _within(imp.target, wire)
                or any(_within(imp.target, a) for a in allowed)):
            continue
        bad.append(f"{imp.importer}:{imp.line} imports {imp.target}")
    return bad


def private_violations(root: Path, package: str) -> list[str]:
    """``from other import _x`` and ``other_module._x`` across packages."""
    modules = module_names(root, package)
    bad = []
    for name, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        aliases: dict[str, str] = {}  # local name -> a skeye module it is bound to
        for imp in imports_of(name, path, modules):
            if not _within(imp.target, package) or _top(imp.target, package) == _top(
                name, package
            ):
                continue
            for n in imp.names:
                if n.startswith("_") and not n.startswith("__"):
                    bad.append(f"{name}:{imp.line} imports {imp.target}.{n}")
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                base = _resolve(name, path.name == "__init__.py", node.level, node.module)
                for alias in node.names:
                    if f"{base}.{alias.name}" in modules:
                        aliases[alias.asname or alias.name] = f"{base}.{alias.name}"
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.asname and alias.name in modules:
                        aliases[alias.asname] = alias.name
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and node.attr.startswith("_")
                    and not node.attr.startswith("__")):
                target = aliases[node.value.id]
                if _top(target, package) != _top(name, package):
                    bad.append(f"{name}:{node.lineno} uses {target}.{node.attr}")
    return bad


def import_cycles(imports: list[Import], modules: set[str]) -> list[list[str]]:
    """Strongly connected groups of more than one module (or a module importing itself)."""
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for imp in imports:
        if imp.target in modules and imp.target != imp.importer:
            graph[imp.importer].add(imp.target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:  # Tarjan's algorithm
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                cycles.append(sorted(group))

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(graph) + 100))
    try:
        for v in sorted(graph):
            if v not in index:
                visit(v)
    finally:
        sys.setrecursionlimit(limit)
    return cycles


# --------------------------------------------------------------------------- the real tree


@pytest.fixture(scope="module")
def imports() -> list[Import]:
    return all_imports(ROOT, PACKAGE)


def test_only_the_simulator_and_its_command_import_skeye_sim(imports: list[Import]) -> None:
    assert sim_violations(imports) == []


def test_wire_imports_only_stdlib_numpy_and_errors(imports: list[Import]) -> None:
    assert any(_within(i.importer, WIRE) for i in imports)  # the package is really scanned
    assert wire_violations(imports) == []


def test_no_package_imports_another_packages_private_names() -> None:
    assert private_violations(ROOT, PACKAGE) == []


def test_no_import_circle(imports: list[Import]) -> None:
    assert import_cycles(imports, set(module_names(ROOT, PACKAGE))) == []


def test_clients_neither_load_mujoco_nor_set_its_gl_backend() -> None:
    clients = ["skeye", "skeye.control", "skeye.pilot.cli", "skeye.pilot.server",
               "skeye.ground.cli", "skeye.ground.app", "skeye.vision.cli", "skeye.validate.cli",
               "skeye.sweep.cli", "skeye.recording.replay", "skeye.recording.plotting",
               "skeye.recording.snapshot", "skeye.robots.config", "skeye.wire.images",
               "skeye.link.vehicle", "skeye.pixels", "skeye.pilot.policy",
               "skeye.pilot.asctec_ll", "skeye.pilot.camera_sim", "skeye.pilot.camera_v4l2",
               "skeye.pilot.camera_file", "skeye.hil.cli", "skeye.hil.ll_server"]
    code = textwrap.dedent(f"""
        import importlib, os, sys
        for name in {clients!r}:
            importlib.import_module(name)
        print(os.environ.get("MUJOCO_GL"), "mujoco" in sys.modules)
    """)
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                          cwd=ROOT, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["None", "False"]
    started = subprocess.run(
        [sys.executable, "-c", "import os, skeye.sim.engine; print(os.environ['MUJOCO_GL'])"],
        capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
    assert started.returncode == 0 and started.stdout.strip(), started.stderr


# --------------------------------------------------------------------------- the checker itself


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))
    for folder in {p.parent for p in tmp_path.rglob("*.py")}:
        (folder / "__init__.py").touch()
    return tmp_path


@pytest.mark.parametrize(
    ("files", "rule"),
    [
        ({"pkg/control/a.py": "from pkg.sim.engine import run\n", "pkg/sim/engine.py": ""},
         "sim"),
        ({"pkg/control/a.py": "def f():\n    import pkg.sim.engine\n",
          "pkg/sim/engine.py": ""}, "sim"),
        ({"pkg/control/a.py": "from ..sim import engine\n", "pkg/sim/engine.py": ""}, "sim"),
        ({"pkg/wire/a.py": "import cv2\n"}, "wire"),
        ({"pkg/wire/a.py": "from pkg.control import b\n", "pkg/control/b.py": ""}, "wire"),
        ({"pkg/control/a.py": "from pkg.link.b import _helper\n", "pkg/link/b.py": ""},
         "private"),
        ({"pkg/control/a.py": "from pkg.link import b\nb._helper()\n", "pkg/link/b.py": ""},
         "private"),
        ({"pkg/a.py": "import pkg.b\n", "pkg/b.py": "from pkg import c\n",
          "pkg/c.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pkg.a\n"},
         "cycle"),
    ],
    ids=["sim-from", "sim-in-function", "sim-relative", "wire-third-party", "wire-upward",
         "private-import", "private-attribute", "cycle-via-type-checking"],
)
def test_each_rule_catches_a_violation(tmp_path: Path, files: dict[str, str], rule: str
                                       ) -> None:
    root = _tree(tmp_path, files)
    found = all_imports(root, "pkg")
    results = {
        "sim": sim_violations(found, "pkg"),
        "wire": wire_violations(found, "pkg"),
        "private": private_violations(root, "pkg"),
        "cycle": import_cycles(found, set(module_names(root, "pkg"))),
    }
    assert results[rule], f"the {rule} rule missed it"
    assert all(not v for k, v in results.items() if k != rule), results


def test_allowed_imports_pass(tmp_path: Path) -> None:
    root = _tree(tmp_path, {
        "pkg/cli.py": "from pkg.sim import engine\n",
        "pkg/sim/engine.py": "from pkg.sim import _inner\nfrom pkg.sim._inner import _x\n",
        "pkg/sim/_inner.py": "_x = 1\n",
        "pkg/wire/a.py": "import struct\nimport numpy as np\nfrom pkg.errors import E\n"
                         "from pkg.wire import b\n",
        "pkg/wire/b.py": "",
        "pkg/errors.py": "class E(Exception):\n    pass\n",
    })
    found = all_imports(root, "pkg")
    assert sim_violations(found, "pkg") == []
    assert wire_violations(found, "pkg") == []
    assert private_violations(root, "pkg") == []
    assert import_cycles(found, set(module_names(root, "pkg"))) == []
