"""The pilot's frame times (arrival, not capture) and the ground-truth pad source."""

from __future__ import annotations

import math
import threading
from types import SimpleNamespace
from typing import Any

import pytest

from skeye.errors import InvalidArgument
from skeye.pilot.vision import CAMERA_BELOW_CENTRE_M, PAD_SURFACE_M, PadVision


def vision(**kwargs: Any) -> PadVision:
    robot = SimpleNamespace(camera=SimpleNamespace(latest=None),
                            ground_truth=SimpleNamespace(latest=None))
    return PadVision(SimpleNamespace(), robot, threading.Lock(), fov_h_rad=1.309, **kwargs)


def test_a_frame_gets_the_time_it_arrived_not_its_capture_time() -> None:
    v = vision()
    v._note_arrival(7, 10.20)  # announced (seen by the pilot) at 10.20 s
    v._note_arrival(7, 10.25)  # seen again later: the first sighting counts
    assert v.frame_time_s(7, capture_s=10.08) == 10.20
    # a frame fetched before its announcement was seen: no earlier than the newest arrival
    assert v.frame_time_s(8, capture_s=10.15) == 10.20
    assert vision(frame_time="capture").frame_time_s(7, capture_s=10.08) == 10.08


def test_host_jitter_is_bounded_and_seeded() -> None:
    times = []
    for _ in range(2):
        v = vision(frame_jitter_s=0.02, seed=5)
        for frame in range(1, 200):
            v._note_arrival(frame, frame / 30.0)
        times.append([v.frame_time_s(f, 0.0) - f / 30.0 for f in range(150, 200)])
    assert times[0] == times[1]  # same seed, same jitter
    assert all(0.0 <= j <= 0.02 for j in times[0]) and max(times[0]) > 0.01


def test_bad_settings_are_refused() -> None:
    with pytest.raises(InvalidArgument, match="frame time"):
        vision(frame_time="exposure")
    with pytest.raises(InvalidArgument, match="jitter"):
        vision(frame_jitter_s=-0.1)
    with pytest.raises(InvalidArgument, match="pad source"):
        vision(pad_source="oracle")


def test_the_truth_source_is_a_perfect_detector_of_the_captured_moment() -> None:
    """Ground truth at the frame's capture, between the rows around it, stamped with the
    frame's time as a detection is. It took the last row kept at or before the frame's time
    (by default its arrival, a later moment than the image's; at any frame time a row up to
    the pilot's loop interval old): E1 read a 0.47 cm, 1.27 % height error for a perfect
    detector (``skeye validate E1 --quick --pad-source truth``), 0.05 cm, 0.14 % now."""
    v = vision(pad_source="truth")
    for k in range(10):  # ground truth every 0.02 s: north 1 m, east -0.5 m, yaw 90 deg
        v.robot.ground_truth.latest = SimpleNamespace(
            time_s=5.0 + 0.02 * k, position_ned_m=(1.0 + 0.01 * k, -0.5, -0.7 - 0.02 * k),
            rpy_rad=(0.0, 0.0, math.pi / 2))
        v._note_truth()
    obs = v._truth_observation(5.12, capture_s=5.05)  # captured at 5.05 s: north 1.025
    assert obs.found and obs.frame_time_s == 5.12
    # facing east: the pad (at the origin) is 0.5 m ahead and 1.025 m to the right
    assert obs.dx_m == pytest.approx(0.5) and obs.dy_m == pytest.approx(1.025)
    assert obs.height_m == pytest.approx(0.75 - CAMERA_BELOW_CENTRE_M - PAD_SURFACE_M)
    # before the first row kept, and after the last: the nearest
    assert v._truth_observation(4.9, capture_s=4.9).dy_m == pytest.approx(1.0)
    assert v._truth_observation(6.0, capture_s=6.0).dy_m == pytest.approx(1.09)
