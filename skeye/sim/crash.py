"""Crash detection: when a simulated vehicle has crashed, and why (docs/protocols/simulator.md,
"Crashes").

How this works: every board tick the robot hands its ground-truth attitude, velocity and
ground contact to its :class:`CrashDetector`, which answers None or the crash's cause, once.
Two rules, both on the true state (a crash is what happened to the vehicle, not what its
estimator believes):

- **Attitude** (PX4's failure detector, "Attitude Trigger"): roll or pitch (ZYX Euler angles)
  beyond ``FD_FAIL_R`` / ``FD_FAIL_P`` = 60 deg, continuously for ``FD_FAIL_R_TTRI`` /
  ``FD_FAIL_P_TTRI`` = 0.3 s, PX4's defaults. PX4 then terminates the flight (motors off); so
  does the simulated board. It applies with the motors off too: a vehicle that a gust rolls
  over on the ground has crashed as surely as one that tumbles in the air.
- **Hard impact**: the vehicle touches something (ground contact after a tick without one)
  faster than :data:`IMPACT_SPEED_M_S` (its speed relative to what it touches: on the ground,
  and what stands on it, its own speed; against another vehicle, the two's closing speed, now
  or at the tick before, as two vehicles flying at each other meet at the sum of their speeds),
  the speed of a free drop from 1.5 x 8 in: the reserve
  energy drop (1.5 times the limit drop height, 14 CFR 27.727) of the smallest limit drop height
  the FAA's rotorcraft airworthiness standards require a landing gear to take (at least 8 in,
  14 CFR 29.725(a)). A small multirotor's skids are no stronger than a certified rotorcraft's
  gear, so a faster touchdown is a crash; every built-in robot's fastest commanded descent
  (``MaxClimb``, 1.5 m/s at most) lands well below it.

A crashed robot stays crashed (motors off, DRIVE refused) until a client RESETs it.
Invariant: :meth:`CrashDetector.update` answers a cause at most once per detector.
"""

from __future__ import annotations

import math
from typing import Final

FAIL_ANGLE_RAD: Final = math.radians(60.0)
"""PX4 ``FD_FAIL_R`` and ``FD_FAIL_P`` (default 60 deg): the largest roll / pitch of a vehicle
under control."""

FAIL_TRIGGER_S: Final = 0.3
"""PX4 ``FD_FAIL_R_TTRI`` and ``FD_FAIL_P_TTRI`` (default 0.3 s): how long the angle must stay
beyond the limit."""

DROP_HEIGHT_M: Final = 1.5 * 8 * 0.0254
"""1.5 x 8 in (0.3048 m): the reserve-energy drop (14 CFR 27.727: 1.5 times the limit drop
height) of the smallest limit drop height of the rotorcraft standards (14 CFR 29.725(a): 8 in)."""

IMPACT_SPEED_M_S: Final = math.sqrt(2.0 * 9.80665 * DROP_HEIGHT_M)
"""2.445 m/s: the contact speed of a free drop from :data:`DROP_HEIGHT_M`."""


class CrashDetector:
    """The crash rules of one vehicle (see the module comment); plain floats (hot path)."""

    def __init__(
        self,
        fail_angle_rad: float = FAIL_ANGLE_RAD,
        trigger_s: float = FAIL_TRIGGER_S,
        impact_speed_m_s: float = IMPACT_SPEED_M_S,
    ) -> None:
        self.fail_angle_rad = fail_angle_rad
        self.trigger_s = trigger_s
        self.impact_speed_m_s = impact_speed_m_s
        self.cause: str | None = None
        self._beyond_since_s = -1.0  # < 0: the attitude is within the limit
        self._was_in_contact = True  # a spawn on the ground is no impact
        self._last_speed_m_s = 0.0

    def update(
        self,
        time_s: float,
        roll_rad: float,
        pitch_rad: float,
        vel_ned_m_s: tuple[float, float, float],
        in_contact: bool,
        closing_m_s: float = 0.0,
    ) -> str | None:
        """One board tick's true state; the crash's cause the first time a rule fires, else
        None (also after the crash: it is reported once). ``closing_m_s``: the speed at which
        the vehicle meets another vehicle it touches now (0: none); the ground's is the
        vehicle's own."""
        if self.cause is not None:
            return None
        vx, vy, vz = vel_ned_m_s
        speed = math.sqrt(vx * vx + vy * vy + vz * vz)
        cause: str | None = None
        if in_contact and not self._was_in_contact:
            impact = max(speed, self._last_speed_m_s, closing_m_s)
            if impact > self.impact_speed_m_s:
                cause = (f"hard impact at {impact:.1f} m/s (a crash above "
                         f"{self.impact_speed_m_s:.2f} m/s)")
        self._was_in_contact = in_contact
        self._last_speed_m_s = speed
        limit = self.fail_angle_rad
        if abs(roll_rad) > limit or abs(pitch_rad) > limit:
            if self._beyond_since_s < 0.0:
                self._beyond_since_s = time_s
            elif cause is None and time_s - self._beyond_since_s >= self.trigger_s - 1e-9:
                axis = "roll" if abs(roll_rad) > limit else "pitch"
                angle = roll_rad if axis == "roll" else pitch_rad
                cause = (f"tumbled: {axis} {math.degrees(angle):.0f} deg, beyond "
                         f"{math.degrees(limit):.0f} deg for {self.trigger_s:g} s "
                         "(PX4 failure detector)")
        else:
            self._beyond_since_s = -1.0
        if cause is not None:
            self.cause = cause
        return cause
