"""``Airframe`` on a simulated robot, through ``skeye.control``.

How this works: motion commands map onto the control interface's robot methods with
``wait=False`` (the boards watch ``busy``); readings come from the robot's sensor objects'
``latest``. Stick input (CTRL_INPUT) is the simulator's attitude ``DRIVE`` form, sent as a raw
line on the connection; the robot's own motion control must be idle first, or its next tick
would overwrite the sticks with a velocity ``DRIVE``. So the first stick command while a motion
runs replaces it with a one-shot zero velocity (which ends after one tick) and is deferred;
``advance`` (called every pilot tick) and later stick commands send the newest sticks once the
robot is idle. The robot's motion limits are raised to its robot file's (``MaxSpeed`` ...), the
limits the boards and ground control check commands against. Altitudes: the control
interface's ``take_off`` is relative to the spawn point;
everything here is above the world origin (``-down``).

As the ``sim://HOST:PORT`` backend (:func:`open_sim_airframe`, chosen by ``skeye pilot
--airframe``), it connects, spawns the robot ``AirframeOptions`` describe and owns both: its
``close`` closes the connection, and the simulator removes the robot.

A frozen simulator is as lost as a dead one (:attr:`SimAirframe.lost`): in realtime, sim time
(the newest time any line carried) must move within ``frozen_timeout_s`` of wall time; in
lockstep, a ``STEP`` that was answered must have moved it. Otherwise the pilot's failsafe
applies, exactly as when the simulator's connection drops.

Crashes: the simulator's ``ERR {Command CRASH}`` (or ``PHYSICS``: it removed the robot) is the
snapshot's ``crashed``; :meth:`SimAirframe.reset` sends ``RESET`` (the robot respawns at its
start pose, keeping its cameras), or, for a robot the simulator removed, asks for a new one.
Re-attaching: with an ``attach`` factory (a new connection and a newly spawned robot, as
``skeye pilot`` made the first), :attr:`SimAirframe.needs_attach` says when the simulator is
lost (or a respawn was asked for); the pilot's re-attach thread calls :meth:`attach_new`, and
the loop swaps the result in with :meth:`bind`.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import replace

from skeye.control.connection import Connection, connect
from skeye.control.robots import Robot
from skeye.errors import ConfigError, LocalProtocolError, SkeyeError
from skeye.pilot.airframe import (
    AirframeOptions,
    BaroClimb,
    GpsFix,
    Snapshot,
    VehicleLimits,
)
from skeye.wire.sim_messages import Drive

Attitude = tuple[float, float, float, float, bool]  # roll, pitch, yaw rate, thrust, height mode
SENSORS_READ = ("GroundTruth", "INS", "Gyro", "Accelerometer", "MagneticCompass", "Barometer",
                "GPS", "Battery")
"""The sensor types :meth:`SimAirframe.snapshot` reads: a robot that mounts none of one type
cannot be flown (``R1 (airrobot) has no Gyro sensor``); ``skeye up`` checks them first."""

FROZEN_TIMEOUT_S = 5.0
"""Realtime: sim time standing still this long (wall seconds) means the simulator is frozen."""
CLOSE_S = 1.0
"""At stop, how long the pilot waits for the simulator to close its end of the connection (it
does so in milliseconds once it has removed the robot; a stopped one never does)."""


class SimAirframe:
    """A robot spawned (by the caller) on a ``skeye.control`` connection."""

    def __init__(
        self,
        connection: Connection,
        robot: Robot,
        *,
        frozen_timeout_s: float = FROZEN_TIMEOUT_S,
        clock: Callable[[], float] = time.monotonic,
        attach: Callable[[], tuple[Connection, Robot]] | None = None,
        owns_connection: bool = False,
    ) -> None:
        if not (math.isfinite(frozen_timeout_s) and frozen_timeout_s > 0):
            raise ConfigError(f"--sim-frozen-timeout must be > 0 s, got {frozen_timeout_s!r}")
        self.frozen_timeout_s = frozen_timeout_s
        self._clock = clock
        self._attach = attach
        self._owns_connection = owns_connection
        self._respawn = False  # a RESET of a robot the simulator removed: a new one is due
        self._lock = threading.Lock()
        self._bind(connection, robot)

    def _bind(self, connection: Connection, robot: Robot) -> None:
        self.connection = connection
        self.robot = robot
        # One set of speed limits: the robot file's [controller] table as the simulator reports
        # it (MaxSpeed, MaxClimb, MaxYawRate), not the control interface's gentler defaults;
        # the boards refuse faster commands and ground control checks against the same file.
        cfg = robot.motion_config
        robot.motion_config = replace(
            cfg,
            max_speed_m_s=robot.limits.get("MaxSpeed", cfg.max_speed_m_s),
            max_climb_m_s=robot.limits.get("MaxClimb", cfg.max_climb_m_s),
            max_yaw_rate_rad_s=robot.limits.get("MaxYawRate", cfg.max_yaw_rate_rad_s),
        )
        self.lockstep = connection.mode == "lockstep"
        cfg = robot.motion_config
        self.limits = VehicleLimits(cfg.max_speed_m_s, cfg.max_climb_m_s, cfg.max_yaw_rate_rad_s)
        self.control_period_s = 1.0 / cfg.control_rate_hz
        self.clock_is_sim = True
        self.uri = f"sim://{getattr(connection, 'peer', '?')}"
        self.link_failed: SkeyeError | None = None  # the link went down, not closed by us
        add_hook = getattr(connection, "add_close_hook", None)  # a test's stand-in may lack it
        if add_hook is not None:
            add_hook(self._on_link_down)
        self._seen_time_s = connection.time_s
        self._seen_at_s = self._clock()
        self._frozen: str | None = None
        self._sticks: Attitude | None = None  # deferred until the robot's motion is idle
        self._sticks_live = False
        mass = robot.limits.get("Mass")
        self._max_thrust_n: float | None = None
        if mass is not None:
            self._max_thrust_n = 2.0 * mass * 9.80665  # fallback until Motors reports
        self._baro_climb = BaroClimb()

    # -- crashes and re-attaching ---------------------------------------------------------
    def reset(self) -> str:
        """RESET the robot (it respawns at its start pose, still, keeping its cameras); a robot
        the simulator removed gets a new one through :meth:`attach_new` instead. Returns what
        was done.

        Raises:
            SkeyeError: the simulator is lost, refused, or did not answer.
        """
        lost = self.lost
        if lost is not None:
            raise SkeyeError(f"cannot reset: {lost}")
        self._manual_off()
        robot = self.robot
        if robot.removed:
            if self._attach is None:
                raise SkeyeError(f"robot {robot.name} was removed by the simulator")
            self._respawn = True
            return f"the simulator removed {robot.name}: spawning a new one"
        robot.reset(wait=False)
        return f"{robot.name} reset at its start pose"

    @property
    def needs_attach(self) -> bool:
        """A new connection and robot are due: the simulator is lost, or a removed robot was
        reset (and there is a way to attach)."""
        return self._attach is not None and (self._respawn or self.lost is not None)

    def attach_new(self) -> tuple[Connection, Robot]:
        """Connect and spawn anew with the ``attach`` factory (closing the old connection first,
        so the robot's name is free); the caller hands the result to :meth:`bind`.

        Raises:
            SkeyeError, OSError: the simulator is not (yet) there.
        """
        if self._attach is None:
            raise SkeyeError("this airframe cannot re-attach (no attach factory)")
        self.connection.close()
        return self._attach()

    def bind(self, connection: Connection, robot: Robot) -> str:
        """Fly the new connection's robot from now on; returns what happened, for the log."""
        old = self.connection
        with self._lock:
            self._bind(connection, robot)
            self._respawn = False
        if old is not connection:
            old.close()
        return (f"simulator at {connection.peer} ({connection.mode}): robot {robot.name} "
                f"respawned at its start pose")

    @property
    def lost(self) -> str | None:
        """Why the simulator link is down (it died or closed), or None while it is up."""
        if self.connection.error is not None:
            return f"simulator lost: {self.connection.error}"
        if self.connection.closed:
            return "simulator lost: the connection is closed"
        if self._frozen is None and not self.lockstep and not self.robot.removed:
            # (a removed robot streams nothing: its silence is a crash, not a frozen simulator)
            now, t = self._clock(), self.connection.time_s
            if t != self._seen_time_s:
                self._seen_time_s, self._seen_at_s = t, now
            elif now - self._seen_at_s >= self.frozen_timeout_s:
                self._frozen = (
                    f"simulator frozen: sim time stuck at {t:.3f} s for "
                    f"{now - self._seen_at_s:.1f} s of wall time"
                )
        return self._frozen

    @property
    def busy(self) -> bool:
        return self.robot.busy

    def _ready(self) -> Robot:
        """The robot, for a motion command; refused while a new one is being spawned."""
        if self._respawn:
            raise SkeyeError(f"{self.robot.name} is being respawned: try again in a moment")
        return self.robot

    def _on_link_down(self, error: SkeyeError) -> None:
        if not self.connection.closed:
            self.link_failed = error

    def describe(self) -> str:
        level = getattr(self.connection, "level", "") or "the simulator"
        return (f"{self.robot.name} in {level} at {self.uri} "
                f"({'lockstep' if self.lockstep else 'realtime'})")

    def close(self) -> None:
        """Close the simulator connection if this backend opened it (idempotent), waiting at
        most ``CLOSE_S`` for the simulator to close its end (it removes the robot then); one
        that does not (stopped, frozen) is named in :attr:`close_problem`."""
        if self._owns_connection:
            self.connection.close(CLOSE_S)

    @property
    def close_problem(self) -> str | None:
        """What :meth:`close` could not do (the simulator did not answer), else None."""
        return getattr(self.connection, "close_unanswered", None)

    def snapshot(self) -> Snapshot:
        r = self.robot
        ins = r.ins.latest
        gt = r.ground_truth.latest
        pose = ins or gt
        assert pose is not None  # spawn waits for the first readings
        vel = pose.velocity_ned_m_s or (gt.velocity_ned_m_s if gt else None) or (0.0, 0.0, 0.0)
        gyro = r.gyro.latest
        acc = r.accelerometer.latest
        compass = r.compass.latest
        baro = r.barometer.latest
        gps = r.gps.latest
        battery = r.battery.latest
        status = r.status.latest
        motors = r.motors.latest if ("motors", "motors") in r.sensors else None
        if baro is not None:
            self._baro_climb.update(baro.time_s, baro.altitude_m)
        fix = None
        if gps is not None:
            fix = GpsFix(
                gps.fix,
                gps.satellites,
                gps.latitude_deg or 0.0,
                gps.longitude_deg or 0.0,
                gps.altitude_m or 0.0,
                gps.velocity_ned_m_s or (0.0, 0.0, 0.0),
            )
        thrust_fraction = 0.0
        if motors is not None and math.isfinite(motors.thrust_n) and self._max_thrust_n:
            thrust_fraction = max(0.0, min(1.0, motors.thrust_n / self._max_thrust_n))
        return Snapshot(
            time_s=max(pose.time_s, self.connection.time_s),
            pos_ned_m=pose.position_ned_m,
            rpy_rad=pose.rpy_rad,
            vel_ned_m_s=vel,
            rates_frd_rad_s=gyro.angular_velocity_frd_rad_s if gyro else (0.0, 0.0, 0.0),
            specific_force_frd_m_s2=(
                acc.proper_acceleration_frd_m_s2 if acc else (0.0, 0.0, -9.80665)
            ),
            mag_field_frd_ut=compass.field_frd_ut if compass else (0.0, 0.0, 0.0),
            mag_heading_rad=compass.heading_rad if compass else pose.rpy_rad[2],
            baro_pressure_pa=baro.pressure_pa if baro else 101325.0,
            baro_altitude_m=baro.altitude_m if baro else -pose.position_ned_m[2],
            baro_climb_m_s=self._baro_climb.climb_m_s,
            gps=fix,
            battery_v=(
                battery.voltage_v
                if battery
                else (status.voltage_v if status and status.voltage_v else 0.0)
            ),
            armed=status.armed if status else False,
            landed=status.landed if status else True,
            thrust_fraction=thrust_fraction,
            crashed="" if self._respawn else (r.crashed or ""),
            pos_sigma_ned_m=ins.position_sigma_ned_m if ins is not None else None,
            truth_ned_m=gt.position_ned_m if gt is not None else None,
            truth_yaw_rad=gt.rpy_rad[2] if gt is not None else None,
        )

    # -- commands ------------------------------------------------------------------------
    def _manual_off(self) -> None:
        with self._lock:
            self._sticks = None
            self._sticks_live = False

    def take_off(self, altitude_m: float) -> None:
        robot = self._ready()
        self._manual_off()
        robot.take_off(altitude_m + robot.home_ned_m[2], wait=False)

    def fly_to(self, north_m: float, east_m: float, altitude_m: float, speed_m_s: float) -> None:
        self._manual_off()
        # The packet's speed bounds the whole move: horizontal speed and climb rate alike.
        self.robot.fly_to(
            north_m,
            east_m,
            altitude_m,
            wait=False,
            max_speed_m_s=speed_m_s,
            max_climb_m_s=min(speed_m_s, self.robot.motion_config.max_climb_m_s),
        )

    def fly_to_gps(
        self, latitude_deg: float, longitude_deg: float, altitude_m: float, speed_m_s: float
    ) -> None:
        self._manual_off()
        self.robot.fly_to_gps(
            latitude_deg, longitude_deg, altitude_m, wait=False, max_speed_m_s=speed_m_s
        )

    def turn_by(self, yaw_rad: float) -> None:
        self._manual_off()
        self.robot.move_by(yaw_rad=yaw_rad, wait=False)

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
        self._manual_off()
        self.robot.set_velocity(
            forward_m_s, right_m_s, up_m_s, yaw_rate_rad_s, duration_s=duration_s, wait=False,
            board_mode="gps" if gps_mode else None,
        )

    def hover(self) -> None:
        self._manual_off()
        self.robot.hover()

    def land(self) -> None:
        self._manual_off()
        self.robot.land(wait=False)

    def attitude(
        self, roll_rad: float, pitch_rad: float, yaw_rate_rad_s: float, thrust_fraction: float,
        height_mode: bool = False,
    ) -> None:
        with self._lock:
            self._sticks = (roll_rad, pitch_rad, yaw_rate_rad_s, thrust_fraction, height_mode)
            live = self._sticks_live
        if not live and (self.robot.busy or self.robot._motion is not None):
            # Replace the robot's motion by a one-shot velocity DRIVE that ends after a tick.
            self.robot.set_velocity(0.0, 0.0, 0.0, 0.0, duration_s=None, wait=False)
            return
        self._flush_sticks()

    def _flush_sticks(self) -> None:
        with self._lock:
            sticks = self._sticks
        if sticks is None or self.robot._motion is not None:
            return
        roll, pitch, yaw_rate, thrust, height_mode = sticks
        self.connection.send_message(
            Drive(roll_rad=roll, pitch_rad=pitch, yaw_rate_rad_s=yaw_rate, thrust_fraction=thrust,
                  board_mode="height" if height_mode else None)
        )
        with self._lock:
            self._sticks_live = True
            if self._sticks is sticks:
                self._sticks = None

    def advance(self, seconds: float) -> None:
        """Send deferred sticks; in lockstep, let ``seconds`` of sim time pass."""
        self._flush_sticks()
        if self.lockstep and seconds > 0:
            before = self.connection.time_s
            after = self.connection.run_for(seconds)
            if after <= before and self._frozen is None:
                self._frozen = (
                    f"simulator frozen: STEP answered but sim time stayed at {after:.3f} s"
                )


def sim_address(uri: str) -> str:
    """``HOST:PORT`` of a ``sim://HOST:PORT`` URI (the port defaults to 3000).

    Raises:
        LocalProtocolError: not a ``sim://`` URI, or one with a path or options.
    """
    scheme, sep, rest = uri.partition("://")
    if scheme.lower() != "sim" or not sep:
        raise LocalProtocolError(f"airframe {uri!r}: expected sim://HOST:PORT")
    if not rest or "/" in rest or "?" in rest:
        raise LocalProtocolError(
            f"airframe {uri!r}: expected sim://HOST:PORT (the simulator's control port), "
            "with no path or options")
    return rest if ":" in rest.rsplit("]", 1)[-1] else f"{rest}:3000"


def open_sim_airframe(uri: str, options: AirframeOptions) -> SimAirframe:
    """The ``sim://`` backend: connect to the simulator, spawn the robot, fly it.

    Raises:
        LocalProtocolError: a bad URI.
        LinkClosed / LinkTimeout: the simulator cannot be reached.
        SkeyeError: the spawn was refused (a name already taken: the hint says ``--name``;
            a start pose the world lacks: ``--start``).
    """
    address = sim_address(uri)

    def attach() -> tuple[Connection, Robot]:
        """Connect and spawn: at start, and again whenever the simulator comes back after it
        was lost (the pilot re-attaches: :attr:`SimAirframe.needs_attach`)."""
        sim = connect(address, images=options.images, timeout_s=options.timeout_s,
                      sync_clock=options.sync_clock)
        try:
            if options.location_ned_m is not None:
                robot = sim.spawn(options.robot, location_ned_m=options.location_ned_m,
                                  name=options.name)
            else:
                robot = sim.spawn(options.robot, start=options.start or "Pad1",
                                  name=options.name)
        except SkeyeError as exc:
            sim.close()
            if "already exists" in str(exc):
                raise SkeyeError(
                    f"{exc}; another pilot or client flies it - give this one another "
                    "name with --name"
                ) from None
            if isinstance(exc, LocalProtocolError) and "no start pose" in str(exc):
                raise LocalProtocolError(
                    f"{exc}; give --start one of them, or --location") from None
            raise
        except BaseException:
            sim.close()
            raise
        return sim, robot

    sim, robot = attach()
    try:
        return SimAirframe(sim, robot, frozen_timeout_s=options.frozen_timeout_s,
                           attach=attach, owns_connection=True)
    except BaseException:
        sim.close()
        raise
