"""What the emulated onboard boards need from the vehicle: a sensor snapshot and motion commands.

How this works: ``Airframe`` is the narrow interface the boards (``skeye.pilot.boards``) drive;
``Snapshot`` is one consistent set of the latest sensor readings in SI (NED world, FRD body,
altitude positive up). ``skeye.pilot.sim_airframe.SimAirframe`` implements it on a robot of the
simulator through ``skeye.control``; tests implement it with a scripted fake. Keeping the boards
behind this interface keeps them free of sockets and threads (they take the time as an
argument), so their protocol behaviour is tested without a simulator.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class GpsFix:
    """The GPS receiver's latest solution (``fix`` False indoors: positions meaningless)."""

    fix: bool
    satellites: int
    latitude_deg: float
    longitude_deg: float
    altitude_m: float
    vel_ned_m_s: Vec3


@dataclass(frozen=True)
class Snapshot:
    """The latest readings of every sensor the boards use, in SI."""

    time_s: float  # sim time of the newest reading
    pos_ned_m: Vec3  # onboard estimate (INS)
    rpy_rad: Vec3  # onboard estimate (INS), roll/pitch/yaw
    vel_ned_m_s: Vec3  # onboard estimate
    rates_frd_rad_s: Vec3  # gyro
    specific_force_frd_m_s2: Vec3  # accelerometer: about (0, 0, -9.81) at rest
    mag_field_frd_ut: Vec3
    mag_heading_rad: float
    baro_pressure_pa: float
    baro_altitude_m: float
    baro_climb_m_s: float
    gps: GpsFix | None
    battery_v: float
    armed: bool  # motors running
    landed: bool  # resting on the ground
    thrust_fraction: float  # total rotor thrust / maximum thrust, 0..1
    crashed: str = ""  # why the vehicle crashed ("" while it has not): see Airframe.reset

    @property
    def altitude_m(self) -> float:
        """Estimated height above the world origin (up positive)."""
        return -self.pos_ned_m[2]


class Airframe(Protocol):
    """Motion commands and sensor access of one vehicle. Commands return at once."""

    @property
    def busy(self) -> bool:
        """True while a take-off, fly-to or landing is under way."""
        ...

    def snapshot(self) -> Snapshot:
        """The latest readings."""
        ...

    def take_off(self, altitude_m: float) -> None:
        """Start the motors and climb to ``altitude_m`` (above the world origin)."""
        ...

    def fly_to(self, north_m: float, east_m: float, altitude_m: float, speed_m_s: float) -> None:
        """Fly to a world position, then hover there."""
        ...

    def fly_to_gps(
        self, latitude_deg: float, longitude_deg: float, altitude_m: float, speed_m_s: float
    ) -> None:
        """Fly to GPS coordinates at ``altitude_m`` (above the world origin), then hover."""
        ...

    def turn_by(self, yaw_rad: float) -> None:
        """Turn on the spot by ``yaw_rad`` (positive clockwise seen from above)."""
        ...

    def set_velocity(
        self,
        forward_m_s: float,
        right_m_s: float,
        up_m_s: float,
        yaw_rate_rad_s: float,
        duration_s: float | None,
        *,
        gps_mode: bool = False,
    ) -> None:
        """Fly at body-frame velocities (None: until replaced), then hover. ``gps_mode``: the
        LL board's GPS mode (centred sticks hold the GPS position while there is a fix)."""
        ...

    def hover(self) -> None:
        """Cancel any motion and hold the current position."""
        ...

    def land(self) -> None:
        """Descend where it is and stop the motors."""
        ...

    def attitude(
        self, roll_rad: float, pitch_rad: float, yaw_rate_rad_s: float, thrust_fraction: float,
        height_mode: bool = False,
    ) -> None:
        """Low-level stick input to the attitude controller (cancels any motion). In height mode
        ``thrust_fraction`` is a climb rate around 0.5 (the LL board's height control)."""
        ...

    def advance(self, seconds: float) -> None:
        """Let sim time pass when the simulator is in lockstep (no-op in realtime)."""
        ...

    def reset(self) -> str:
        """Bring a crashed (or landed) vehicle back at home, still, motors off: a simulated one
        respawns at its start pose; returns what was done, for the log. Raises SkeyeError when
        it cannot (the vehicle below is lost)."""
        ...
