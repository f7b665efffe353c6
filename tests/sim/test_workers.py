"""No worker thread dies silently (issue 15, point 12): the shared Worker helper, and the
simulator's render thread, whose failures now reach the clients in realtime mode too (the
engine's are in test_hardening.py)."""

from __future__ import annotations

import queue
import threading
from pathlib import Path

import pytest

from skeye.errors import SkeyeError
from skeye.sim.cameras import CameraSystem
from skeye.sim.engine import Simulation
from skeye.sim.image_server import FrameBuffer
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.world import load_world
from skeye.workers import Worker, WorkerFailed
from tests.sim.conftest import LineClient
from tests.sim.test_cameras import small_camera_robot


def test_a_worker_exception_reaches_its_owner_three_ways() -> None:
    errors: queue.Queue[tuple[str, BaseException]] = queue.Queue()
    told: list[BaseException] = []
    told_event = threading.Event()

    def on_error(exc: BaseException) -> None:
        told.append(exc)
        told_event.set()

    def work(x: int) -> None:
        raise ZeroDivisionError(x)

    worker = Worker(work, "test-worker", on_error=on_error, errors=errors, args=(7,)).start()
    assert told_event.wait(30)
    name, exc = errors.get(timeout=30)
    assert name == "test-worker" and isinstance(exc, ZeroDivisionError)
    assert told == [exc]
    worker.join(30)
    assert not worker.alive
    with pytest.raises(WorkerFailed, match="test-worker failed: ZeroDivisionError: 7"):
        worker.check()
    assert isinstance(WorkerFailed("w", exc), SkeyeError)


def test_a_failing_callback_is_logged_not_raised() -> None:
    def bad_callback(exc: BaseException) -> None:
        raise RuntimeError("callback bug")

    worker = Worker(lambda: 1 / 0, "w2", on_error=bad_callback).start()
    worker.join(30)
    assert isinstance(worker.error, ZeroDivisionError)


def test_realtime_render_failure_reaches_the_robot_client(tmp_path: Path) -> None:
    """A camera that cannot be rendered: in realtime mode the client used to get nothing at
    all; now it gets ERR {Command CAMERA} with the reason. (The camera larger than the
    offscreen buffer was spawned in-process before the cameras were attached: over the
    protocol such a robot is refused at INIT, the next test.)"""
    robots = small_camera_robot(tmp_path, width=1600, height=1200)  # offscreen is 800x600
    sim = Simulation(load_world("pad"), seed=3, robot_dirs=(robots,))
    sim.spawn("smallcam", name="R0", sink=lambda events: None, location_ned_m=(3.0, 0.0, 0.0))
    with (
        SimulationRunner(sim, mode="realtime") as runner,
        CameraSystem(sim, FrameBuffer(), synchronous=False) as cameras,
        ControlServer(runner, port=0) as control,
    ):
        c = LineClient(control.port)
        c.expect("NFO")
        assert c.answer("INIT {ClassName hummingbird} {Name R1} {Start Pad1}", "INIT").type == "RES"
        err = c.read_until(lambda m: m.type == "ERR" and m.get("Command") == "CAMERA",
                           timeout_s=120)[1]
        assert "camera R0/Down: a 1600x1200 image does not fit the offscreen buffer" in (
            err.get("Reason") or ""), err
        assert cameras.error is not None
        assert runner.alive  # the physics goes on; only the camera is out
        c.close()


def test_a_camera_too_large_is_refused_at_init_and_the_others_fly_on(tmp_path: Path) -> None:
    """One client's robot file with a camera larger than the offscreen buffer stopped every
    other client's camera robot (the camera system's error was one for all) and its own INIT
    was answered OK. Its INIT is refused naming the buffer; the others are not told anything
    and go on."""
    robots = small_camera_robot(tmp_path, width=1600, height=1200)  # offscreen is 800x600
    sim = Simulation(load_world("pad"), seed=3, robot_dirs=(robots,))
    with (
        SimulationRunner(sim, mode="lockstep") as runner,
        CameraSystem(sim, FrameBuffer(), synchronous=True) as cameras,
        ControlServer(runner, port=0) as control,
    ):
        a, b = LineClient(control.port), LineClient(control.port)
        a.expect("NFO")
        b.expect("NFO")
        assert a.answer("INIT {ClassName hummingbird} {Name R1} {Start Pad1}", "INIT").type == "RES"
        refused = b.answer("INIT {ClassName smallcam} {Name R2} {Location 3,0,0}", "INIT")
        assert refused.type == "ERR", refused
        assert "R2/Down: a 1600x1200 image does not fit the offscreen buffer" in (
            refused.get("Reason") or ""), refused
        assert b.answer("INIT {ClassName hummingbird} {Name R2} {Location 3,0,0}",
                        "INIT").type == "RES"  # the same client, a camera that fits
        answer = a.answer("STEP {Count 200}", "STEP")
        assert answer.type == "RES", answer
        assert a.answer("PING {Id 1}", "PING").type == "RES"
        assert cameras.error is None and runner.alive
        a.close()
        b.close()
