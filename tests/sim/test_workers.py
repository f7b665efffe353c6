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
    """A camera larger than the offscreen buffer cannot be rendered: in realtime mode the
    client used to get nothing at all; now it gets ERR {Command CAMERA} with the reason."""
    robots = small_camera_robot(tmp_path, width=1600, height=1200)  # offscreen is 800x600
    sim = Simulation(load_world("pad"), seed=3, robot_dirs=(robots,))
    with (
        SimulationRunner(sim, mode="realtime") as runner,
        CameraSystem(sim, FrameBuffer(), synchronous=False) as cameras,
        ControlServer(runner, port=0) as control,
    ):
        c = LineClient(control.port)
        c.expect("NFO")
        assert c.answer("INIT {ClassName smallcam} {Name R1} {Start Pad1}", "INIT").type == "RES"
        err = c.read_until(lambda m: m.type == "ERR" and m.get("Command") == "CAMERA",
                           timeout_s=120)[1]
        assert "framebuffer width 800" in (err.get("Reason") or ""), err
        assert cameras.error is not None
        assert runner.alive  # the physics goes on; only the camera is out
        c.close()
