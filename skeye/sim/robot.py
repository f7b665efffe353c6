"""One simulated vehicle at run time: its board (controller, motors, battery) and its sensors.

How this works: the engine calls :meth:`Robot.board_tick` every board period with the vehicle's
ground-truth :class:`BodyState`; the robot takes the onboard estimate from its board
estimator (:mod:`skeye.sim.estimator`, fed by :meth:`Robot.observe` with the readings of the
board's sensors, never ground truth) or, with ``--estimator truth``, from its INS sensor's
oracle (ground truth plus small error processes), runs the low-level controller on it,
advances the motors and the battery, and returns the wrench (NED force and torque on the
centre of mass) for the engine to apply. Sensors are sampled by the engine when due (the
board's sensors' readings also go to :meth:`Robot.observe`); the robot never touches MuJoCo.

Flight state (``armed``, ``landed``) follows a small table: a robot spawned on the ground is
disarmed; any DRIVE that asks for motion arms it; a robot that is landed and asked to go no
higher for one second disarms (motors stop), as the AscTec board does. A robot whose crash
detector fires (:mod:`skeye.sim.crash`: tumbled, or a hard impact) is crashed: its motors stop,
as PX4's flight termination stops them, and every DRIVE is refused until the engine resets it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np

from skeye.errors import ConfigError, LocalProtocolError, PhysicsError
from skeye.geo import MAX_POSITION_M
from skeye.robots.config import CAMERA_TYPE, MOTORS_TYPE, RobotConfig, SensorMount
from skeye.robots.params import ESTIMATOR_KINDS, AirframeParams
from skeye.sim.cameras import CameraSpec
from skeye.sim.controller import Command, LowLevelController
from skeye.sim.crash import CrashDetector
from skeye.sim.estimator import BoardEstimator, from_sensor_figures
from skeye.sim.readings import Event, ReadingSink, SensorSample, StatusReading
from skeye.sim.sensors import (
    INS,
    Mount,
    Param,
    Reading,
    Sensor,
    WorldQuery,
    build_sensor,
    parse_params,
)
from skeye.sim.state import BodyState
from skeye.sim.vehicle import Battery, RotorModel, ground_effect_factor
from skeye.wire.sim import sen_layout
from skeye.wire.sim_format import Layout
from skeye.wire.sim_messages import SenMotors


@dataclass
class ScheduledSensor:
    """A mounted sensor with its period in physics steps."""

    sensor: Any
    period_steps: int
    mount: SensorMount
    board: bool = False  # the board's estimator takes its readings (Robot.observe)

    def __post_init__(self) -> None:
        # Typed once, for the hot path: a call on ``Any`` is a generic Python call.
        sensor = self.sensor
        self.reader: Sensor[Any] | None = sensor if isinstance(sensor, Sensor) else None
        self.type_name: str = sensor.type_name
        self.name: str = self.mount.name

    def read(self, state: BodyState, world: WorldQuery) -> Any:
        """One typed reading of this sensor."""
        reader = self.reader
        if reader is not None:
            return reader.read(state, world)
        return self.sensor.read(state, world)

    def sample(self, state: BodyState, world: WorldQuery) -> SensorSample:
        """One typed reading of this sensor, named for the robot's sink."""
        return SensorSample(self.type_name, self.name, self.read(state, world))


BOARD_SENSOR_TYPES: Final = (
    "Gyro", "Accelerometer", "MagneticCompass", "Barometer", "Sonar", "OpticalFlow", "GPS"
)
"""The sensors the board's estimator reads: the first mounted one of each type aligned with the
body (so Sonar and OpticalFlow look straight down), else one the board has but does not
stream."""

POWER_UP_S: Final = 1.0
"""How long the board's power-up calibration averages its gyro and accelerometer (at rest)."""

_MOTORS_LAYOUT: Final[Layout] = sen_layout(SenMotors, counts={"Speeds": 4, "Commands": 4})


@dataclass
class MotorsReading(Reading):
    speeds_rad_s: tuple[float, float, float, float]
    commands_rad_s: tuple[float, float, float, float]
    thrust_n: float

    def __init__(
        self,
        time_s: float,
        speeds_rad_s: tuple[float, float, float, float],
        commands_rad_s: tuple[float, float, float, float],
        thrust_n: float,
    ) -> None:
        self.time_s = time_s
        self.speeds_rad_s = speeds_rad_s
        self.commands_rad_s = commands_rad_s
        self.thrust_n = thrust_n

    def layout(self) -> Layout:
        return _MOTORS_LAYOUT

    def values(self) -> tuple[object, ...]:
        return (*self.speeds_rad_s, *self.commands_rad_s, self.thrust_n)


class MotorsSensor:
    """Rotor speeds as the ESCs report them (rad/s); skeye's extension, used to check lag."""

    type_name = "Motors"

    def __init__(self, name: str, rotors: RotorModel, rate_hz: float) -> None:
        self.name = name
        self.rotors = rotors
        self.rate_hz = rate_hz
        self.last: MotorsReading | None = None

    def read(self, state: BodyState, world: WorldQuery) -> MotorsReading:
        s0, s1, s2, s3 = self.rotors.speed_rad_s
        c0, c1, c2, c3 = self.rotors.command_rad_s
        self.last = MotorsReading(
            state.time_s, (s0, s1, s2, s3), (c0, c1, c2, c3), self.rotors.total_thrust_n()
        )
        return self.last

    def sample(self, state: BodyState, world: WorldQuery) -> list[tuple[str, object]]:
        return self.read(state, world).fields()

    def conf_fields(self) -> list[tuple[str, object]]:
        return [("Rate", self.rate_hz), ("MaxSpeed", self.rotors.p.max_rotor_speed_rad_s)]

    def geo_fields(self) -> list[tuple[str, object]]:
        return [("Location", (0.0, 0.0, 0.0)), ("Orientation", (0.0, 0.0, 0.0))]


MOTORS_PARAMS: Final = (Param("Rate", 100.0, "sample rate, Hz", exclusive=True),)
"""The parameters of the Motors sensor (``rate_hz`` or ``Rate``), parsed as every sensor's."""


def period_steps(rate_hz: float, physics_step_s: float, what: str) -> int:
    """The period of a rate in physics steps (at least 1).

    Raises:
        ConfigError: a rate so low that its period is no finite number of steps, or above the
            physics rate, which no sampling once per step can give (``what`` names the file
            and the key).
    """
    check_rate(rate_hz, physics_step_s, what)
    steps = 1.0 / (rate_hz * physics_step_s)
    if not math.isfinite(steps):
        raise ConfigError(
            f"{what} {rate_hz!r} Hz is too low: its period is no finite number of "
            f"{physics_step_s:g} s physics steps"
        )
    return max(1, round(steps))


def check_rate(rate_hz: float, physics_step_s: float, what: str) -> None:
    """Refuse a rate above the physics rate: a sensor (a camera, the status) is sampled at
    most once per physics step, so it would run at the physics rate while its CONF and the
    board's estimator took the file's rate.

    Raises:
        ConfigError: the rate is above ``1 / physics_step_s`` (``what`` names the file and
            the key).
    """
    if rate_hz * physics_step_s > 1.0 + 1e-9:
        raise ConfigError(
            f"{what} {rate_hz!r} Hz is above the physics rate {1.0 / physics_step_s:g} Hz "
            f"(--timestep {physics_step_s:g} s): nothing is sampled more than once per "
            "physics step"
        )


def board_decimation(config: RobotConfig, physics_step_s: float) -> int:
    """The board period in physics steps.

    Raises:
        ConfigError: ``board_rate_hz`` is not an integer fraction of the physics rate.
    """
    steps = 1.0 / (config.board_rate_hz * physics_step_s)
    decimation = round(steps) if math.isfinite(steps) else 0
    if decimation < 1 or abs(decimation * physics_step_s * config.board_rate_hz - 1.0) > 1e-6:
        raise ConfigError(
            f"{config.source}: board_rate_hz {config.board_rate_hz!r}: the board rate is not an "
            f"integer fraction of the physics rate {1.0 / physics_step_s:g} Hz"
        )
    return decimation


def mount_sensors(
    config: RobotConfig, physics_step_s: float, rotors: RotorModel, rng: np.random.Generator
) -> tuple[list[ScheduledSensor], list[CameraSpec]]:
    """Build a robot file's sensors (scheduled) and cameras, in the file's order; each sensor
    other than Motors takes a Generator seeded from ``rng``, one draw each, in that order.

    Raises:
        ConfigError: a bad sensor or camera entry, named with the file, the key and the value.
    """
    sensors: list[ScheduledSensor] = []
    cameras: list[CameraSpec] = []
    for i, mount in enumerate(config.sensors):
        type_key = mount.type_name.lower()
        params = dict(mount.params)
        if type_key == CAMERA_TYPE:
            camera = CameraSpec.from_mount(mount, config.source)  # names the file
            check_rate(camera.rate_hz, physics_step_s,
                       f"{config.source} camera {mount.name!r}: rate_hz")
            cameras.append(camera)
            continue
        where = f"{config.source} sensors[{i}]"
        try:
            if type_key == MOTORS_TYPE:
                rate = parse_params(mount.name, "Motors", MOTORS_PARAMS, params)["Rate"]
                sensor: Any = MotorsSensor(mount.name, rotors, rate)
            else:
                sensor = build_sensor(
                    mount.type_name,
                    mount.name,
                    Mount(mount.position_m, mount.direction_rad),
                    params,
                    np.random.default_rng(rng.integers(0, 2**63)),
                )
            period = period_steps(sensor.rate_hz, physics_step_s, "rate_hz")
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        sensors.append(ScheduledSensor(sensor, period, mount))
    return sensors, cameras


def check_robot_config(
    config: RobotConfig, physics_step_s: float, estimator: str | None = None
) -> None:
    """Run every check building a :class:`Robot` of this class runs, without a simulation
    (``skeye sim --robot-dir`` runs it at start-up, so a file INIT would refuse stops it).
    ``estimator`` is ``skeye sim --estimator``, over the file's ``[estimator] kind`` as at INIT
    (the board's filter, built for ``onboard``, has checks of its own).

    Raises:
        ConfigError: what INIT would answer, naming the file, the key and the value.
    """
    try:  # a robot of this class, as INIT builds one (its board's estimator too), off the ground
        Robot("check", config, physics_step_s=physics_step_s, rng=np.random.default_rng(0),
              sink=_no_readings, spawn_pos_ned_m=(0.0, 0.0, -1.0),
              spawn_rpy_rad=(0.0, 0.0, 0.0), airborne=False, estimator=estimator)
    except ConfigError as exc:
        text = str(exc)
        raise ConfigError(text if text.startswith(config.source)
                          else f"{config.source}: {text}") from None


def _no_readings(events: list[Event]) -> None:
    """The sink of the robot :func:`check_robot_config` builds: it never steps."""


@dataclass
class FlightState:
    armed: bool = False
    landed: bool = True
    landed_since_s: float = 0.0
    failed: str | None = None
    crashed: str | None = None  # the crash's cause (skeye.sim.crash), until a reset
    extra: dict[str, Any] = field(default_factory=dict)


class Robot:
    """A vehicle bound to one client connection (USARSim: one robot per connection)."""

    def __init__(
        self,
        name: str,
        config: RobotConfig,
        *,
        physics_step_s: float,
        rng: np.random.Generator,
        sink: ReadingSink,
        spawn_pos_ned_m: tuple[float, float, float],
        spawn_rpy_rad: tuple[float, float, float],
        airborne: bool,
        estimator: str | None = None,
        declination_rad: float = 0.0,
    ) -> None:
        """``estimator`` overrides the robot file's ``[estimator] kind`` ("onboard"/"truth");
        ``declination_rad`` is the local magnetic declination the board is configured with."""
        self.name = name
        self.config = config
        self.sink = sink
        self.spawn_pos_ned_m = spawn_pos_ned_m
        self.spawn_rpy_rad = spawn_rpy_rad
        decimation = board_decimation(config, physics_step_s)
        self.board_decimation = decimation
        self.tick_s = decimation * physics_step_s
        self.rotors = RotorModel(config.airframe, self.tick_s)
        self.controller = LowLevelController(config.airframe, config.controller, self.tick_s)
        self.battery = Battery(config.battery, RotorModel.hover_power_w(config.airframe))
        self.command = Command()
        self.flight = FlightState()
        self.crash = CrashDetector()
        self.crash_news: str | None = None
        """A crash's cause, set on the tick it happened; the engine reports and clears it."""
        self.spawn_airborne = airborne
        self.status_period_steps = period_steps(
            config.status_rate_hz, physics_step_s, f"{config.source}: status_rate_hz"
        )
        # The engine's schedule: the periods (steps) of the sensors and the status, and the next
        # step at which one of them falls due (skeye.sim.engine keeps them).
        self.sensing_periods: list[int] = []
        self.next_sensing_step = 0
        self.sensors: list[ScheduledSensor]
        self.cameras: list[CameraSpec]
        self.sensors, self.cameras = mount_sensors(config, physics_step_s, self.rotors, rng)
        ins: INS | None = None
        for sched in self.sensors:
            if isinstance(sched.sensor, INS):
                ins = sched.sensor
                break
        if ins is None:
            # The board always has an estimator, even when no INS is streamed to the client.
            built = build_sensor(
                "INS", "INS", Mount(), {}, np.random.default_rng(rng.integers(0, 2**63))
            )
            assert isinstance(built, INS)
            ins = built
        self.ins: INS = ins
        kind = estimator if estimator is not None else config.estimator.kind
        if kind not in ESTIMATOR_KINDS:
            raise ConfigError(f"estimator must be one of {list(ESTIMATOR_KINDS)}, got {kind!r}")
        self.estimator_kind = kind
        self.board_sensors: list[ScheduledSensor] = []  # sampled for the board, not streamed
        self.estimator: BoardEstimator | None = None
        if kind == "onboard":
            try:  # a sensor figure the board's filter cannot take: named with the file
                self.estimator = self._build_estimator(physics_step_s, rng, declination_rad)
            except ConfigError as exc:
                raise ConfigError(f"{config.source}: {exc}") from None
            self.ins.board = self.estimator
        self.ground_effect = 1.0
        self.airframe: AirframeParams = config.airframe  # typed: the board reads it every tick
        self._full_voltage_v = config.battery.cells * 4.2
        self._half_body_height_m = config.airframe.body_size_m[2] / 2
        self.ground_distance_m: float | None = None
        if airborne:
            self.flight.armed = True
            self.flight.landed = False
            self.rotors.set_speeds(config.airframe.hover_speed_rad_s)

    def _build_estimator(
        self, physics_step_s: float, rng: np.random.Generator, declination_rad: float
    ) -> BoardEstimator:
        """Pick (or add) the board's sensors and start its estimator at the spawn pose."""
        chosen: dict[str, ScheduledSensor] = {}
        for sched in self.sensors:
            type_name = sched.sensor.type_name
            if type_name not in BOARD_SENSOR_TYPES or type_name in chosen:
                continue
            if any(abs(a) > 1e-9 for a in sched.mount.direction_rad):
                continue  # the board's own sensors are aligned with the body (range: down)
            sched.board = True
            chosen[type_name] = sched
        for type_name in BOARD_SENSOR_TYPES:
            if type_name in chosen:
                continue
            name = f"Board{type_name}"
            sensor = build_sensor(
                type_name, name, Mount(), {}, np.random.default_rng(rng.integers(0, 2**63))
            )
            period = max(1, round(1.0 / (sensor.rate_hz * physics_step_s)))
            sched = ScheduledSensor(
                sensor, period, SensorMount(type_name, name, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), ()),
                True,
            )
            self.board_sensors.append(sched)
            chosen[type_name] = sched
        board = {name: sched.sensor for name, sched in chosen.items()}
        board["Gyro"].share_board(board["Accelerometer"])
        params = from_sensor_figures(
            self.config.estimator, board["Accelerometer"], board["Gyro"], board["Barometer"],
            board["Sonar"], board["OpticalFlow"], board["GPS"],
        )
        estimator = BoardEstimator(
            params,
            self.spawn_pos_ned_m,
            self.spawn_rpy_rad,
            declination_rad,
            float(board["OpticalFlow"].counts_per_rad),
        )
        estimator.sonar_half_beam_rad = 0.5 * float(board["Sonar"].params["BeamAngle"])
        return estimator

    def power_up(self, state: BodyState, world: WorldQuery) -> None:
        """The board's power-up calibration at the spawn pose, the vehicle still: one second's
        worth of its own gyro and accelerometer readings (at their rates) go to the estimator's
        :meth:`BoardEstimator.align_at_rest`. Readings only, never ground truth."""
        estimator = self.estimator
        if estimator is None:
            return
        # The calibration runs with the motors off (a vehicle spawned in the air calibrated on
        # the ground before it took off): no rotor vibration in these readings.
        state = BodyState(state.time_s, state.pos_ned_m, state.vel_ned_m_s, state.quat_ned,
                          state.rpy_rad, state.rot_body_to_ned, state.omega_frd_rad_s,
                          state.accel_ned_m_s2, state.specific_force_frd_m_s2)
        gyro: list[tuple[float, float, float]] = []
        accel: list[tuple[float, float, float]] = []
        for sched in self.sensors + self.board_sensors:
            if not sched.board:
                continue
            sensor = sched.sensor
            if sensor.type_name == "Gyro":
                for _ in range(max(1, round(sensor.rate_hz * POWER_UP_S))):
                    gyro.append(sensor.read(state, world).angular_velocity_rad_s)
            elif sensor.type_name == "Accelerometer":
                for _ in range(max(1, round(sensor.rate_hz * POWER_UP_S))):
                    accel.append(sensor.read(state, world).proper_acceleration_m_s2)
        estimator.align_at_rest(gyro, accel)

    def observe(self, reading: object) -> None:
        """A reading of one of the board's sensors, for its estimator."""
        if self.estimator is not None:
            self.estimator.observe(reading)

    # -- commands ------------------------------------------------------------------------
    def drive(self, **changes: float | bool) -> None:
        """Update the set-point; arms the motors when the command asks for motion.

        Each value sets its own axis and selects that axis's form (USARSim's
        ``AerialVehicle.Drive``): ``pitch_rad`` / ``forward_m_s`` the pitch axis, ``roll_rad`` /
        ``right_m_s`` the roll axis, ``thrust`` / ``up_m_s`` the vertical axis; an axis not
        named keeps its form and value. ``attitude`` (True or False) first puts every axis in
        that form with its values cleared. A switch of all three axes at once resets the
        controller, as a change of mode does; a switch of some resets only theirs."""
        if self.flight.failed:
            raise LocalProtocolError(f"robot {self.name} is stopped: {self.flight.failed}")
        if self.flight.crashed:
            raise LocalProtocolError(
                f"robot {self.name} crashed ({self.flight.crashed}): send RESET to bring it back"
            )
        c = self.command
        form = changes.pop("attitude", None)
        if form is not None:
            whole = bool(form)
            if not (c.attitude if whole else c.velocity):
                c = self.command = Command(pitch_angle=whole, roll_angle=whole,
                                           thrust_vertical=whole)
                self.controller.reset()
        if "gps_mode" in changes:
            c.gps_mode = bool(changes.pop("gps_mode"))
        if "height_mode" in changes:
            c.height_mode = bool(changes.pop("height_mode"))
        pitch = roll = vertical = False
        for key, value in changes.items():
            if key == "pitch_rad" or key == "forward_m_s":
                if c.pitch_angle != (key == "pitch_rad"):
                    c.pitch_angle = key == "pitch_rad"
                    c.pitch_rad = c.forward_m_s = 0.0
                    pitch = True
            elif key == "roll_rad" or key == "right_m_s":
                if c.roll_angle != (key == "roll_rad"):
                    c.roll_angle = key == "roll_rad"
                    c.roll_rad = c.right_m_s = 0.0
                    roll = True
            elif (key == "thrust" or key == "up_m_s") and c.thrust_vertical != (key == "thrust"):
                c.thrust_vertical = key == "thrust"
                c.thrust = c.up_m_s = 0.0
                vertical = True
            setattr(c, key, float(value))
        if pitch and roll and vertical:
            self.controller.reset()
        elif pitch or roll or vertical:
            self.controller.reset_axes(pitch, roll, vertical)
        if self._wants_motion() and not self.flight.armed and not self.battery.empty:
            self.flight.armed = True
            self.controller.reset()

    def _wants_motion(self) -> bool:
        """Whether the set-point asks the vehicle to move: a thrust stick above 0, a climb, or
        (with a climb-rate vertical axis) a horizontal velocity or a yaw rate."""
        c = self.command
        if c.thrust_vertical:
            return c.thrust > 0.0
        return (
            c.up_m_s > 0.0
            or (not c.pitch_angle and c.forward_m_s != 0.0)
            or (not c.roll_angle and c.right_m_s != 0.0)
            or c.yaw_rate_rad_s != 0.0
        )

    # -- the board -----------------------------------------------------------------------
    def board_tick(
        self,
        state: BodyState,
        ground_distance_m: float | None,
        in_contact: bool,
        air_vel_ned: tuple[float, float, float],
        closing_m_s: float = 0.0,
    ) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """Advance the board one tick; returns (force NED N, torque NED N m) on the body.
        ``closing_m_s``: the speed at which it meets another robot it touches now (0: none;
        :class:`~skeye.sim.crash.CrashDetector`'s).

        Hot path (every board tick of every robot): plain floats throughout.
        """
        if self.flight.failed:
            return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        roll, pitch, _ = state.rpy_rad
        cause = self.crash.update(state.time_s, roll, pitch, state.vel_ned_m_s, in_contact,
                                  closing_m_s)
        if cause is not None:
            self._crashed(cause)
        estimator = self.estimator
        est = estimator.estimate() if estimator is not None else self.ins.estimate_now(state)
        gps_hold = estimator.has_gps_fix(state.time_s) if estimator is not None else False
        airframe = self.airframe
        battery = self.battery
        # A brushless motor's top speed is its Kv times the voltage it gets (less its own
        # resistive drop): the airframe's top speed at a full battery, scaled by the battery's
        # voltage under load now (docs/physics.md, Battery and endurance).
        w_max = airframe.max_rotor_speed_rad_s * min(1.0, battery.voltage_v / self._full_voltage_v)
        if self.flight.armed and not battery.empty:
            pos, vel = est.pos_ned_m, est.vel_ned_m_s
            if estimator is not None and self.command.attitude and self.command.height_mode:
                # The AscTec LL board's height mode holds its pressure altitude.
                down, rate = estimator.pressure_down()
                pos, vel = (pos[0], pos[1], down), (vel[0], vel[1], rate)
            commands = self.controller.update(
                self.command,
                est.rpy_rad,
                est.omega_frd_rad_s,
                vel,
                pos,
                w_max,
                gps_hold,
            )
        else:
            commands = [0.0, 0.0, 0.0, 0.0]
            if estimator is not None:  # motors off: the board takes itself to be at rest
                estimator.at_rest(state.time_s)
        self.rotors.advance(commands, w_max)
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = state.rot_body_to_ned
        vn, ve, vd = state.vel_ned_m_s
        an, ae, ad = vn - air_vel_ned[0], ve - air_vel_ned[1], vd - air_vel_ned[2]
        vb = (
            r00 * an + r10 * ae + r20 * ad,
            r01 * an + r11 * ae + r21 * ad,
            r02 * an + r12 * ae + r22 * ad,
        )
        self.ground_distance_m = ground_distance_m
        rotor_height = None
        if ground_distance_m is not None:
            rotor_height = ground_distance_m + self._half_body_height_m
        self.ground_effect = ground_effect_factor(rotor_height, airframe.rotor_radius_m)
        fx, fy, fz, tx, ty, tz, power = self.rotors.wrench(vb, self.ground_effect)
        battery.draw(power, self.tick_s)
        if (fx + fy + fz + tx + ty + tz) - (fx + fy + fz + tx + ty + tz) != 0.0:
            raise PhysicsError(f"robot {self.name}: non-finite rotor wrench")
        force = (
            r00 * fx + r01 * fy + r02 * fz,
            r10 * fx + r11 * fy + r12 * fz,
            r20 * fx + r21 * fy + r22 * fz,
        )
        torque = (
            r00 * tx + r01 * ty + r02 * tz,
            r10 * tx + r11 * ty + r12 * tz,
            r20 * tx + r21 * ty + r22 * tz,
        )
        self._update_flight_state(state, in_contact)
        return force, torque

    def _crashed(self, cause: str) -> None:
        """Flight termination: motors off, set-points cleared, DRIVE refused until a reset."""
        f = self.flight
        f.crashed = cause
        f.armed = False
        c = self.command  # each axis keeps its form, its set-point cleared
        self.command = Command(pitch_angle=c.pitch_angle, roll_angle=c.roll_angle,
                               thrust_vertical=c.thrust_vertical)
        self.controller.reset()
        self.crash_news = cause

    def _update_flight_state(self, state: BodyState, in_contact: bool) -> None:
        f = self.flight
        vx, vy, vz = state.vel_ned_m_s
        landed_now = in_contact and vx * vx + vy * vy + vz * vz < 0.09  # under 0.3 m/s
        if landed_now and not f.landed:
            f.landed_since_s = state.time_s
        f.landed = landed_now
        c = self.command
        asks_up = (c.thrust > 0.3) if c.thrust_vertical else (c.up_m_s > 0.0)
        if f.armed and f.landed and not asks_up and state.time_s - f.landed_since_s >= 1.0:
            f.armed = False
            self.command = Command(pitch_angle=c.pitch_angle, roll_angle=c.roll_angle,
                                   thrust_vertical=c.thrust_vertical)
            self.controller.reset()
        if self.battery.empty and f.armed:
            f.armed = False

    def status(self, time_s: float) -> StatusReading:
        """The robot's status now (the protocol's ``STA``; fields: :meth:`status_fields`)."""
        b, f = self.battery, self.flight
        return StatusReading(self.name, time_s, b.remaining_s, b.voltage_v, b.current_a,
                             f.armed, f.landed)

    def status_fields(self) -> list[tuple[str, object]]:
        return [
            ("Battery", int(self.battery.remaining_s)),  # whole seconds, as USARSim
            ("Voltage", self.battery.voltage_v),
            ("Current", self.battery.current_a),
            ("Armed", self.flight.armed),
            ("Landed", self.flight.landed),
        ]

    def find_sensors(self, type_name: str, name: str | None = None) -> list[ScheduledSensor]:
        """Mounted sensors (cameras included) of a type, optionally by name."""
        everything = self.sensors + [ScheduledSensor(cam, 0, cam.mount) for cam in self.cameras]
        return [
            s
            for s in everything
            if s.sensor.type_name.lower() == type_name.lower()
            and (name is None or s.mount.name.lower() == name.lower())
        ]


MAX_SPEED_M_S: Final = 150.0
"""The runaway limits :func:`check_state` stops a robot at: a position coordinate beyond
:data:`skeye.geo.MAX_POSITION_M` (100 km) from the world's origin, a speed over 150 m/s
(540 km/h), a rotation rate over 200 rad/s (32 turns a second); no small UAV's flight comes
near them, a diverged simulation passes them."""
MAX_RATE_RAD_S: Final = 200.0


def check_state(name: str, state: BodyState) -> None:
    """Raise PhysicsError if the state is non-finite or runaway (plain floats: hot path)."""
    px, py, pz = state.pos_ned_m
    vx, vy, vz = state.vel_ned_m_s
    wx, wy, wz = state.omega_frd_rad_s
    total = px + py + pz + vx + vy + vz + wx + wy + wz
    if math.isnan(total - total):  # inf or NaN (math.isnan compiles to C; isfinite does not)
        raise PhysicsError(f"robot {name}: NaN in the simulated state")
    if (max(max(abs(px), abs(py)), abs(pz)) > MAX_POSITION_M
            or vx * vx + vy * vy + vz * vz > MAX_SPEED_M_S**2):
        raise PhysicsError(f"robot {name}: the simulation diverged (runaway position or speed)")
    if wx * wx + wy * wy + wz * wz > MAX_RATE_RAD_S**2:
        raise PhysicsError(f"robot {name}: the simulation diverged (runaway rotation rate)")
