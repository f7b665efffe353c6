"""``skeye sim`` and ``skeye snapshot`` refuse bad set-ups at once, with messages that say what
to change: a robot file with a typo in ``--robot-dir``, no image server at the address."""

from __future__ import annotations

import socket
import subprocess
import sys
from importlib import resources
from pathlib import Path

import pytest

from skeye.errors import ConfigError
from skeye.sim.engine import Simulation
from skeye.sim.world import load_world


def _skeye(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "skeye.cli", *argv], capture_output=True,
                          text=True, timeout=120)


def test_sim_refuses_to_start_with_a_robot_file_that_has_a_typo(tmp_path: Path) -> None:
    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
    (tmp_path / "good.toml").write_text(text.replace('name = "hummingbird"', 'name = "good"'))
    (tmp_path / "typo.toml").write_text(
        text.replace('name = "hummingbird"', 'name = "typo"').replace("mass_kg", "mas_kg"))
    # The message INIT {ClassName typo} would get...
    sim = Simulation(load_world("pad"), seed=1, robot_dirs=(tmp_path,))
    with pytest.raises(ConfigError) as info:
        sim.spawn("typo", sink=lambda events: None, name="T")
    assert "mas_kg" in str(info.value)
    # ... is what skeye sim says at start-up, before it listens.
    done = _skeye("sim", "--port", "0", "--robot-dir", str(tmp_path))
    assert done.returncode == 2, done
    assert str(info.value) in done.stderr
    assert "control protocol on" not in done.stdout
    done = _skeye("sim", "--port", "0", "--robot-dir", str(tmp_path / "nowhere"))
    assert done.returncode == 2 and "not a folder" in done.stderr


def test_snapshot_without_an_image_server_names_the_address_and_the_option() -> None:
    with socket.create_server(("127.0.0.1", 0)) as probe:
        port = probe.getsockname()[1]  # free once closed: nothing listens there
    done = _skeye("snapshot", "--images", f"127.0.0.1:{port}", "--out", "x.png")
    assert done.returncode == 2
    assert f"no image server at 127.0.0.1:{port}" in done.stderr
    assert f"--image-port {port}" in done.stderr and "--images" in done.stderr
