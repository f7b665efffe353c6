"""benchmarks/bench_sim.py's own pieces, against a real server on a loopback port.

The benchmark's figures are not asserted (speed is the benchmark's job); what is tested is that
its ``--board-rate`` robot copy loads and flies, and that a robot the simulator refuses stops the
benchmark with the simulator's reason instead of waiting forever for an INIT answer, and that
an option it cannot measure with is refused by its name.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.sim.conftest import running_sim

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from bench_sim import Conn, measure_in_process_rtf, measure_rtf, robot_dir_with_board_rate

ROOT = Path(__file__).resolve().parents[2]


def test_board_rate_copy_flies_at_every_physics_step(tmp_path: Path) -> None:
    name = robot_dir_with_board_rate(tmp_path, 1000.0)
    assert name == "hummingbird_board1000"
    with running_sim(robot_dirs=(tmp_path,)) as server:
        conn = Conn(server.port)
        conn.spawn(name, "X", "0,0,-1")
        conn.send("GETCONF {Type Robot}")
        conf = conn.wait_for(b"CONF")
        assert b"{BoardRate 1000" in conf, conf
        conn.sock.close()
        rtf, lines = measure_rtf(server.port, 1, 0.5, 0.001, name)
        assert rtf > 0 and lines > 0


def test_refused_robot_raises_with_the_simulators_reason(tmp_path: Path) -> None:
    name = robot_dir_with_board_rate(tmp_path, 300.0)  # not a whole number of 1 ms steps
    with running_sim(robot_dirs=(tmp_path,)) as server:
        conn = Conn(server.port)
        with pytest.raises(RuntimeError, match="not an integer fraction of the physics rate"):
            conn.spawn(name, "X", "0,0,-1")
        conn.spawn("hummingbird", "Y", "0,0,-1")  # the connection stays usable
        conn.sock.close()


def test_in_process_measurement_steps_without_a_server() -> None:
    rtf, readings = measure_in_process_rtf(1, 0.2, 0.001, "hummingbird")
    assert rtf > 0 and readings > 0
    rtf, lines = measure_in_process_rtf(1, 0.2, 0.001, "hummingbird", encode=True)
    assert rtf > 0 and lines == readings  # one line per reading


def test_still_copy_has_no_imu_vibration(tmp_path: Path) -> None:
    from bench_sim import robot_dir_without_vibration

    from skeye.sim.engine import Simulation
    from skeye.sim.world import load_world

    name = robot_dir_without_vibration(tmp_path)
    sim = Simulation(load_world("pad"), seed=1, robot_dirs=(tmp_path,))
    robot = sim.spawn(name, name="R1", sink=lambda events: None, location_ned_m=(0, 0, -1.0))
    imu = [s.sensor for s in robot.sensors if s.sensor.type_name in ("Accelerometer", "Gyro")]
    assert len(imu) == 2 and not any(s.vibration.enabled for s in imu)
    rtf, readings = measure_in_process_rtf(1, 0.2, 0.001, name, str(tmp_path))
    assert rtf > 0 and readings > 0


def bench_sim(*args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_sim.py"),
                           "--no-pure", *args], env=env, capture_output=True, text=True,
                          timeout=120)


def test_a_simulator_that_refuses_its_options_ends_the_run_with_its_reason() -> None:
    """``--timestep 1`` (a number, but not a physics step skeye sim takes) ended in a
    SkeyeError traceback; the simulator's reason is the run's one error line."""
    done = bench_sim("--timestep", "1", "--sim-seconds", "0.5", "--samples", "1")
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert "bench_sim: skeye sim did not start" in done.stderr and "--timestep" in done.stderr
