"""The compiled hot path (skeye.native): chosen only when fresh, and identical to the source.

The equivalence test flies the same seeded lockstep scenario twice, in two processes: once on
the mypyc-compiled modules, once on their ``.py`` sources (``SKEYE_PURE_PYTHON=1``), and
compares every byte both streamed and the final MuJoCo state. ``make test`` sets
``SKEYE_REQUIRE_COMPILED=1``, so there a missing or stale build fails instead of skipping.
"""

from __future__ import annotations

import importlib.machinery
import os
import subprocess
import sys
from pathlib import Path

import pytest

from skeye import native

# A scenario that crosses every compiled module: two robots (one landed, one hovering), both
# command forms, turbulence, every sensor (GPS, sonar rays, flow), a robot leaving mid-run.
SCENARIO = r"""
import hashlib, sys
from skeye import native
from skeye.sim.engine import Simulation
from skeye.sim.stream import text_sink
from skeye.wire.wind import make_settings
from skeye.sim.world import load_world

print(native.status().describe())
out = []
sim = Simulation(load_world("yard"), seed=11,
                 wind=make_settings("turbulence", {"speed_m_s": 3.0}))
sink = text_sink(out.append)
a = sim.spawn("hummingbird", sink=sink, name="A", location_ned_m=(0.0, 0.0, -1.5))
b = sim.spawn("hummingbird", sink=sink, name="B", start="Street1")
sim.step(700)
a.drive(forward_m_s=0.8, right_m_s=-0.3, yaw_rate_rad_s=0.4)
b.drive(up_m_s=1.0)
sim.step(1500)
b.drive(attitude=True, roll_rad=0.05, pitch_rad=-0.04, thrust=0.55)
sim.step(900)
sim.remove("A")
sim.step(400)
out.append(sim.data.qpos.tobytes() + sim.data.qvel.tobytes())
stream = b"".join(out)
print(len(stream), hashlib.sha256(stream).hexdigest())
"""


def _run_scenario(pure: bool) -> tuple[str, str]:
    env = dict(os.environ)
    env.pop(native.PURE_PYTHON_ENV, None)
    if pure:
        env[native.PURE_PYTHON_ENV] = "1"
    done = subprocess.run(
        [sys.executable, "-c", SCENARIO], env=env, capture_output=True, text=True, timeout=240
    )
    assert done.returncode == 0, done.stderr
    mode, digest = done.stdout.strip().splitlines()[-2:]
    return mode, digest


def test_the_build_is_compiled_where_required() -> None:
    status = native.status()
    if os.environ.get("SKEYE_REQUIRE_COMPILED") == "1":
        assert status.compiled, status.describe()
    elif not status.compiled:
        pytest.skip(status.describe())
    import skeye.sim.engine

    assert not str(skeye.sim.engine.__file__).endswith(".py")


def test_compiled_and_pure_python_stream_identical_bytes() -> None:
    if not native.status().compiled and os.environ.get("SKEYE_REQUIRE_COMPILED") != "1":
        pytest.skip(native.status().describe())
    compiled_mode, compiled = _run_scenario(pure=False)
    pure_mode, pure = _run_scenario(pure=True)
    assert "compiled" in compiled_mode
    assert "pure Python" in pure_mode and native.PURE_PYTHON_ENV in pure_mode
    assert compiled == pure
    size = int(compiled.split()[0])
    assert size > 100_000, "the scenario streamed little: did it fly?"


def _fake_build(root: Path, *, group: bool = True) -> None:
    """Sources and (empty) extension files laid out as an in-place build leaves them."""
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    for module in native.COMPILED_MODULES:
        src = native.source_path(module, root)
        src.parent.mkdir(parents=True, exist_ok=True)
        src.write_text("# source\n")
        os.utime(src, (1_000_000, 1_000_000))
        ext = src.with_name(src.stem + suffix)
        ext.write_bytes(b"")
        os.utime(ext, (1_000_010, 1_000_010))
    if group:
        (root / (native.GROUP_LIBRARY + suffix)).write_bytes(b"")


def test_a_fresh_build_is_used(tmp_path: Path) -> None:
    _fake_build(tmp_path)
    assert native.decide(tmp_path, environ={}).compiled


def test_an_edited_source_falls_back_to_python_and_says_how_to_rebuild(tmp_path: Path) -> None:
    _fake_build(tmp_path)
    edited = native.source_path("skeye.sim.controller", tmp_path)
    os.utime(edited, (1_000_100, 1_000_100))
    status = native.decide(tmp_path, environ={})
    assert not status.compiled
    assert "skeye/sim/controller.py changed since it was compiled" in status.reason
    assert "make" in status.describe()


def test_an_install_writing_source_after_extension_is_not_stale(tmp_path: Path) -> None:
    _fake_build(tmp_path)
    src = native.source_path("skeye.sim.engine", tmp_path)
    os.utime(src, (1_000_011, 1_000_011))  # a second after its extension: same install
    assert native.decide(tmp_path, environ={}).compiled


def test_missing_pieces_and_the_environment_switch(tmp_path: Path) -> None:
    _fake_build(tmp_path, group=False)
    assert "not compiled" in native.decide(tmp_path, environ={}).reason
    _fake_build(tmp_path)
    native.extension_path("skeye.sim.wind", tmp_path).unlink()  # type: ignore[union-attr]
    assert "skeye.sim.wind" in native.decide(tmp_path, environ={}).reason
    _fake_build(tmp_path)
    assert not native.decide(tmp_path, environ={native.PURE_PYTHON_ENV: "1"}).compiled
    assert native.decide(tmp_path, environ={native.PURE_PYTHON_ENV: "0"}).compiled


def test_setup_compiles_exactly_the_listed_modules() -> None:
    listed = subprocess.run(
        [sys.executable, str(Path(native.__file__)), "--sources"],
        capture_output=True, text=True, check=True,
    ).stdout.split()
    assert listed == [
        str(native.source_path(m).relative_to(Path(native.__file__).parent.parent))
        for m in native.COMPILED_MODULES
    ]


def test_an_extension_left_from_an_older_list_is_found(tmp_path: Path) -> None:
    _fake_build(tmp_path)
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    source = tmp_path / "skeye" / "sim" / "protocol.py"
    source.write_text("# source\n")
    stray = source.with_name("protocol" + suffix)
    stray.write_bytes(b"")
    assert native.stray_extensions(tmp_path) == {"skeye.sim.protocol": stray}
    assert native.decide(tmp_path, environ={}).compiled  # the listed ones are still fine
