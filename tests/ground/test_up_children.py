"""``skeye up`` leaves no orphans (issue 15, point 13) and reports a failed simulator (point 5).

Each ``skeye up`` here runs in its own process group (``start_new_session``), and a finalizer
kills that whole group whatever happens, so a failing test cannot leave processes behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator

import pytest

from tests.ground.conftest import wait_until
from tests.ground.test_up import _children, _free_ports

Start = Callable[..., tuple[subprocess.Popen[str], list[str]]]


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.fixture
def start_up() -> Iterator[Start]:
    started: list[subprocess.Popen[str]] = []

    def start(env: dict[str, str] | None = None, until: str = "skeye up: open"
              ) -> tuple[subprocess.Popen[str], list[str]]:
        sim, img, pilot, ground, video = _free_ports(5)
        argv = [sys.executable, "-m", "skeye.cli", "up", "--sim-port", str(sim),
                "--image-port", str(img), "--pilot-port", str(pilot), "--ground-port",
                str(ground), "--video-port", str(video)]
        full_env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
                    "PYTHONUNBUFFERED": "1", **(env or {})}
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True, env=full_env, start_new_session=True)
        started.append(proc)
        lines: list[str] = []
        assert proc.stdout is not None
        deadline = time.monotonic() + 600  # three interpreters importing MuJoCo on a busy host
        while not any(until in line for line in lines):
            line = proc.stdout.readline()
            assert line and time.monotonic() < deadline, f"no {until!r}: {lines}"
            lines.append(line)
        return proc, lines

    yield start
    for proc in started:  # the whole group, whatever state the test left it in
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait(30)


def test_no_child_survives_a_sigkilled_skeye_up(start_up: Start) -> None:
    proc, _ = start_up()
    children = _children(proc.pid)
    assert len(children) == 3
    os.kill(proc.pid, signal.SIGKILL)  # no handler, no atexit, no finally runs
    proc.wait(30)
    wait_until(lambda: not any(_alive(pid) for pid in children), 120,
               "every child of the killed skeye up to stop")


def test_skeye_up_reports_a_failed_simulator_and_stops_everything(start_up: Start) -> None:
    # The engine fails 2 s of sim time in: while the pilot or ground control may still be
    # starting, or after; either way skeye up must name the simulator's failure and stop.
    proc, lines = start_up(env={"SKEYE_SIM_FAULT_AT_S": "2"}, until="skeye up: stopped")
    assert any("simulator exited (3: its simulation engine failed)" in line
               for line in lines), lines
    assert proc.wait(120) == 1
    assert _children(proc.pid) == []
