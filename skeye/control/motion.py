"""Motion control: PI controllers and the motions built on them (sans-IO: no sockets, no clock).

How this works: a motion is fed one :class:`NavState` (the feedback sensor's latest reading)
per control tick and answers a :class:`DriveCommand`, USARSim's aerial ``DRIVE`` velocity
set-points (forward/right in the frame that follows the robot's yaw, up, yaw rate), plus whether
it is done. Position motions run four PI controllers, as the paper's design has them: linear
(forward), lateral (right), vertical (up) and angular (yaw). Each PI clamps its integral
(anti-windup: it also stops integrating while its output saturates in the error's direction) and
its output; the horizontal speed is limited as a vector so diagonal moves are not faster.

Arrival: a position motion is done when the position error is within its tolerance and the
speed below ``settle_speed_m_s``, either at this tick or averaged over the last
``settle_window_s`` (the error's RMS then within twice the tolerance and the mean speed below
twice the settle speed, so a swing through the target does not count). The second form is for
a vehicle flying on its own estimate (the board's onboard estimator): hovering over the
target, that estimate jitters by centimetres about it (hover on the Hummingbird's sensors, pad
world: error from the target 4.8 cm at the median, 8.8 cm at the 90th percentile, speed
7.8 cm/s at the median; docs/physics.md), so the instantaneous test would pass only now and
then while the vehicle is, on average, there.

Invariants: time is an argument (``state.time_s``), so a motion behaves the same at any
wall-clock speed; a position motion is done only when the position error is within its
tolerance and the speed has settled, at one tick or on average over the settle window; angles
are compared wrapped to (-pi, pi].
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Final

from skeye.errors import ConfigError, InvalidArgument, LocalProtocolError, SkeyeError
from skeye.values import is_finite_number, is_number
from skeye.wire.sim_messages import Drive

from .clock import MAX_RUN_FOR_S
from .sensors import Vec3, wrap_pi


class MotionFailed(SkeyeError):
    """A motion could not finish (it ran out of time, or was rejected or cancelled)."""


class MotionCancelled(MotionFailed):
    """The motion was replaced by another one or cancelled before it finished."""


@dataclass(frozen=True)
class PIGains:
    """One PI controller: ``out = kp * e + ki * integral(e)``, both clamped."""

    kp: float
    ki: float
    integral_limit: float
    """Largest ``|ki * integral(e)|`` contribution (anti-windup)."""
    integral_zone: float = math.inf
    """Integrate only while ``|e|`` is below this: no wind-up during a long approach."""

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "integral_limit"):
            value = getattr(self, name)
            if not (is_finite_number(value) and value >= 0):
                raise ConfigError(f"PI gains: {name} must be a finite number >= 0, got {value!r}")
        zone = self.integral_zone  # inf, the default: integrate at any error
        if not (is_number(zone) and zone == zone and zone >= 0):  # zone == zone: not NaN
            raise ConfigError(f"PI gains: integral_zone must be a number >= 0 (inf: any error), "
                              f"got {zone!r}")


@dataclass(frozen=True)
class MotionConfig:
    """Gains, limits and tolerances of the client-side motion control.

    The outer loop commands velocities; the vehicle's own board closes the velocity loop, so the
    gains are per second ((m/s)/m and (rad/s)/rad).
    """

    linear: PIGains = field(default_factory=lambda: PIGains(1.0, 0.3, 0.1, 0.2))
    lateral: PIGains = field(default_factory=lambda: PIGains(1.0, 0.3, 0.1, 0.2))
    vertical: PIGains = field(default_factory=lambda: PIGains(1.2, 0.3, 0.2, 0.2))
    angular: PIGains = field(default_factory=lambda: PIGains(1.5, 0.1, 0.1, 0.2))
    max_speed_m_s: float = 1.0
    max_climb_m_s: float = 0.8
    max_yaw_rate_rad_s: float = 1.0
    tolerance_m: float = 0.05
    yaw_tolerance_rad: float = 0.05
    settle_speed_m_s: float = 0.08
    """A position motion is done once within tolerance *and* slower than this."""
    settle_window_s: float = 1.0
    """... now, or on the position error and velocity averaged over this much sim time
    (with their spread within twice the tolerance and settle speed)."""
    land_speed_m_s: float = 0.4
    take_off_speed_m_s: float = 0.6
    control_rate_hz: float = 20.0
    timeout_margin_s: float = 10.0
    """Sim-time budget of a motion beyond its distance over its speed limit."""

    def __post_init__(self) -> None:
        for name in (
            "max_speed_m_s",
            "max_climb_m_s",
            "max_yaw_rate_rad_s",
            "tolerance_m",
            "yaw_tolerance_rad",
            "settle_speed_m_s",
            "settle_window_s",
            "land_speed_m_s",
            "take_off_speed_m_s",
            "control_rate_hz",
            "timeout_margin_s",
        ):
            value = getattr(self, name)
            if not (is_finite_number(value) and value > 0):
                raise ConfigError(f"MotionConfig.{name} must be a positive number, got {value!r}")


MIN_WINDOW_SAMPLES: Final = 5
"""Fewest control ticks an averaged arrival test rests on (a gap in the feedback leaves fewer)."""


class PIController:
    """A PI controller with a clamped integral and output (anti-windup)."""

    def __init__(self, gains: PIGains) -> None:
        self.gains = gains
        self.integral = 0.0

    def reset(self) -> None:
        self.integral = 0.0

    def update(self, error: float, dt_s: float, limit: float) -> float:
        """The output for ``error`` after ``dt_s`` seconds, clamped to ``[-limit, limit]``."""
        g = self.gains
        p = g.kp * error
        i_term = g.ki * self.integral
        unclamped = p + i_term
        saturated = abs(unclamped) >= limit and unclamped * error > 0
        if g.ki > 0 and dt_s > 0 and not saturated and abs(error) < g.integral_zone:
            self.integral += error * dt_s
            bound = g.integral_limit / g.ki
            self.integral = max(-bound, min(bound, self.integral))
        out = p + g.ki * self.integral
        return max(-limit, min(limit, out))


@dataclass(frozen=True)
class DriveCommand:
    """Velocity set-points for ``DRIVE``: body-yaw frame forward/right, up, yaw rate."""

    forward_m_s: float = 0.0
    right_m_s: float = 0.0
    up_m_s: float = 0.0
    yaw_rate_rad_s: float = 0.0
    board_mode: str | None = None  # "gps": the board's GPS mode (DRIVE {BoardMode gps})

    def to_message(self) -> Drive:
        """The velocity-form ``DRIVE`` of these set-points (the wire table spells it)."""
        return Drive(
            forward_m_s=self.forward_m_s,
            right_m_s=self.right_m_s,
            up_m_s=self.up_m_s,
            yaw_rate_rad_s=self.yaw_rate_rad_s,
            board_mode=self.board_mode,
        )


STOP = DriveCommand()


@dataclass(frozen=True)
class NavState:
    """What motion control knows at one tick: position NED, yaw, velocity NED, sim time."""

    time_s: float
    position_ned_m: Vec3
    yaw_rad: float
    velocity_ned_m_s: Vec3 | None = None

    @property
    def altitude_m(self) -> float:
        return -self.position_ned_m[2]


@dataclass(frozen=True)
class Target:
    """Where a position motion goes: world NED position and, optionally, a heading."""

    position_ned_m: Vec3
    yaw_rad: float | None = None


def world_to_body(north: float, east: float, yaw_rad: float) -> tuple[float, float]:
    """A horizontal NED vector in the frame that follows the yaw: (forward, right)."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return c * north + s * east, -s * north + c * east


def body_to_world(forward: float, right: float, yaw_rad: float) -> tuple[float, float]:
    """(forward, right) in the yaw-following frame as (north, east)."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return c * forward - s * right, s * forward + c * right


class Motion:
    """Base of motions: one ``update`` per control tick; ``done`` once finished."""

    name = "motion"
    holds = False  # True for motions that never finish by themselves (position hold)

    def __init__(self) -> None:
        self.done = False
        self.error: SkeyeError | None = None
        self.started_s: float | None = None
        self.sim_timeout_s: float | None = None

    def update(self, state: NavState, landed: bool, armed: bool = True) -> DriveCommand:
        if self.started_s is None:
            self.started_s = state.time_s
        if (
            self.sim_timeout_s is not None
            and state.time_s - self.started_s > self.sim_timeout_s
            and not self.done
        ):
            raise MotionFailed(
                f"{self.name} not done after {self.sim_timeout_s:.1f} s of sim time"
            )
        return self._update(state, landed, armed)

    def _update(self, state: NavState, landed: bool, armed: bool) -> DriveCommand:
        raise NotImplementedError


class GoTo(Motion):
    """Fly to a world position (and heading) with the four PI controllers; hold it after.

    Args:
        target: where to go.
        config: gains and limits.
        max_speed_m_s / max_climb_m_s / tolerance_m: per-motion overrides of the config.
        hold: keep controlling after arriving (``done`` still becomes True on arrival).
    """

    name = "fly_to"

    def __init__(
        self,
        target: Target,
        config: MotionConfig,
        *,
        max_speed_m_s: float | None = None,
        max_climb_m_s: float | None = None,
        tolerance_m: float | None = None,
        name: str = "fly_to",
        start: NavState | None = None,
    ) -> None:
        super().__init__()
        self.name = name
        self.target = target
        self.config = config
        self.max_speed_m_s = config.max_speed_m_s if max_speed_m_s is None else max_speed_m_s
        self.max_climb_m_s = config.max_climb_m_s if max_climb_m_s is None else max_climb_m_s
        self.tolerance_m = config.tolerance_m if tolerance_m is None else tolerance_m
        for label, value in (
            ("max_speed_m_s", self.max_speed_m_s),
            ("max_climb_m_s", self.max_climb_m_s),
            ("tolerance_m", self.tolerance_m),
        ):
            if not (is_finite_number(value) and value > 0):
                raise LocalProtocolError(f"{name}: {label} must be a positive number, got {value}")
        for v in target.position_ned_m:
            if not is_finite_number(v):
                raise LocalProtocolError(f"{name}: target position (north, east, down) "
                                         f"{target.position_ned_m} m is not finite")
        if target.yaw_rad is not None and not is_finite_number(target.yaw_rad):
            raise LocalProtocolError(f"{name}: yaw_rad {target.yaw_rad!r} is not finite")
        self.linear = PIController(config.linear)
        self.lateral = PIController(config.lateral)
        self.vertical = PIController(config.vertical)
        self.angular = PIController(config.angular)
        self._last_s: float | None = None
        self.error_m = math.inf
        # (time, error north/east/up, velocity north/east/down) over the last settle window
        self._recent: deque[tuple[float, float, float, float, float, float, float]] = deque()
        if start is not None:
            dn, de, dd = (t - p for t, p in zip(target.position_ned_m, start.position_ned_m,
                                                strict=True))
            horizontal = math.hypot(dn, de) / self.max_speed_m_s
            vertical = abs(dd) / self.max_climb_m_s
            self.sim_timeout_s = 2.0 * max(horizontal, vertical) + config.timeout_margin_s

    def _update(self, state: NavState, landed: bool, armed: bool) -> DriveCommand:
        dt = 0.0 if self._last_s is None else max(0.0, state.time_s - self._last_s)
        self._last_s = state.time_s
        tn, te, td = self.target.position_ned_m
        pn, pe, pd = state.position_ned_m
        en, ee, e_up = tn - pn, te - pe, pd - td
        self.error_m = math.sqrt(en * en + ee * ee + e_up * e_up)
        e_fwd, e_right = world_to_body(en, ee, state.yaw_rad)
        forward = self.linear.update(e_fwd, dt, self.max_speed_m_s)
        right = self.lateral.update(e_right, dt, self.max_speed_m_s)
        speed = math.hypot(forward, right)
        if speed > self.max_speed_m_s:
            forward, right = (v * self.max_speed_m_s / speed for v in (forward, right))
        up = self.vertical.update(e_up, dt, self.max_climb_m_s)
        e_yaw = 0.0 if self.target.yaw_rad is None else wrap_pi(self.target.yaw_rad - state.yaw_rad)
        yaw_rate = self.angular.update(e_yaw, dt, self.config.max_yaw_rate_rad_s)
        vel = state.velocity_ned_m_s
        settled = vel is None or math.sqrt(sum(v * v for v in vel)) < self.config.settle_speed_m_s
        on_average = self._settled_on_average(state.time_s, (en, ee, e_up), vel)
        if abs(e_yaw) <= self.config.yaw_tolerance_rad and (
            (self.error_m <= self.tolerance_m and settled) or on_average
        ):
            self.done = True
        return DriveCommand(forward, right, up, yaw_rate)

    def _settled_on_average(self, time_s: float, error: Vec3, vel: Vec3 | None) -> bool:
        """Whether, over the last settle window (once that much time has been seen, in at
        least ``MIN_WINDOW_SAMPLES`` ticks), the mean error vector is within the tolerance and
        the mean velocity below the settle speed, while the error's RMS stays within twice
        the tolerance and the mean speed below twice the settle speed: jitter about the
        target passes, a swing through it does not."""
        recent = self._recent
        vn, ve, vd = vel if vel is not None else (0.0, 0.0, 0.0)
        recent.append((time_s, error[0], error[1], error[2], vn, ve, vd))
        start = time_s - self.config.settle_window_s
        while len(recent) > 1 and recent[1][0] <= start + 1e-9:
            recent.popleft()
        n = len(recent)
        if recent[0][0] > start + 1e-9 or n < MIN_WINDOW_SAMPLES:
            return False  # not a whole window yet
        mean = [sum(entry[i] for entry in recent) / n for i in range(1, 7)]
        error_ms = sum(e[1] * e[1] + e[2] * e[2] + e[3] * e[3] for e in recent) / n
        speed = sum(math.sqrt(e[4] * e[4] + e[5] * e[5] + e[6] * e[6]) for e in recent) / n
        tol, settle = self.tolerance_m, self.config.settle_speed_m_s
        return (
            math.sqrt(mean[0] ** 2 + mean[1] ** 2 + mean[2] ** 2) <= tol
            and math.sqrt(error_ms) <= 2.0 * tol
            and math.sqrt(mean[3] ** 2 + mean[4] ** 2 + mean[5] ** 2) < settle
            and speed < 2.0 * settle
        )


class Hold(GoTo):
    """Hold a position (and heading): a GoTo that never finishes by itself."""

    holds = True

    def __init__(self, target: Target, config: MotionConfig) -> None:
        super().__init__(target, config, name="hold")
        self.done = True  # nothing to wait for

    def _update(self, state: NavState, landed: bool, armed: bool) -> DriveCommand:
        command = super()._update(state, landed, armed)
        self.done = True
        return command


class Velocity(Motion):
    """Hold velocity set-points for ``duration_s`` of sim time (or hand them over at once)."""

    name = "set_velocity"

    def __init__(self, command: DriveCommand, duration_s: float | None) -> None:
        super().__init__()
        if duration_s is not None and not (is_finite_number(duration_s)
                                           and 0 <= duration_s <= MAX_RUN_FOR_S):
            raise InvalidArgument(f"set_velocity: duration_s must be a finite number "
                                  f"0..{MAX_RUN_FOR_S:g} s (a day of sim time at most), got "
                                  f"{duration_s!r}")
        self.command = command
        self.duration_s = duration_s
        if duration_s is not None:
            self.sim_timeout_s = duration_s + 1.0

    def _update(self, state: NavState, landed: bool, armed: bool) -> DriveCommand:
        assert self.started_s is not None
        if self.duration_s is None or state.time_s - self.started_s >= self.duration_s - 1e-9:
            self.done = True
        return self.command


class Land(Motion):
    """Descend at the landing speed holding the horizontal position; done once landed.

    Done when the vehicle reports itself landed and disarmed (its board stops the motors one
    second after touch-down).
    """

    name = "land"

    def __init__(self, config: MotionConfig, start: NavState) -> None:
        super().__init__()
        self.config = config
        n, e, _ = start.position_ned_m
        self.hold = GoTo(Target((n, e, start.position_ned_m[2]), None), config, name="land")
        self.sim_timeout_s = max(0.0, start.altitude_m) * 3.0 / config.land_speed_m_s + 15.0

    def _update(self, state: NavState, landed: bool, armed: bool) -> DriveCommand:
        if landed:
            if not armed:
                self.done = True
            return DriveCommand(0.0, 0.0, -self.config.land_speed_m_s / 2, 0.0)
        command = self.hold._update(state, landed, armed)
        return DriveCommand(command.forward_m_s, command.right_m_s, -self.config.land_speed_m_s,
                            command.yaw_rate_rad_s)
