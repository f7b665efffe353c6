"""The vision in lockstep: the loop waits for the detector's result on each frame, however long
it takes, so a flight never depends on the machine's load; a detector that hangs is an error
naming the frame, never a silently different flight."""

from __future__ import annotations

import threading
from types import SimpleNamespace

import numpy as np
import pytest

from skeye.errors import SkeyeError
from skeye.gym.board import FrameImage, FrameInfo
from skeye.pilot.boards import OnboardBoards
from skeye.pilot.policy import ObservedPad
from skeye.pilot.vision import LOCKSTEP_WAIT_S, PadVision
from skeye.sim.render import RENDER_TIMEOUT_S
from tests.pilot.fake_airframe import FakeAirframe

HANG_GUARD_S = 60.0
"""A bound on how long a broken test may hang, never reached by a passing one."""


class GatedCamera:
    """One frame (number 1, captured at 0 s), whose fetch waits until the test opens the
    gate: a detector as slow as the test wants it, with no clock involved."""

    def __init__(self) -> None:
        self.latest = FrameInfo(1, 0.0)
        self.gate = threading.Event()
        self.fetching = threading.Event()  # the worker has started on the frame

    def image(self) -> FrameImage:
        self.fetching.set()
        if not self.gate.wait(HANG_GUARD_S):
            raise SkeyeError("the test never opened the gate")
        return FrameImage(1, 0.0, np.zeros((48, 64, 3), np.uint8))


class MovingCamera:
    """A camera whose newest frame moves on at every look, as one taking frames on its own
    clock does: the pilot's loop and its vision's worker never see the same newest frame."""

    def __init__(self) -> None:
        self.looks = 0
        self.fetched: list[int] = []

    @property
    def latest(self) -> FrameInfo:
        self.looks += 1
        return FrameInfo(self.looks, 0.01 * self.looks)

    def image(self) -> FrameImage:
        self.fetched.append(self.looks)  # the newest frame now
        return FrameImage(self.looks, 0.01 * self.looks, np.zeros((48, 64, 3), np.uint8))


def lockstep_vision(camera: GatedCamera | MovingCamera,
                    wait_s: float) -> tuple[PadVision, ObservedPad]:
    pad = ObservedPad()
    boards = OnboardBoards(FakeAirframe(), pad=pad)
    robot = SimpleNamespace(camera=camera, ins=SimpleNamespace(latest=None))
    return PadVision(boards, robot, threading.Lock(), fov_h_rad=1.309, lockstep=True,
                     lockstep_wait_s=wait_s), pad


def test_a_detector_past_the_lockstep_wait_is_an_error_not_another_flight() -> None:
    # Until 2026-11-28 the loop waited at most lockstep_wait_s (5 s) and then flew on without
    # the frame's detection, which it applied a period or more later: on a loaded machine a
    # webcam episode's first frame took more than 5 s and PadLanding-v0's seed 100 landed
    # 4.3 cm from the pad instead of 5.4.
    camera = GatedCamera()
    vision, pad = lockstep_vision(camera, wait_s=0.2)
    try:
        with pytest.raises(SkeyeError, match=r"frame 1 .*0\.2 s"):
            vision.step()
        assert pad.latest is None  # nothing applied, nothing flown on
        camera.gate.set()  # the detector finishes: the next step applies the frame
        vision.step()
        assert pad.latest is not None and pad.latest.frame_time_s == 0.0
        assert not pad.latest.found  # a black frame
    finally:
        camera.gate.set()
        vision.close()


def test_in_lockstep_the_worker_takes_the_frame_the_loop_let_it_take() -> None:
    """The loop lets the detector take the newest frame it sees and waits for it; the worker
    takes that frame, not the newest it would see itself. Until 2026-11-28 the worker looked
    again and waited for the loop to let it take that newer frame, while the loop waited for
    the worker: with a ``sim://`` camera whose two looks disagreed, a pad flight stopped for
    the lockstep wait (120 s) and then flew without the pad."""
    camera = MovingCamera()
    vision, _ = lockstep_vision(camera, wait_s=HANG_GUARD_S)
    try:
        vision.step()  # the loop looked once (frame 1), then waited for its detection
        assert (camera.looks, camera.fetched, vision.stats.frames) == (1, [1], 1)
    finally:
        vision.close()


def test_closing_the_vision_releases_a_loop_waiting_on_a_hung_detector() -> None:
    camera = GatedCamera()
    vision, _ = lockstep_vision(camera, wait_s=HANG_GUARD_S)
    errors: list[BaseException] = []

    def step() -> None:
        try:
            vision.step()
        except BaseException as exc:  # reported by the assertion below
            errors.append(exc)

    loop = threading.Thread(target=step, name="test-loop", daemon=True)
    try:
        loop.start()
        assert camera.fetching.wait(HANG_GUARD_S), "the worker never took the frame"
        vision.close(timeout_s=0.1)  # the worker stays stuck in its fetch: not waited for
        loop.join(HANG_GUARD_S / 2)
        assert not loop.is_alive(), "close() left the loop waiting on the hung detector"
        assert errors == []
    finally:
        camera.gate.set()


def test_the_lockstep_wait_outlasts_a_frames_render() -> None:
    # In skeye.gym a frame's fetch includes its render, which the camera system gives up on
    # only after RENDER_TIMEOUT_S, and a lockstep pilot's image request waits at least
    # LOCKSTEP_IMAGE_TIMEOUT_S, itself past the render's limit: a shorter wait would stop a
    # flight that would go on.
    from skeye.control.connection import LOCKSTEP_IMAGE_TIMEOUT_S

    assert LOCKSTEP_WAIT_S > LOCKSTEP_IMAGE_TIMEOUT_S > RENDER_TIMEOUT_S
    assert PadVision(SimpleNamespace(), SimpleNamespace(), threading.Lock(),
                     fov_h_rad=1.309).lockstep_wait_s == LOCKSTEP_WAIT_S
