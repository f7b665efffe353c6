"""The flight envelope: how high above home and how far from it the pilot lets the vehicle go.

How this works: like PX4's geofence (``GF_MAX_VER_DIST``, ``GF_MAX_HOR_DIST``), the envelope is
a cylinder around home (the take-off point): at most ``ceiling_m`` above it, at most
``max_radius_m`` from it horizontally, and no target below it: its floor is the ground the
vehicle took off from (ArduPilot's minimum-altitude fence, ``FENCE_ALT_MIN``, which its guided
mode checks every destination against, at home's height; there is no terrain model, so ground
higher than home elsewhere is not known). The boards check it (pure functions here, positions in
NED metres, no clock):

- every command with a target (TAKE_OFF, LAUNCH, MOVE_BY, GOTO_GPS, waypoint goto, a VELOCITY
  with a duration: its end point) before it starts: outside, it is refused with RESULT code 3
  (bad value) and a reason naming the limit (``check_target``); a target below home was flown
  into the ground at the move's descent rate. Landing is LAND's, never a move's;
- stick input is limited, not refused: at the ceiling a full-thrust stick holds height, at the
  radius the outward part of the velocity is removed (``limit_velocity``); so are the onboard
  computer's own velocities (the pad modes, a ``--policy``: ``OnboardBoards.fly_velocity``).
  An open-ended VELOCITY is neither refused nor limited: the stop below acts on it;
- every tick: a vehicle beyond a limit and still moving outward (an open-ended VELOCITY, a gust)
  is stopped and holds (``breach``), as PX4's geofence "hold" action does. Moving back inside is
  always allowed; COME_HOME (``>*>wh``) is never refused.

Defaults: a 120 m ceiling (the maximum height of the EU "open" category, Regulation (EU)
2019/947, UAS.OPEN.010, and of the FAA's Part 107, 14 CFR 107.51(b): 400 ft) and a 500 m radius
(UK CAA CAP 722, 6th edition 2015, paragraph 3.11: visual-line-of-sight operations "normally
accepted out to a maximum distance of 500 m horizontally and 400 ft vertically").
A robot file's ``[envelope]`` table and ``skeye pilot --ceiling-m/--max-radius-m`` change them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from skeye.errors import ConfigError

Vec3 = tuple[float, float, float]
OUTWARD_SPEED_M_S = 0.05  # moving out faster than this beyond a limit is a breach


@dataclass(frozen=True)
class FlightEnvelope:
    """A cylinder around home: ``ceiling_m`` above it, ``max_radius_m`` around it."""

    ceiling_m: float = 120.0
    max_radius_m: float = 500.0

    def __post_init__(self) -> None:
        for name in ("ceiling_m", "max_radius_m"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ConfigError(f"flight envelope: {name} must be a number, got {value!r}")
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(
                    f"flight envelope: {name} must be a positive finite number of metres, "
                    f"got {value!r}"
                )

    def describe(self) -> str:
        return f"ceiling {self.ceiling_m:g} m above home, radius {self.max_radius_m:g} m"

    def check_target(self, home_ned_m: Vec3, target_ned_m: Vec3) -> str | None:
        """Why a target is outside the envelope (above the ceiling, below home, beyond the
        radius), or None when it is inside."""
        height = home_ned_m[2] - target_ned_m[2]
        if not all(math.isfinite(v) for v in target_ned_m):
            return "target is not a finite position"
        if height > self.ceiling_m + 1e-6:
            return (
                f"outside the flight envelope: {_fmt(height)} above home, "
                f"ceiling {self.ceiling_m:g} m"
            )
        if height < -1e-6:
            return (
                f"outside the flight envelope: {_fmt(-height)} below home, under the ground "
                "it took off from (the floor; to land, send LAND)"
            )
        dist = math.hypot(target_ned_m[0] - home_ned_m[0], target_ned_m[1] - home_ned_m[1])
        if dist > self.max_radius_m + 1e-6:
            return (
                f"outside the flight envelope: {_fmt(dist)} from home, "
                f"radius {self.max_radius_m:g} m"
            )
        return None

    def limit_velocity(
        self, home_ned_m: Vec3, pos_ned_m: Vec3, north_m_s: float, east_m_s: float, up_m_s: float
    ) -> tuple[float, float, float]:
        """The velocity with its outward parts removed where the vehicle is at a limit."""
        if home_ned_m[2] - pos_ned_m[2] >= self.ceiling_m:
            up_m_s = min(up_m_s, 0.0)
        dn, de = pos_ned_m[0] - home_ned_m[0], pos_ned_m[1] - home_ned_m[1]
        dist = math.hypot(dn, de)
        if dist >= self.max_radius_m and dist > 0:
            rn, re = dn / dist, de / dist
            outward = north_m_s * rn + east_m_s * re
            if outward > 0:
                north_m_s, east_m_s = north_m_s - outward * rn, east_m_s - outward * re
        return north_m_s, east_m_s, up_m_s

    def at_limit(self, home_ned_m: Vec3, pos_ned_m: Vec3) -> bool:
        """At or beyond the ceiling or the radius: where ``limit_velocity`` may change a
        velocity (elsewhere it leaves it as it is)."""
        dn, de = pos_ned_m[0] - home_ned_m[0], pos_ned_m[1] - home_ned_m[1]
        return (home_ned_m[2] - pos_ned_m[2] >= self.ceiling_m
                or math.hypot(dn, de) >= self.max_radius_m)

    def limit_body_velocity(
        self, home_ned_m: Vec3, pos_ned_m: Vec3, yaw_rad: float, fwd: float, right: float,
        up: float
    ) -> tuple[float, float, float]:
        """``limit_velocity`` for a heading-frame velocity (forward, right, up)."""
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        vn, ve = c * fwd - s * right, s * fwd + c * right
        vn, ve, up = self.limit_velocity(home_ned_m, pos_ned_m, vn, ve, up)
        return c * vn + s * ve, -s * vn + c * ve, up

    def breach(self, home_ned_m: Vec3, pos_ned_m: Vec3, vel_ned_m_s: Vec3) -> str | None:
        """Why the vehicle must stop: beyond a limit and moving further out; else None."""
        height = home_ned_m[2] - pos_ned_m[2]
        if height > self.ceiling_m and -vel_ned_m_s[2] > OUTWARD_SPEED_M_S:
            return f"flight envelope: {_fmt(height)} above home, ceiling {self.ceiling_m:g} m"
        dn, de = pos_ned_m[0] - home_ned_m[0], pos_ned_m[1] - home_ned_m[1]
        dist = math.hypot(dn, de)
        if dist > self.max_radius_m:
            outward = (vel_ned_m_s[0] * dn + vel_ned_m_s[1] * de) / dist
            if outward > OUTWARD_SPEED_M_S:
                return f"flight envelope: {_fmt(dist)} from home, radius {self.max_radius_m:g} m"
        return None


def _fmt(metres: float) -> str:
    return f"{metres / 1000:.1f} km" if abs(metres) >= 10_000 else f"{metres:.1f} m"
