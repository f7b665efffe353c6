"""Position hold over the landing pad and autonomous landing on it: the control law.

How this works (the paper's method, section 5): every processed camera frame gives the pad
centre's offset in the level body frame (forward, right) and the height; the pilot predicts
it to the present from the frame's capture pose (skeye.pilot.pad_track) and calls the law
every control tick. While the offset is larger than the deadband (0.05 m by default) a PI
controller turns it into a horizontal velocity command towards the pad, limited in magnitude
to ``max_speed_m_s`` (0.3 m/s by default; the integral does not grow while the command is at
the limit). The gains come from the loop's delay (:func:`loop_gains`, docs/pilot.md "Vision
latency"). Inside the deadband the command is zero (the vehicle's own board then holds zero
velocity on its INS estimate, and the integrator keeps its value so a steady push stays
compensated). Vertically, HOLD keeps the height; LAND descends while the pad is within a cone
below the vehicle (offset at most ``descent_cone`` times the height above ``commit_height_m``,
or ``centre_tolerance_m``: the pad stays well inside any camera's view while the approach goes
on), correcting down to a tighter deadband (``landing_deadband_m``) so it aims at the
centre; it descends at ``high_descent_m_s`` above ``high_above_m``, ``descent_m_s`` below,
``final_descent_m_s`` below ``slow_below_m``, and commits to the touchdown below
``commit_height_m`` once centred (offset within ``centre_tolerance_m``), before the detector
loses the pad (it needs two rings).

Losing the pad (no detection for ``lost_after_s``), or never having seen it, makes the vehicle
stop, then climb (``search_climb_per_s`` of its height per second, so the view widens at a
steady rate, within ``search_climb_min_m_s``..``search_climb_max_m_s``, up to
``search_ceiling_m``; not at all while no height is known) to widen its view, and say so
through ``searching``. The law is pure: it takes observations, the vehicle's own height
estimate and the time, returns set-points; the pilot owns the clock, the camera and the link.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from skeye.errors import LocalProtocolError

VEHICLE_LAG_S = 1.0 / 2.8 + 1.0 / 7.0
"""How late the vehicle follows a velocity command (s): its velocity loop's time constant
(1 / velocity_gain, 2.8 /s) plus its attitude loop's (1 / angle_gain, 7 /s), the low-level
controller's gains (skeye.robots.params.ControllerParams, docs/physics.md). A first-order lag
of time constant T costs atan(w T) <= w T of phase, so counting it as a pure delay is safe."""
CONTROL_PERIOD_S = 0.05
"""The pilot's tick in lockstep (the control interface's 20 Hz); a command held for a tick
is half a tick late on average (zero-order hold)."""
PHASE_MARGIN_RAD = math.pi / 3
"""60 degrees: the usual design target for a well damped loop (about 10 % overshoot;
Astrom & Murray, Feedback Systems, 2008, section 11.3: phase margins of 30-60 degrees)."""
INTEGRAL_RATIO = 0.1
"""ki = INTEGRAL_RATIO * kp^2: the integrator's corner (ki/kp) a decade below the crossover
(kp), so it costs atan(0.1) = 5.7 degrees of phase there."""


def loop_gains(delay_s: float, phase_margin_rad: float = PHASE_MARGIN_RAD,
               integral_ratio: float = INTEGRAL_RATIO) -> tuple[float, float]:
    """PI gains (kp in (m/s)/m, ki in (m/s)/(m s)) for a position loop with ``delay_s`` of
    delay in it, from its phase margin.

    The loop: offset -> velocity command kp e + ki * integral(e) -> the vehicle's velocity (late by
    the delay) -> position (an integrator). Its open-loop gain is
    L(s) = (kp + ki/s) e^(-s delay) / s, crossing 1 at w = kp (for ki << kp^2), where the
    phase is -pi/2 - kp delay - atan(ki / kp^2). Asking for a phase margin phi gives
    kp = (pi/2 - phi - atan(ratio)) / delay; the delay margin (extra delay the loop takes
    before it oscillates) is then phi / kp.

    Raises:
        LocalProtocolError: a delay <= 0 or a margin that leaves no gain.
    """
    if not (math.isfinite(delay_s) and delay_s > 0):
        raise LocalProtocolError(f"pad hold: loop delay must be > 0 s, got {delay_s!r}")
    phase = math.pi / 2 - phase_margin_rad - math.atan(integral_ratio)
    if not phase > 0 or integral_ratio < 0:
        raise LocalProtocolError(f"pad hold: a phase margin of {phase_margin_rad} rad leaves "
                                 "no gain")
    kp = phase / delay_s
    return kp, integral_ratio * kp * kp


def design_delay(latency_s: float, predicted: bool) -> float:
    """The delay in the pad-hold loop: the vehicle's lag and half a tick; without the
    prediction also the vision latency and half the detection period (one detection per
    latency: the pipeline takes the next frame when it is done), both of which the
    prediction removes (it flies on the offset predicted to now from the estimator)."""
    delay = VEHICLE_LAG_S + CONTROL_PERIOD_S / 2
    if not predicted:
        delay += 1.5 * max(0.0, latency_s)
    return delay


_KP, _KI = loop_gains(design_delay(0.0, predicted=True))


@dataclass(frozen=True)
class PadHoldParams:
    """Gains and limits; deadband and speed limit come from PAD_MODE."""

    deadband_m: float = 0.05
    max_speed_m_s: float = 0.3
    kp: float = _KP  # (m/s) per m of offset: loop_gains(design_delay(...)), about 0.81
    ki: float = _KI  # (m/s) per m s: about 0.065
    integral_limit_m_s: float = 0.15
    high_descent_m_s: float = 0.5  # ArduPilot Copter's LAND_SPEED default (50 cm/s)
    high_above_m: float = 2.0
    descent_m_s: float = 0.25
    final_descent_m_s: float = 0.12
    slow_below_m: float = 0.8
    descent_cone: float = 0.2  # descend while offset <= 0.2 x (height - commit): 11 deg
    centre_tolerance_m: float = 0.08
    landing_deadband_m: float = 0.02  # LAND aims at the centre, not just near it
    commit_height_m: float = 0.5  # the detector needs two rings: lost below ~0.3 m
    lost_after_s: float = 0.5
    search_climb_per_s: float = 0.1  # the view widens 10 % per second
    search_climb_min_m_s: float = 0.1
    search_climb_max_m_s: float = 0.5
    search_ceiling_m: float = 8.0

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not (math.isfinite(value) and value >= 0):
                raise LocalProtocolError(f"pad hold: {name} must be a finite number >= 0")
        if self.max_speed_m_s <= 0:
            raise LocalProtocolError("pad hold: max_speed_m_s must be > 0")


@dataclass(frozen=True)
class PadSetpoint:
    """What the pilot should command now (body frame, SI), and why."""

    forward_m_s: float
    right_m_s: float
    up_m_s: float
    touchdown: bool = False  # LAND: hand over to the final landing
    searching: bool = False  # the pad is lost; climbing slowly to find it


class PadHoldLaw:
    """Stateful PI law for HOLD (mode 1) and LAND (mode 2)."""

    def __init__(self, params: PadHoldParams | None = None) -> None:
        self.p = params or PadHoldParams()
        self.reset()

    def reset(self) -> None:
        self._int_f = 0.0
        self._int_r = 0.0
        self._last_seen_s: float | None = None
        self._last_time_s: float | None = None
        self._height_m: float | None = None

    def update(
        self,
        time_s: float,
        found: bool,
        forward_m: float = 0.0,
        right_m: float = 0.0,
        height_m: float = 0.0,
        *,
        landing: bool = False,
        altitude_m: float | None = None,
    ) -> PadSetpoint:
        """One observation (or a frame without the pad) -> a velocity set-point.

        ``height_m`` is the detection's (above the pad); ``altitude_m`` the vehicle's own
        height estimate, which bounds the search when the pad is not seen (else the height of
        the last detection does)."""
        p = self.p
        if not math.isfinite(time_s):  # a NaN time would never count as lost: no search
            raise LocalProtocolError(f"pad hold: time must be finite, got {time_s!r}")
        if self._last_time_s is not None and time_s < self._last_time_s:
            # The clock went back (a restarted simulator under a re-attached pilot, or a
            # snapshot a little older than the last): no time passed, so the pad was last seen
            # as long before now as before the step. Kept on the old clock, a pad last seen at
            # 500 s left the vehicle holding still, never searching, until the new clock passed
            # 500 s; a full reset would drop the integral on a reordered snapshot.
            if self._last_seen_s is not None:
                self._last_seen_s += time_s - self._last_time_s
            self._last_time_s = time_s
        dt = 0.0 if self._last_time_s is None else time_s - self._last_time_s
        self._last_time_s = time_s
        if not found:
            if self._last_seen_s is None or time_s - self._last_seen_s >= p.lost_after_s:
                height = altitude_m if altitude_m is not None else self._height_m
                climb = 0.0  # no height known: no ceiling to stop at, so no climb
                if height is not None and height < p.search_ceiling_m:
                    climb = min(p.search_climb_max_m_s,
                                max(p.search_climb_min_m_s, p.search_climb_per_s * height))
                return PadSetpoint(0.0, 0.0, climb, searching=True)
            return PadSetpoint(0.0, 0.0, 0.0)  # a missed frame or two: keep still
        self._last_seen_s = time_s
        self._height_m = height_m
        offset = math.hypot(forward_m, right_m)
        deadband = min(p.deadband_m, p.landing_deadband_m) if landing else p.deadband_m
        if offset > deadband:
            lim = p.integral_limit_m_s / max(p.ki, 1e-9)
            int_f = min(lim, max(-lim, self._int_f + forward_m * dt))
            int_r = min(lim, max(-lim, self._int_r + right_m * dt))
            vf = p.kp * forward_m + p.ki * int_f
            vr = p.kp * right_m + p.ki * int_r
            speed = math.hypot(vf, vr)
            if speed > p.max_speed_m_s:
                # Saturated: the integral stays as it was (conditional integration, against
                # windup: a long approach at the speed limit would otherwise leave it pushing
                # past the pad; Astrom & Murray, Feedback Systems, section 10.4).
                vf = p.kp * forward_m + p.ki * self._int_f
                vr = p.kp * right_m + p.ki * self._int_r
                speed = math.hypot(vf, vr)
                if speed > p.max_speed_m_s:
                    vf, vr = vf * p.max_speed_m_s / speed, vr * p.max_speed_m_s / speed
            else:
                self._int_f, self._int_r = int_f, int_r
        else:
            vf = vr = 0.0
        up = 0.0
        if landing:
            if height_m <= p.commit_height_m and offset <= p.centre_tolerance_m:
                return PadSetpoint(vf, vr, -p.final_descent_m_s, touchdown=True)
            cone = max(p.centre_tolerance_m, p.descent_cone * (height_m - p.commit_height_m))
            if offset <= cone:
                if height_m < p.slow_below_m:
                    up = -p.final_descent_m_s
                elif height_m > p.high_above_m:
                    up = -p.high_descent_m_s
                else:
                    up = -p.descent_m_s
        return PadSetpoint(vf, vr, up)
