"""A frozen simulator (issue 15, point 6): the ``skeye sim`` process is stopped (SIGSTOP) under a
hovering pilot. Its sockets stay open, so only the clock tells: sim time stands still while the
wall clock runs. The pilot declares FAILSAFE, NAV_STATUS says so, commands are refused with the
reason, and a real ``skeye ground`` process shows ``failsafe``."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import urllib.request
from contextlib import ExitStack
from typing import ClassVar

import pytest

from skeye.control.connection import connect
from skeye.control.motion import MotionConfig
from skeye.errors import CommandRejected
from skeye.link.vehicle import Vehicle
from skeye.pilot.boards import BoardSettings
from skeye.pilot.server import STOP_S, PilotServer
from skeye.pilot.sim_airframe import CLOSE_S, SimAirframe
from skeye.processes import die_with_parent, start_skeye, stop_process
from skeye.wire.packets import NavState, SkeyeMask
from tests.ground.conftest import wait_until


def _ground_state(port: int, token: str) -> dict:
    request = urllib.request.Request(f"http://127.0.0.1:{port}/api/state",
                                     headers={"X-Skeye-Token": token})
    with urllib.request.urlopen(request, timeout=10) as r:
        return json.load(r)


def test_frozen_realtime_simulator_puts_the_pilot_in_failsafe() -> None:
    with ExitStack() as stack:
        sim_proc, found = start_skeye(["sim", "--port", "0"], [r"control protocol on [\d.]+:(\d+)"],
                                      "simulator", timeout_s=120)
        stack.callback(stop_process, sim_proc)
        stack.callback(lambda: sim_proc.poll() is None and os.kill(sim_proc.pid, signal.SIGCONT))
        sim = stack.enter_context(connect(f"127.0.0.1:{found[0].group(1)}", timeout_s=30.0))
        robot = sim.spawn("hummingbird", start="Pad1")
        # Long link timeout: only the frozen simulator may cause the failsafe in this test.
        pilot = stack.enter_context(
            PilotServer(SimAirframe(sim, robot, frozen_timeout_s=5.0), port=0,
                        settings=BoardSettings(link_timeout_s=600.0, land_timeout_s=600.0))
        )
        with Vehicle.open(pilot.address, timeout_s=30.0) as vehicle:
            vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.05)
            vehicle.take_off(1.0)
            vehicle.wait_state(NavState.HOLDING, timeout_s=120)
        # its address and the vehicle it reached (issue 34), in whichever order they come
        either = (r"skeye ground: (?:http://127.0.0.1:(\d+)/\?token=([\w-]+)|reached (.+) "
                  r"\((simulated|a real vehicle)\) at )")
        ground_proc, gfound = start_skeye(
            ["ground", "--vehicle", pilot.address, "--port", "0"], [either, either],
            "ground control", timeout_s=120)
        stack.callback(stop_process, ground_proc)
        web = next(m for m in gfound if m.group(1))
        reached = next(m for m in gfound if m.group(3))
        gport, token = int(web.group(1)), web.group(2)
        assert reached.group(4) == "simulated" and robot.name in reached.group(3), reached.group(0)
        wait_until(lambda: (_ground_state(gport, token)["nav"] or {}).get("state") == "holding", 60,
                   "ground control shows the vehicle holding")
        assert pilot.vehicle_lost is None

        os.kill(sim_proc.pid, signal.SIGSTOP)  # frozen: connected, silent
        wait_until(lambda: pilot.vehicle_lost is not None, 120, "the pilot notices")
        assert "simulator frozen" in str(pilot.vehicle_lost)
        assert pilot.boards.state is NavState.FAILSAFE
        wait_until(lambda: (_ground_state(gport, token)["nav"] or {}).get("state") == "failsafe",
                   60, "ground control shows the failsafe")
        assert pilot.loop_error is None
        stop_process(ground_proc)

        # NAV_STATUS says so to any ground station, and commands are refused with the reason.
        with Vehicle.open(pilot.address, timeout_s=30.0) as vehicle:
            vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.05)
            vehicle.wait_state(NavState.FAILSAFE, timeout_s=30)
            with pytest.raises(CommandRejected) as info:
                vehicle.move_by(forward_m=1.0)
            assert info.value.code == 4
            assert "the vehicle is lost: simulator frozen" in str(info.value), info.value
        os.kill(sim_proc.pid, signal.SIGCONT)


def test_frozen_detection_needs_sim_time_to_stand_still() -> None:
    """The watchdog's rule on an injected clock: moving sim time resets it; standing sim time
    trips it only after the timeout."""

    class _Conn:
        mode = "realtime"
        time_s = 1.0
        error = None
        closed = False

    class _Robot:
        limits: ClassVar[dict[str, float]] = {}
        motion_config = MotionConfig()
        removed = False

    now = [100.0]
    conn = _Conn()
    airframe = SimAirframe(conn, _Robot(), frozen_timeout_s=5.0,  # type: ignore[arg-type]
                           clock=lambda: now[0])
    for _ in range(20):  # 20 s of wall time, sim time moving: never frozen
        now[0] += 1.0
        conn.time_s += 0.5
        assert airframe.lost is None
    now[0] += 4.9
    assert airframe.lost is None
    now[0] += 0.2
    assert airframe.lost is not None and "frozen" in airframe.lost


def _pilot_stop_s(tmp_path, sim_port: str, image_port: str, name: str,
                  freeze: subprocess.Popen | None) -> tuple[float, int, str, str]:
    """Start a ``skeye pilot`` on the simulator, stop that simulator with SIGSTOP (when
    ``freeze`` is it), Ctrl-C the pilot: the seconds from the signal to its exit, its status,
    stdout and stderr."""
    out, err = tmp_path / f"{name}.out", tmp_path / f"{name}.err"
    with ExitStack() as stack:
        o, e = stack.enter_context(out.open("w")), stack.enter_context(err.open("w"))
        pilot = subprocess.Popen(
            [sys.executable, "-m", "skeye.cli", "pilot", "--sim", f"127.0.0.1:{sim_port}",
             "--images", f"127.0.0.1:{image_port}", "--port", "0"],
            stdout=o, stderr=e, stdin=subprocess.DEVNULL, preexec_fn=die_with_parent())
        stack.callback(stop_process, pilot)  # type: ignore[arg-type]
        deadline = time.monotonic() + 120  # a stuck guard
        while "ground control on" not in out.read_text():
            assert pilot.poll() is None, err.read_text()
            assert time.monotonic() < deadline, "the pilot did not start within 120 s"
            time.sleep(0.05)
        if freeze is not None:
            os.kill(freeze.pid, signal.SIGSTOP)  # connected, silent
        t0 = time.monotonic()
        pilot.send_signal(signal.SIGINT)
        status = pilot.wait(60)
        took_s = time.monotonic() - t0
    return took_s, status, out.read_text(), err.read_text()


def test_ctrl_c_stops_a_pilot_on_a_frozen_simulator_promptly(tmp_path) -> None:
    """A ``skeye pilot`` process (lockstep, with its camera) whose ``skeye sim`` is stopped with
    SIGSTOP gets Ctrl-C. Every wait at stop is bounded: the loop's STEP and the vision's frame
    request never get their answer, nor does the simulator close its end. It took 6 s here
    (14 s flying in realtime: the camera retried its request on a new connection), against
    about 1 s on a simulator that answers; now it stops within its stop bounds of that and
    says what it could not do. The pilot on the answering simulator is stopped first, in the
    same test, so that a loaded machine's slower start and exit are on both sides."""
    with ExitStack() as stack:
        sim_proc, found = start_skeye(
            ["sim", "--port", "0", "--image-port", "0", "--mode", "lockstep"],
            [r"control protocol on [\d.]+:(\d+)", r"image server on [\d.]+:(\d+)"],
            "simulator", timeout_s=120)
        stack.callback(stop_process, sim_proc)
        stack.callback(lambda: sim_proc.poll() is None and os.kill(sim_proc.pid, signal.SIGCONT))
        ports = found[0].group(1), found[1].group(1)
        answered_s, status, _, said = _pilot_stop_s(tmp_path, *ports, "answered", None)
        assert status == 0, said
        took_s, status, printed, said = _pilot_stop_s(tmp_path, *ports, "frozen", sim_proc)
    print(f"\nCtrl-C stopped the pilot in {answered_s:.2f} s on an answering simulator, "
          f"{took_s:.2f} s on a frozen one")
    # the pilot's two bounded waits, and 1.5 s for the two runs' scheduling to differ by
    bound_s = answered_s + STOP_S + CLOSE_S + 1.5
    assert status == 0, said
    assert took_s < bound_s, (f"stopped in {took_s:.1f} s, {answered_s:.1f} s on a simulator "
                              f"that answers, bound {bound_s:.1f} s; {said}")
    assert "skeye pilot: stopping" in printed
    assert ("skeye pilot: warning: stopped without the simulator: the simulator at "
            f"127.0.0.1:{ports[0]} did not close its end") in said, said
    assert "vehicle lost" not in said and "camera lost" not in said, said
