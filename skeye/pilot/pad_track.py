"""Vision latency in the pilot: the vehicle's recent poses, and a detection predicted to now.

How this works: a camera frame shows the pad as it was at the frame's capture time, and the
detector's answer arrives (is applied) one processing time later; meanwhile the vehicle moved.
:class:`PoseHistory` keeps the onboard estimate's poses (the INS stream, the airframe
snapshot) for the last ``span_s`` seconds; :func:`predict_offset` takes a detection (the pad
centre's offset in the level body frame at capture time, and the height) with the pose at
capture time and the pose now, places the pad in the estimate's world frame (NED) and returns
its offset from the vehicle now. The pad does not move, so only the vehicle's own motion since
the capture (as its estimator saw it) is needed: the shift is exact up to the estimator's error
over the latency. :class:`PadTrack` keeps the pad's world position from the newest detection so
the pilot predicts the offset on every control tick, not just when a detection arrives.
"""

from __future__ import annotations

import bisect
import math
import threading
from dataclasses import dataclass

from skeye.errors import InvalidArgument


@dataclass(frozen=True)
class Pose:
    """One onboard-estimate pose: NED position (m) and roll, pitch, yaw (rad), at ``time_s``."""

    time_s: float
    north_m: float
    east_m: float
    down_m: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float


def _lerp_angle(a: float, b: float, f: float) -> float:
    d = math.remainder(b - a, math.tau)
    return math.remainder(a + f * d, math.tau)


class PoseHistory:
    """The estimate's poses of the last ``span_s`` seconds (thread-safe: the control loop adds,
    the vision worker reads the attitude at a frame's capture time)."""

    def __init__(self, span_s: float = 2.0) -> None:
        if not (math.isfinite(span_s) and span_s > 0):
            raise InvalidArgument(f"pose history span must be > 0 s, got {span_s!r}")
        self.span_s = span_s
        self._times: list[float] = []
        self._poses: list[Pose] = []
        self._lock = threading.Lock()

    def add(self, pose: Pose) -> None:
        """Record a pose; one older than the newest is ignored (the stream only goes forward),
        one at the same time replaces it."""
        with self._lock:
            if self._times and pose.time_s <= self._times[-1]:
                if pose.time_s == self._times[-1]:
                    self._poses[-1] = pose
                return
            self._times.append(pose.time_s)
            self._poses.append(pose)
            cut = bisect.bisect_left(self._times, pose.time_s - self.span_s)
            if cut > 0:
                del self._times[:cut]
                del self._poses[:cut]

    @property
    def latest(self) -> Pose | None:
        with self._lock:
            return self._poses[-1] if self._poses else None

    def at(self, time_s: float) -> Pose | None:
        """The pose at ``time_s``, interpolated between the two recorded around it; the newest
        for a later time; None when ``time_s`` is before the history (too old to predict from)."""
        with self._lock:
            times, poses = self._times, self._poses
            if not times or time_s < times[0] - 1e-9:
                return None
            i = bisect.bisect_left(times, time_s)
            if i >= len(times):
                return poses[-1]
            if times[i] == time_s or i == 0:
                return poses[i]
            a, b = poses[i - 1], poses[i]
        f = (time_s - a.time_s) / (b.time_s - a.time_s)
        return Pose(
            time_s,
            a.north_m + f * (b.north_m - a.north_m),
            a.east_m + f * (b.east_m - a.east_m),
            a.down_m + f * (b.down_m - a.down_m),
            _lerp_angle(a.roll_rad, b.roll_rad, f),
            _lerp_angle(a.pitch_rad, b.pitch_rad, f),
            _lerp_angle(a.yaw_rad, b.yaw_rad, f),
        )


@dataclass(frozen=True)
class PadFix:
    """The pad's position in the estimate's world frame, from one detection."""

    capture_s: float  # the frame's capture time
    north_m: float
    east_m: float
    down_m: float  # the pad's surface (vehicle's down + height at capture)


def locate_pad(forward_m: float, right_m: float, height_m: float, then: Pose) -> PadFix:
    """Where a detection puts the pad: its level-body offset at capture, rotated by the heading
    then and added to the position then."""
    c, s = math.cos(then.yaw_rad), math.sin(then.yaw_rad)
    return PadFix(
        then.time_s,
        then.north_m + c * forward_m - s * right_m,
        then.east_m + s * forward_m + c * right_m,
        then.down_m + height_m,
    )


def offset_now(pad: PadFix, now: Pose) -> tuple[float, float, float]:
    """The pad's level-body offset (forward, right) and height seen from the pose ``now``."""
    dn, de = pad.north_m - now.north_m, pad.east_m - now.east_m
    c, s = math.cos(now.yaw_rad), math.sin(now.yaw_rad)
    return c * dn + s * de, -s * dn + c * de, pad.down_m - now.down_m


def predict_offset(forward_m: float, right_m: float, height_m: float, then: Pose,
                   now: Pose) -> tuple[float, float, float]:
    """A detection made at ``then`` (offset forward, right, height) as it stands at ``now``:
    shifted and turned by the vehicle's motion between the two poses."""
    return offset_now(locate_pad(forward_m, right_m, height_m, then), now)
