"""What the emulated onboard boards need from the vehicle: a sensor snapshot and motion commands.

How this works: ``Airframe`` is the narrow interface the boards (``skeye.pilot.boards``) drive;
``Snapshot`` is one consistent set of the latest sensor readings in SI (NED world, FRD body,
altitude positive up). Keeping the boards behind this interface keeps them free of sockets and
threads (they take the time as an argument), so their protocol behaviour is tested without a
simulator; tests implement it with a scripted fake.

Backends are chosen by URI, as Crazyflie's link drivers are (``radio://``, ``usb://``): one
module per backend, a registry by scheme, and :func:`open_airframe` picks the module.

- ``sim://HOST:PORT``: a robot of the simulator through ``skeye.control``
  (:mod:`skeye.pilot.sim_airframe`);
- ``asctec-ll://serial/dev/ttyS1?baud=57600`` or ``asctec-ll://tcp/HOST:PORT``: a real AscTec
  low-level board over its serial protocol, or the simulator playing one (``skeye sim
  --ll-board``) (:mod:`skeye.pilot.asctec_ll`).

A new backend is one entry in :data:`BACKENDS` (or a :func:`register_airframe` call): a
function ``open(uri, options) -> AirframeBackend``, named as ``"module:function"`` so that the
registry imports a backend's dependencies only when its scheme is used.
tests/pilot/test_airframe_backends.py is the conformance test every backend passes.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from skeye.errors import LocalProtocolError

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
    # The estimate's own 1-sigma per NED position axis (m), where the estimator states one.
    pos_sigma_ned_m: Vec3 | None = None
    # A simulated vehicle's true position (NED, m) and heading (rad), for display beside the
    # estimate; None for a vehicle whose truth nobody knows (a real one). Never flown on.
    truth_ned_m: Vec3 | None = None
    truth_yaw_rad: float | None = None

    @property
    def altitude_m(self) -> float:
        """Estimated height above the world origin (up positive)."""
        return -self.pos_ned_m[2]


class BaroClimb:
    """The climb rate a backend derives from its pressure altitudes for ``Snapshot``: the
    altitude change over the time between readings at least 50 ms apart (the newest rate is
    kept in between)."""

    MIN_INTERVAL_S = 0.05

    def __init__(self) -> None:
        self._last: tuple[float, float] | None = None  # (time s, altitude m)
        self.climb_m_s = 0.0

    def update(self, time_s: float, altitude_m: float) -> float:
        """Take one pressure-altitude reading; the climb rate, m/s (up positive)."""
        if self._last is None:
            self._last = (time_s, altitude_m)
        elif time_s > self._last[0] + self.MIN_INTERVAL_S:
            t0, a0 = self._last
            self.climb_m_s = (altitude_m - a0) / (time_s - t0)
            self._last = (time_s, altitude_m)
        return self.climb_m_s


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

    def describe(self) -> str:
        """One line naming what is flown and where (the start-up message; VEHICLE's text)."""
        ...


# -- backends by URI ---------------------------------------------------------------------------
@dataclass(frozen=True)
class VehicleLimits:
    """The one set of speed limits the boards check commands against (the robot file's
    ``[controller]`` table on the simulator; the vehicle's configuration on a real one)."""

    max_speed_m_s: float = 3.0
    max_climb_m_s: float = 1.5
    max_yaw_rate_rad_s: float = 1.745


def vehicle_limits(robot: str, robot_dirs: tuple[str, ...] = ()) -> VehicleLimits:
    """The speed limits of a robot class's file (``[controller]``), what a real vehicle's
    backend (``asctec-ll://``, ``mavlink://``) gives the boards: on an LL board also the stick
    scales (full stick in GPS mode is ``max_speed_m_s``, full thrust ``max_climb_m_s``).

    Raises:
        ConfigError: the class has no readable file.
    """
    from pathlib import Path

    from skeye.robots.config import load_robot_config

    config = load_robot_config(robot, tuple(Path(d) for d in robot_dirs), allow_paths=False)
    c = config.controller
    return VehicleLimits(c.max_speed_m_s, c.max_climb_m_s, c.max_yaw_rate_rad_s)


@dataclass(frozen=True)
class AirframeOptions:
    """What ``skeye pilot`` tells every backend; each uses the fields that apply to it.

    ``robot``, ``name``, ``start`` / ``location_ned_m`` and ``images`` are about spawning a
    robot in the simulator (``sim://``); ``robot`` and ``robot_dirs`` also name the robot file
    whose limits a real vehicle's backend takes (``asctec-ll://``: the stick scales);
    ``timeout_s`` bounds connecting and each answer; ``frozen_timeout_s`` is the realtime
    frozen-simulator check (``sim://``).
    """

    robot: str = "hummingbird"
    name: str = "R1"
    start: str | None = "Pad1"
    location_ned_m: Vec3 | None = None
    images: str | None = None
    timeout_s: float = 10.0
    frozen_timeout_s: float = 5.0
    robot_dirs: tuple[str, ...] = ()  # where robot files outside the built-ins are found
    sync_clock: bool = False  # lockstep sim://: step in the clock barrier (--lockstep-sync)


@runtime_checkable
class AirframeBackend(Airframe, Protocol):
    """An opened vehicle: the ``Airframe`` the boards drive, plus what the pilot needs to run it.

    ``lockstep``: ``advance`` moves a simulator's clock (the pilot then drives time);
    ``control_period_s``: the period the pilot ticks at in lockstep; ``clock_is_sim``: the
    snapshot's ``time_s`` is simulator time (else the onboard computer's monotonic clock);
    ``lost``: why the vehicle stopped answering (None while it answers).
    """

    uri: str
    limits: VehicleLimits
    lockstep: bool
    control_period_s: float
    clock_is_sim: bool

    @property
    def lost(self) -> str | None: ...

    def close(self) -> None:
        """Release the vehicle's link (idempotent)."""
        ...


AirframeOpener = Callable[[str, AirframeOptions], AirframeBackend]

BACKENDS: dict[str, str | AirframeOpener] = {
    "sim": "skeye.pilot.sim_airframe:open_sim_airframe",
    "asctec-ll": "skeye.pilot.asctec_ll:open_asctec_ll",
    "mavlink": "skeye.pilot.mavlink_airframe:open_mavlink_backend",
}
"""Scheme -> opener (a function, or ``"module:function"`` imported when the scheme is used)."""


def register_airframe(scheme: str, opener: str | AirframeOpener) -> None:
    """Add (or replace) the backend for ``scheme://`` URIs."""
    if not scheme or "://" in scheme or scheme != scheme.lower():
        raise LocalProtocolError(f"airframe scheme must be a lower-case name, got {scheme!r}")
    BACKENDS[scheme] = opener


def airframe_scheme(uri: str) -> str:
    """The scheme of an airframe URI, checked against the registry.

    Raises:
        LocalProtocolError: no ``scheme://``, or no backend for it.
    """
    scheme, sep, _ = uri.partition("://")
    if not sep or not scheme:
        raise LocalProtocolError(
            f"airframe {uri!r}: expected a URI such as sim://127.0.0.1:3000 or "
            f"asctec-ll://serial/dev/ttyS1?baud=57600")
    scheme = scheme.lower()
    if scheme not in BACKENDS:
        raise LocalProtocolError(
            f"airframe {uri!r}: no backend for {scheme}:// (known: "
            f"{', '.join(s + '://' for s in sorted(BACKENDS))})")
    return scheme


def _opener(scheme: str) -> AirframeOpener:
    entry = BACKENDS[scheme]
    if not isinstance(entry, str):
        return entry
    module, _, name = entry.partition(":")
    opener: AirframeOpener = getattr(importlib.import_module(module), name)
    return opener


def open_airframe(uri: str, options: AirframeOptions | None = None) -> AirframeBackend:
    """Open the vehicle a URI names (see the module docstring for the schemes).

    Raises:
        LocalProtocolError: a malformed URI or an unknown scheme.
        LinkClosed / LinkTimeout: the vehicle (or simulator) cannot be reached.
        SkeyeError: the backend refused (a robot name taken, a board that is not an LL board).
    """
    return _opener(airframe_scheme(uri))(uri, options or AirframeOptions())
