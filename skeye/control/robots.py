"""Robot classes: the supervisory layer that turns sensors and motion control into a flight.

How this works: a :class:`Robot` is bound to one :class:`~skeye.control.connection.Connection`
(one robot per connection, as in USARSim). The message thread routes its ``SEN`` lines to sensor
objects (created from ``CONF {Sensors ...}``, or on first sight) and its ``STA`` lines to
``status``. Motion methods install a :class:`~skeye.control.motion.Motion` as *the* current
motion and, by default, wait for it; the clock's control tick (a thread in realtime, the stepping
loop in lockstep) feeds it the feedback sensor's latest reading and sends its ``DRIVE``. A
position motion that arrives turns into a position hold, so the vehicle stays where it was sent.

The flight state follows a transition table (:mod:`skeye.control.flight`); an illegal request
(flying somewhere while landed) raises LocalProtocolError before anything is sent. The sensor
registry is the base class :class:`~skeye.control.robot_sensors.RobotSensors`; the robot sees
its connection only through :class:`~skeye.control.host.RobotHost`. A motion's error (a
refused ``DRIVE``, the link dying, a sim-time budget exceeded) is raised in whoever waits for it.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from typing import Any, ClassVar

from skeye.errors import (
    CommandRejected,
    LinkTimeout,
    LocalProtocolError,
    PhysicsError,
    SkeyeError,
)
from skeye.geo import GeoOrigin
from skeye.values import is_finite_number
from skeye.wire.sim_lines import Message
from skeye.wire.sim_messages import Reset, RobotConf

from .camera import CameraSensor
from .flight import TRANSITIONS, FlightState, transition
from .host import RobotHost
from .motion import (
    STOP,
    DriveCommand,
    GoTo,
    Hold,
    Land,
    Motion,
    MotionCancelled,
    MotionConfig,
    NavState,
    Target,
    Velocity,
    body_to_world,
)
from .robot_sensors import FEEDBACK_TYPES, RobotSensors
from .sensors import PoseReading, Sensor, StatusSensor

log = logging.getLogger(__name__)

STALE_FEEDBACK_SIM_S = 1.0
"""Sim seconds the feedback sensor's newest reading may lag the connection's sim time (the
newest time any line carried) before a motion fails on it."""


class Robot(RobotSensors):
    """One spawned robot: its sensors, its flight state and its motion commands.

    Made by :meth:`Connection.spawn`. Sensors mounted on the robot are attributes
    (``ground_truth``, ``ins``, ``accelerometer`` alias ``imu``, ``gyro``, ``compass``,
    ``barometer``, ``gps``, ``sonar``, ``optical_flow``, ``battery``, ``motors``, ``camera``);
    every one is also in ``sensors`` by ``(type, name)``.
    """

    class_name: ClassVar[str] = ""

    def __init__(
        self,
        connection: RobotHost,
        name: str,
        home_ned_m: tuple[float, float, float],
        *,
        feedback: str = "ins",
        motion: MotionConfig | None = None,
    ) -> None:
        self.connection = connection
        self.name = name
        self.home_ned_m = home_ned_m
        self.feedback = self._check_feedback(feedback)
        self.motion_config = motion or MotionConfig()
        self.limits: dict[str, float] = {}
        self.mounted: list[tuple[str, str]] = []
        self.sensors: dict[tuple[str, str], Sensor[Any]] = {}
        self.state = FlightState.LANDED
        self.crashed: str | None = None
        """Why the simulator says this robot crashed (``ERR {Command CRASH}``, or ``PHYSICS``:
        it removed the robot), until a reset."""
        self.removed = False
        """The simulator removed this robot (``ERR {Command PHYSICS}``): only a new INIT, on a
        new connection, brings a vehicle back."""
        self.rejections: list[CommandRejected] = []
        advance = connection.clock.advance_period if connection.mode == "lockstep" else None
        self._advance = advance
        self.status = StatusSensor("Status", advance=advance)
        self._lock = threading.RLock()
        self._motion: Motion | None = None
        self._motion_feedback = self.feedback
        self._rejection: SkeyeError | None = None
        self._last_command: DriveCommand | None = None

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r} {self.state.value}>"

    @staticmethod
    def _check_feedback(feedback: str) -> str:
        if feedback not in FEEDBACK_TYPES:
            raise LocalProtocolError(
                f"feedback must be 'ins' or 'ground_truth', got {feedback!r}"
            )
        return feedback

    # -- setup (called by Connection.spawn) -----------------------------------------------
    def configure(self, conf: RobotConf) -> None:
        for key, value in (("MaxSpeed", conf.max_speed_m_s), ("MaxClimb", conf.max_climb_m_s),
                           ("MaxYawRate", conf.max_yaw_rate_rad_s), ("Mass", conf.mass_kg),
                           ("TimeStep", conf.time_step_s), ("MaxTilt", conf.max_tilt_rad)):
            if value is not None:
                self.limits[key] = value
        cfg = self.motion_config
        self.motion_config = replace(
            cfg,
            max_speed_m_s=min(cfg.max_speed_m_s, self.limits.get("MaxSpeed", math.inf)),
            max_climb_m_s=min(cfg.max_climb_m_s, self.limits.get("MaxClimb", math.inf)),
            max_yaw_rate_rad_s=min(cfg.max_yaw_rate_rad_s,
                                   self.limits.get("MaxYawRate", math.inf)),
        )
        for type_name, sensor_name in conf.mounted():
            self.mounted.append((type_name, sensor_name))
            self._sensor(type_name, sensor_name)

    def await_first_readings(self) -> None:
        need: list[Sensor[Any]] = [self.status]
        for type_key in ("groundtruth", "ins"):
            found = self._find(type_key)
            if found is not None:
                need.append(found)
        self.connection.clock.wait_until(
            lambda: all(s.latest is not None for s in need),
            self.connection.timeout_s,
            f"{self.name}: first readings",
        )
        self._hold_if_airborne()

    def _hold_if_airborne(self) -> None:
        """A robot that spawned in the air holds where it is."""
        status = self.status.latest
        if status is not None and not status.landed:
            state = self._nav_state(self.feedback)
            with self._lock:
                self.state = FlightState.HOLDING
                self._motion = Hold(Target(state.position_ned_m, state.yaw_rad),
                                    self.motion_config)

    def reset(
        self,
        *,
        start: str | None = None,
        location_ned_m: tuple[float, float, float] | None = None,
        rotation_rpy_rad: tuple[float, float, float] | None = None,
        home_ned_m: tuple[float, float, float] | None = None,
        timeout_s: float | None = None,
        wait: bool = True,
    ) -> None:
        """``RESET``: the simulator respawns this robot, still, with a fresh board, where it was
        spawned (or at ``start`` / ``location_ned_m``); a crashed robot flies again. Ends the
        current motion, and returns once the simulator answered and (``wait``) the robot
        streams from its new pose.

        ``home_ned_m``: the new pose's position, for take-offs (default: the location given,
        else the home it had; a start pose elsewhere needs it).

        Raises:
            CommandRejected: the simulator refused (an unknown start pose...).
            LinkTimeout: no answer, or no reading from the new pose, within ``timeout_s``.
        """
        self.connection.check()
        with self._lock:
            old, self._motion = self._motion, None
            if old is not None and not old.done and old.error is None:
                old.error = MotionCancelled(f"{self.name}: {old.name} ended by a reset")
            self._rejection = None
        before_s = self.connection.time_s
        self.connection.request_message(
            Reset(start=start, location_ned_m=location_ned_m, rotation_rpy_rad=rotation_rpy_rad),
            timeout_s=timeout_s,
        )
        with self._lock:
            self.crashed = None
            self.state = transition(self.state, "reset", self.name)
            if home_ned_m is not None:
                self.home_ned_m = home_ned_m
            elif location_ned_m is not None:
                self.home_ned_m = location_ned_m
        if not wait:
            return
        need: list[Sensor[Any]] = [self.status]
        for type_key in ("groundtruth", "ins"):
            found = self._find(type_key)
            if found is not None:
                need.append(found)
        self.connection.clock.wait_until(
            lambda: all(s.latest is not None and s.latest.time_s > before_s for s in need),
            self.connection.timeout_s if timeout_s is None else timeout_s,
            f"{self.name}: first readings after the reset",
        )
        self._hold_if_airborne()

    # -- message thread --------------------------------------------------------------------
    def on_sensor(self, msg: Message) -> None:
        type_name = msg.get("Type")
        sensor_name = msg.get("Name")
        if not type_name or not sensor_name:
            log.warning("SEN without Type or Name: %s", msg)
            return
        self._sensor(type_name, sensor_name).update(msg)

    def on_status(self, msg: Message) -> None:
        self.status.update(msg)

    def on_error(self, msg: Message) -> None:
        command = (msg.get("Command") or "").upper()
        reason = msg.get("Reason") or "no reason given"
        error: SkeyeError
        if command in ("PHYSICS", "CRASH"):
            error = PhysicsError(f"{self.name}: {reason}")
            with self._lock:
                self.state = FlightState.FAILED
                self.crashed = reason
                self.removed = self.removed or command == "PHYSICS"
        else:
            error = CommandRejected(f"{command}: {reason}")
        if isinstance(error, CommandRejected):
            self.rejections.append(error)
        with self._lock:
            self._rejection = error

    def link_down(self, error: SkeyeError) -> None:
        for sensor in (*self.sensors.values(), self.status):
            sensor.fail(error)
        with self._lock:
            motion = self._motion
            if motion is not None and not motion.error:
                motion.error = error

    def close(self) -> None:
        for sensor in self.sensors.values():
            if isinstance(sensor, CameraSensor):
                sensor.close()

    @property
    def busy(self) -> bool:
        """A motion is under way (a position hold does not count)."""
        motion = self._motion
        return motion is not None and not motion.done and not motion.holds

    # -- feedback -------------------------------------------------------------------------
    def _nav_state(self, feedback: str) -> NavState:
        sensor = self._find(FEEDBACK_TYPES[feedback])
        if sensor is None:
            raise LocalProtocolError(f"{self.name} has no {feedback} sensor for feedback")
        reading: PoseReading | None = sensor.latest
        if reading is None:
            raise LinkTimeout(f"{self.name}: no {feedback} reading yet")
        self._check_fresh(reading.time_s, feedback)
        return NavState(reading.time_s, reading.position_ned_m, reading.rpy_rad[2],
                        reading.velocity_ned_m_s)

    def _check_fresh(self, time_s: float, what: str) -> None:
        """Feedback is stale when it lags the simulator's clock by more than
        ``STALE_FEEDBACK_SIM_S`` of sim time (the sensor stopped while the world went on), or,
        in realtime, when the simulator has sent nothing at all for the connection's
        ``timeout_s``. A simulator that slips its clock (a starved process) freezes the world
        with it, so wall-clock age alone says nothing about the vehicle."""
        age = self.connection.time_s - time_s
        if age > STALE_FEEDBACK_SIM_S:
            raise LinkTimeout(f"{self.name}: the {what} reading is {age:.2f} s old (sim time)")
        if self.connection.mode != "lockstep":
            silent = self.connection.silent_s
            if silent >= self.connection.timeout_s:
                raise LinkTimeout(
                    f"{self.name}: the simulator has sent nothing for {silent:.1f} s "
                    f"(the connection's timeout_s is {self.connection.timeout_s:g} s)")

    # -- the control tick (clock thread or stepping loop) ----------------------------------
    def control_tick(self) -> None:
        with self._lock:
            motion = self._motion
            rejection, self._rejection = self._rejection, None
        if motion is None:
            return
        try:
            if rejection is not None:
                raise rejection
            state = self._nav_state(self._motion_feedback)
            status = self.status.latest
            landed = status.landed if status is not None else False
            armed = status.armed if status is not None else True
            was_done = motion.done
            command = motion.update(state, landed, armed)
            self.connection.send_message(command.to_message())
            self._last_command = command
        except SkeyeError as exc:
            self._motion_failed(motion, exc)
            return
        if motion.done and not was_done:
            self._motion_finished(motion, state)

    def _motion_failed(self, motion: Motion, exc: SkeyeError) -> None:
        log.warning("%s: %s failed: %s", self.name, motion.name, exc)
        with self._lock:
            motion.error = exc
            if self._motion is motion:
                self._motion = None
                if isinstance(exc, PhysicsError):
                    self.state = FlightState.FAILED
        if self.connection.error is None and not isinstance(exc, PhysicsError):
            try:  # stop where we are rather than keep the last velocity
                self.connection.send_message(STOP.to_message(), timeout_s=0.5)
            except SkeyeError:
                pass

    def _motion_finished(self, motion: Motion, state: NavState) -> None:
        with self._lock:
            if self._motion is not motion:
                return
            if isinstance(motion, Land):
                self.state = transition(self.state, "landed", self.name)
                self._motion = None
            elif isinstance(motion, GoTo) and not motion.holds:
                self.state = transition(self.state, "arrived", self.name)
                hold = Hold(motion.target, self.motion_config)
                hold.linear, hold.lateral = motion.linear, motion.lateral  # keep integrators
                hold.vertical, hold.angular = motion.vertical, motion.angular
                hold._last_s = state.time_s
                self._motion = hold
            elif isinstance(motion, Velocity) and motion.duration_s is not None:
                self.state = transition(self.state, "hold", self.name)
                self._motion = Hold(Target(state.position_ned_m, state.yaw_rad),
                                    self.motion_config)
            elif isinstance(motion, Velocity):
                self._motion = None  # the board keeps flying the velocity set-points

    # -- starting and waiting -------------------------------------------------------------
    def _start(
        self,
        motion: Motion,
        event: str,
        *,
        wait: bool,
        timeout_s: float | None,
        feedback: str | None,
    ) -> None:
        self.connection.check()
        fb = self._check_feedback(feedback or self.feedback)
        with self._lock:
            new_state = transition(self.state, event, self.name)
            old = self._motion
            if old is not None and not old.done and old.error is None:
                old.error = MotionCancelled(
                    f"{self.name}: {old.name} was replaced by {motion.name}"
                )
            motion.error = None
            self.state = new_state
            self._motion = motion
            self._motion_feedback = fb
            self._rejection = None
        if wait:
            self.wait_done(timeout_s, motion=motion)

    def wait_done(self, timeout_s: float | None = None, *, motion: Motion | None = None) -> None:
        """Block until the current motion is done (lockstep: stepping the simulator).

        Raises:
            MotionCancelled: another command replaced it, or :meth:`cancel` was called.
            MotionFailed: it ran out of its sim-time budget.
            CommandRejected / PhysicsError / LinkClosed / LinkTimeout: as it happened.
        """
        target = motion if motion is not None else self._motion
        if target is None:
            self.connection.check()
            return
        if timeout_s is None:
            timeout_s = self.connection.timeout_s + 3.0 * (target.sim_timeout_s or 30.0)

        def finished() -> bool:
            return target.done or target.error is not None

        self.connection.clock.wait_until(finished, timeout_s, f"{self.name} {target.name}")
        error = target.error
        if error is not None:
            raise error

    def cancel(self) -> None:
        """Abandon the current motion (its waiters get MotionCancelled) and hold position."""
        self.hover()

    # -- motion commands ------------------------------------------------------------------
    def _target_yaw(self, state: NavState) -> float:
        motion = self._motion
        if isinstance(motion, GoTo) and motion.target.yaw_rad is not None:
            return motion.target.yaw_rad
        return state.yaw_rad

    def take_off(
        self,
        altitude_m: float = 1.0,
        *,
        wait: bool = True,
        timeout_s: float | None = None,
        feedback: str | None = None,
        tolerance_m: float | None = None,
        max_climb_m_s: float | None = None,
    ) -> None:
        """Climb to ``altitude_m`` above the spawn point's height, holding position after."""
        if not (is_finite_number(altitude_m) and altitude_m > 0):
            raise LocalProtocolError(f"take_off: altitude_m must be a finite number > 0, got "
                                     f"{altitude_m!r}")
        state = self._nav_state(self._check_feedback(feedback or self.feedback))
        n, e, _ = state.position_ned_m
        target = Target((n, e, self.home_ned_m[2] - altitude_m), state.yaw_rad)
        climb = self.motion_config.take_off_speed_m_s if max_climb_m_s is None else max_climb_m_s
        motion = GoTo(target, self.motion_config, name="take_off", start=state,
                      max_climb_m_s=min(climb, self.motion_config.max_climb_m_s),
                      tolerance_m=tolerance_m)
        self._start(motion, "take_off", wait=wait, timeout_s=timeout_s, feedback=feedback)

    def fly_to(
        self,
        north_m: float,
        east_m: float,
        altitude_m: float,
        *,
        yaw_rad: float | None = None,
        wait: bool = True,
        timeout_s: float | None = None,
        feedback: str | None = None,
        tolerance_m: float | None = None,
        max_speed_m_s: float | None = None,
        max_climb_m_s: float | None = None,
    ) -> None:
        """Fly to a world position (NED north/east, altitude up positive), then hold it.

        ``yaw_rad`` turns to a heading on the way (default: keep the current one).
        """
        state = self._nav_state(self._check_feedback(feedback or self.feedback))
        yaw = self._target_yaw(state) if yaw_rad is None else yaw_rad
        motion = GoTo(Target((north_m, east_m, -altitude_m), yaw), self.motion_config,
                      start=state, tolerance_m=tolerance_m, max_speed_m_s=max_speed_m_s,
                      max_climb_m_s=max_climb_m_s)
        self._start(motion, "move", wait=wait, timeout_s=timeout_s, feedback=feedback)

    def fly_to_gps(
        self,
        lat_deg: float,
        lon_deg: float,
        altitude_m: float,
        *,
        wait: bool = True,
        timeout_s: float | None = None,
        feedback: str | None = None,
        tolerance_m: float | None = None,
        max_speed_m_s: float | None = None,
    ) -> None:
        """Fly to a latitude/longitude at ``altitude_m`` (the same altitude as :meth:`fly_to`).

        The geodetic target becomes a world target through the latest GPS fix: the offset from
        the fix to the target (local tangent plane) is added to the navigation position at the
        fix's time. GPS error therefore moves the end point as it would on a real vehicle.

        Raises:
            LinkTimeout: no GPS fix (indoors, or no GPS reading yet).
        """
        fb = self._check_feedback(feedback or self.feedback)
        fix = self.gps.latest
        if fix is None or not fix.fix or fix.latitude_deg is None or fix.longitude_deg is None:
            raise LinkTimeout(f"{self.name}: no GPS fix to navigate by")
        here = GeoOrigin(fix.latitude_deg, fix.longitude_deg, 0.0)
        dn, de, _ = here.to_ned(lat_deg, lon_deg, 0.0)
        sensor = self._find(FEEDBACK_TYPES[fb])
        assert sensor is not None
        history = list(sensor.history)
        if not history:
            raise LinkTimeout(f"{self.name}: no {fb} reading yet")
        at_fix = min(history, key=lambda r: abs(r.time_s - fix.time_s))
        n0, e0, _ = at_fix.position_ned_m
        self.fly_to(n0 + dn, e0 + de, altitude_m, wait=wait, timeout_s=timeout_s, feedback=fb,
                    tolerance_m=tolerance_m, max_speed_m_s=max_speed_m_s)

    def move_by(
        self,
        forward_m: float = 0.0,
        right_m: float = 0.0,
        up_m: float = 0.0,
        yaw_rad: float = 0.0,
        *,
        frame: str = "body",
        wait: bool = True,
        timeout_s: float | None = None,
        feedback: str | None = None,
        tolerance_m: float | None = None,
        max_speed_m_s: float | None = None,
    ) -> None:
        """Move relative to the current target (or position): ``frame="body"`` takes forward/right
        along the current heading, ``frame="world"`` takes them as north/east."""
        if frame not in ("body", "world"):
            raise LocalProtocolError(f"move_by: frame must be 'body' or 'world', got {frame!r}")
        state = self._nav_state(self._check_feedback(feedback or self.feedback))
        motion = self._motion
        if isinstance(motion, GoTo) and self.state in (FlightState.HOLDING, FlightState.FLYING):
            base = motion.target.position_ned_m
        else:
            base = state.position_ned_m
        base_yaw = self._target_yaw(state)
        if frame == "body":
            dn, de = body_to_world(forward_m, right_m, base_yaw)
        else:
            dn, de = forward_m, right_m
        target = Target((base[0] + dn, base[1] + de, base[2] - up_m), base_yaw + yaw_rad)
        motion = GoTo(target, self.motion_config, name="move_by", start=state,
                      tolerance_m=tolerance_m, max_speed_m_s=max_speed_m_s)
        self._start(motion, "move", wait=wait, timeout_s=timeout_s, feedback=feedback)

    def set_velocity(
        self,
        forward_m_s: float = 0.0,
        right_m_s: float = 0.0,
        up_m_s: float = 0.0,
        yaw_rate_rad_s: float = 0.0,
        *,
        duration_s: float | None = None,
        wait: bool = True,
        timeout_s: float | None = None,
        board_mode: str | None = None,
    ) -> None:
        """Fly velocity set-points (heading frame); for ``duration_s`` then hover, or until
        the next command when ``duration_s`` is None (then it returns at once).
        ``board_mode="gps"``: the board's GPS mode (``DRIVE {BoardMode gps}``: zero horizontal
        set-points hold the GPS position while there is a fix, docs/protocols/simulator.md)."""
        if board_mode not in (None, "gps"):
            raise LocalProtocolError(f"set_velocity: board_mode must be None or 'gps', "
                                     f"got {board_mode!r}")
        cfg = self.motion_config
        for label, value, limit in (
            ("forward_m_s", forward_m_s, cfg.max_speed_m_s),
            ("right_m_s", right_m_s, cfg.max_speed_m_s),
            ("up_m_s", up_m_s, cfg.max_climb_m_s),
            ("yaw_rate_rad_s", yaw_rate_rad_s, cfg.max_yaw_rate_rad_s),
        ):
            if not is_finite_number(value):
                raise LocalProtocolError(f"set_velocity: {label} must be a finite number, got "
                                         f"{value!r}")
            if abs(value) > limit + 1e-9:
                raise LocalProtocolError(f"set_velocity: {label}={value} exceeds the limit {limit}")
        motion = Velocity(DriveCommand(forward_m_s, right_m_s, up_m_s, yaw_rate_rad_s,
                                       board_mode), duration_s)
        self._start(motion, "velocity", wait=wait, timeout_s=timeout_s, feedback=None)

    def hover(self, *, feedback: str | None = None) -> None:
        """Stop the current motion (its waiters get MotionCancelled) and hold position here."""
        if self.state is FlightState.LANDED:
            with self._lock:
                old = self._motion
                if old is not None and not old.done:
                    old.error = MotionCancelled(f"{self.name}: {old.name} was cancelled")
                self._motion = None
            return
        state = self._nav_state(self._check_feedback(feedback or self.feedback))
        hold = Hold(Target(state.position_ned_m, state.yaw_rad), self.motion_config)
        hold.name = "hover"
        self._start(hold, "hold", wait=False, timeout_s=None, feedback=feedback)

    def land(
        self, *, wait: bool = True, timeout_s: float | None = None, feedback: str | None = None
    ) -> None:
        """Descend where it is until the vehicle reports landed and disarmed."""
        if self.state is FlightState.LANDED and self.landed:
            return
        state = self._nav_state(self._check_feedback(feedback or self.feedback))
        self._start(Land(self.motion_config, state), "land", wait=wait, timeout_s=timeout_s,
                    feedback=feedback)

    @contextmanager
    def flight(
        self, take_off_m: float | None = None, *, on_exit: str = "land"
    ) -> Iterator[Robot]:
        """A flight that fails safe: on any exit, errors included, land (or hold).

        Args:
            take_off_m: take off to this altitude on entry (None: do not).
            on_exit: ``"land"`` or ``"hold"``.
        """
        if on_exit not in ("land", "hold"):
            raise LocalProtocolError(f"flight: on_exit must be 'land' or 'hold', got {on_exit!r}")
        try:
            if take_off_m is not None:
                self.take_off(take_off_m)
            yield self
        finally:
            if self.connection.error is None and self.state is not FlightState.FAILED:
                try:
                    if on_exit == "land":
                        self.land()
                    else:
                        self.hover()
                except SkeyeError as exc:
                    log.error("%s: could not %s on leaving the flight: %s", self.name, on_exit,
                              exc)
                    raise


class Hummingbird(Robot):
    """AscTec Hummingbird-class quadrotor (the simulator's default robot)."""

    class_name = "hummingbird"


class AirRobot(Robot):
    """USARSim's AirRobot (2 m/s, 100 deg/s limits)."""

    class_name = "airrobot"


ROBOT_CLASSES: dict[str, type[Robot]] = {c.class_name: c for c in (Hummingbird, AirRobot)}


def robot_class(name: str) -> type[Robot]:
    """The robot class for a simulator class name (``USARBot.`` prefix optional).

    A class the client has no subclass for (a robot file of your own) gets a plain Robot
    subclass of that name; the simulator decides whether it exists.
    """
    key = name.strip().lower().removeprefix("usarbot.")
    if not key or any(c.isspace() or c in "{}" for c in key):
        raise LocalProtocolError(f"bad robot class name {name!r}")
    found = ROBOT_CLASSES.get(key)
    if found is not None:
        return found
    return type(key.capitalize(), (Robot,), {"class_name": key})


__all__ = [
    "TRANSITIONS",
    "AirRobot",
    "FlightState",
    "Hummingbird",
    "Robot",
    "robot_class",
    "transition",
]
