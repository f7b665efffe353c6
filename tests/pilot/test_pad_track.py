"""The vision-latency prediction: a detection with an old capture time, shifted by the
vehicle's motion since then (from the estimator's pose history)."""

from __future__ import annotations

import math

import pytest

from skeye.errors import InvalidArgument
from skeye.pilot.pad_hold import PHASE_MARGIN_RAD, design_delay, loop_gains
from skeye.pilot.pad_track import Pose, PoseHistory, predict_offset


def pose(t: float, n: float = 0.0, e: float = 0.0, d: float = -1.5, yaw: float = 0.0) -> Pose:
    return Pose(t, n, e, d, 0.0, 0.0, yaw)


def test_a_detection_300_ms_old_is_shifted_by_the_motion_since_its_capture():
    history = PoseHistory(2.0)
    for i in range(31):  # flying north at 0.5 m/s for 0.3 s, 10 ms apart
        history.add(pose(10.0 + i * 0.01, n=0.5 * i * 0.01))
    then = history.at(10.0)
    now = history.latest
    assert then is not None and now is not None and now.north_m == pytest.approx(0.15)
    # Captured at 10.0 s: the pad 0.4 m ahead; now it is 0.15 m closer.
    forward, right, height = predict_offset(0.4, 0.1, 1.5, then, now)
    assert (forward, right, height) == pytest.approx((0.25, 0.1, 1.5))


def test_the_history_interpolates_between_poses_and_turns_with_the_heading():
    history = PoseHistory(2.0)
    history.add(pose(0.0, n=0.0, e=0.0, yaw=math.radians(170)))
    history.add(pose(0.1, n=0.1, e=0.2, d=-1.4, yaw=math.radians(-170)))  # across +-180
    mid = history.at(0.05)
    assert mid is not None
    assert (mid.north_m, mid.east_m, mid.down_m) == pytest.approx((0.05, 0.1, -1.45))
    assert abs(mid.yaw_rad) == pytest.approx(math.pi)
    # The pad 1 m ahead when facing north; after a 90 deg turn to the right (east) with no
    # motion it is 1 m to the left; after descending 0.2 m it is 0.2 m nearer below.
    then, now = pose(0.0, yaw=0.0), pose(0.3, d=-1.3, yaw=math.pi / 2)
    assert predict_offset(1.0, 0.0, 1.5, then, now) == pytest.approx((0.0, -1.0, 1.3))


def test_a_capture_older_than_the_history_cannot_be_predicted():
    history = PoseHistory(1.0)
    for i in range(300):
        history.add(pose(i * 0.01))
    assert history.at(0.5) is None  # 2.99 s now: only the last second is kept
    assert history.at(2.5) is not None
    assert history.at(5.0) == history.latest  # later than the newest: the newest
    with pytest.raises(InvalidArgument):
        PoseHistory(0.0)


def test_gains_come_from_the_loop_delay_with_the_phase_margin_asked():
    delay = design_delay(0.0, predicted=True)
    kp, ki = loop_gains(delay)
    # The phase at the crossover (w = kp) leaves the 60 degree margin.
    phase = -math.pi / 2 - kp * delay - math.atan(ki / kp**2)
    assert math.pi + phase == pytest.approx(PHASE_MARGIN_RAD)
    # Without the prediction the latency is in the loop: lower gains for the same margin;
    # with it the latency does not change them.
    slow = loop_gains(design_delay(0.3, predicted=False))[0]
    assert slow < kp and loop_gains(design_delay(0.3, predicted=True))[0] == kp
