"""Client-side sensor objects: one class per simulated sensor, all sharing :class:`Sensor`.

How this works: the connection's message-handler thread hands every ``SEN`` line of a sensor to
its object (:meth:`Sensor.update`), which decodes it through the protocol's codec table
(:mod:`skeye.wire.sim`: one layout per sensor Type, shared with the simulator) and converts it
into a frozen, typed reading (SI units,
NED world / FRD body frames, angles in (-pi, pi]), stores it as ``latest`` and in a bounded
``history``, wakes :meth:`Sensor.wait_next` callers and then runs the registered callbacks. A
callback that raises is logged and counted; it never stops the message thread. A line the parser
rejects is logged and counted the same way (the peer's error, not ours).

Invariants: readings are immutable; ``latest``/``history`` change only under the sensor's lock;
callbacks run on the message thread, outside the lock, in registration order. When the link
dies the connection calls :meth:`Sensor.fail`, which wakes every waiter with the link's error.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Generic, TypeVar

from skeye.errors import LinkTimeout, LocalProtocolError, RemoteProtocolError, SkeyeError
from skeye.geo import from_degrees_minutes
from skeye.wire.sim import decode_as
from skeye.wire.sim_lines import Message
from skeye.wire.sim_messages import (
    SenAccelerometer,
    SenBarometer,
    SenBattery,
    SenGps,
    SenGroundTruth,
    SenGyro,
    SenIns,
    SenMagneticCompass,
    SenMotors,
    SenOpticalFlow,
    SenOther,
    SenSonar,
    Sta,
)

log = logging.getLogger(__name__)

Vec3 = tuple[float, float, float]
DEFAULT_HISTORY = 100


def wrap_pi(angle_rad: float) -> float:
    """An angle wrapped to (-pi, pi] (the wire sends [0, 2 pi))."""
    wrapped = math.remainder(angle_rad, 2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


def _rpy(rpy: Vec3) -> Vec3:
    r, p, y = rpy
    return (wrap_pi(r), wrap_pi(p), wrap_pi(y))


# --- readings ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Reading:
    """Base of every reading: the sim time it was taken at."""

    time_s: float


@dataclass(frozen=True)
class PoseReading(Reading):
    """A pose estimate (GroundTruth, INS): NED position, roll/pitch/yaw, NED velocity."""

    position_ned_m: Vec3
    rpy_rad: Vec3
    velocity_ned_m_s: Vec3 | None

    @property
    def altitude_m(self) -> float:
        """Height above the world origin (up positive)."""
        return -self.position_ned_m[2]

    @property
    def yaw_rad(self) -> float:
        return self.rpy_rad[2]


@dataclass(frozen=True)
class GroundTruthReading(PoseReading):
    angular_velocity_frd_rad_s: Vec3


@dataclass(frozen=True)
class InsReading(PoseReading):
    position_sigma_ned_m: Vec3 | None = None
    """The estimator's 1-sigma per position axis (m), None where the simulator sends none."""


@dataclass(frozen=True)
class AccelerometerReading(Reading):
    proper_acceleration_frd_m_s2: Vec3


@dataclass(frozen=True)
class GyroReading(Reading):
    angular_velocity_frd_rad_s: Vec3


@dataclass(frozen=True)
class CompassReading(Reading):
    heading_rad: float
    field_frd_ut: Vec3


@dataclass(frozen=True)
class BarometerReading(Reading):
    pressure_pa: float
    altitude_m: float


@dataclass(frozen=True)
class GpsReading(Reading):
    """A GPS fix; without a fix (indoors) every position field is None."""

    fix: bool
    satellites: int
    latitude_deg: float | None
    longitude_deg: float | None
    altitude_m: float | None
    velocity_ned_m_s: Vec3 | None


@dataclass(frozen=True)
class SonarReading(Reading):
    range_m: float


@dataclass(frozen=True)
class OpticalFlowReading(Reading):
    delta_counts: tuple[float, float]
    quality: int


@dataclass(frozen=True)
class BatteryReading(Reading):
    voltage_v: float
    current_a: float
    remaining: float
    """State of charge, fraction 0..1."""


@dataclass(frozen=True)
class MotorsReading(Reading):
    speeds_rad_s: tuple[float, ...]
    commands_rad_s: tuple[float, ...]
    thrust_n: float


@dataclass(frozen=True)
class CameraReading(Reading):
    """Frame ``frame`` of this camera now exists on the image server."""

    frame: int


@dataclass(frozen=True)
class StatusReading(Reading):
    """The robot's ``STA`` line: flight state and battery life."""

    armed: bool
    landed: bool
    battery_s: float
    voltage_v: float | None


@dataclass(frozen=True)
class RawReading(Reading):
    """A sensor type this client does not know: its fields as text."""

    fields: tuple[tuple[str, str], ...]


R = TypeVar("R", bound=Reading)


# --- the base class ------------------------------------------------------------------------


class Sensor(Generic[R]):
    """One mounted sensor on the client side.

    Args:
        name: the sensor's name on its robot (``Down``, ``IMU``).
        history_length: how many readings ``history`` keeps.
        advance: stepping hook, set by the connection in lockstep mode: ``wait_next`` calls it
            to move sim time forward instead of sleeping (a lockstep sim never moves alone).
    """

    type_name: ClassVar[str] = ""
    message_class: ClassVar[type] = SenOther
    """What this sensor's lines decode as (:mod:`skeye.wire.sim_messages`)."""

    def __init__(
        self,
        name: str,
        history_length: int = DEFAULT_HISTORY,
        advance: Callable[[], None] | None = None,
    ) -> None:
        if history_length < 1:
            raise LocalProtocolError(f"history_length must be >= 1, got {history_length}")
        self.name = name
        self.history: deque[R] = deque(maxlen=history_length)
        self.count = 0
        self.callback_errors = 0
        self.parse_errors = 0
        self._latest: R | None = None
        self._callbacks: list[Callable[[R], None]] = []
        self._cond = threading.Condition()
        self._error: SkeyeError | None = None
        self._advance = advance

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r} readings={self.count}>"

    @property
    def latest(self) -> R | None:
        """The newest reading, or None before the first one."""
        return self._latest

    @property
    def time_s(self) -> float | None:
        """Sim time of the newest reading."""
        latest = self._latest
        return None if latest is None else latest.time_s

    def set_history_length(self, length: int) -> None:
        """Keep the newest ``length`` readings from now on."""
        if length < 1:
            raise LocalProtocolError(f"history length must be >= 1, got {length}")
        with self._cond:
            self.history = deque(self.history, maxlen=length)

    def add_callback(self, fn: Callable[[R], None]) -> None:
        """Call ``fn(reading)`` on the message thread for every new reading (keep it short)."""
        with self._cond:
            self._callbacks.append(fn)

    def remove_callback(self, fn: Callable[[R], None]) -> None:
        with self._cond:
            self._callbacks.remove(fn)

    def wait_next(self, timeout_s: float = 5.0) -> R:
        """Block until a reading newer than the current one arrives; return it.

        In lockstep mode this steps the simulator until the reading comes.

        Raises:
            LinkTimeout: none arrived within ``timeout_s`` of wall time.
            SkeyeError: the link died (the link's own error).
        """
        deadline = time.monotonic() + timeout_s
        with self._cond:
            seen = self.count
        while True:
            with self._cond:
                if self.count > seen and self._latest is not None:
                    return self._latest
                if self._error is not None:
                    raise self._error
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise LinkTimeout(
                        f"{self.type_name} {self.name!r}: no reading within {timeout_s:g} s"
                    )
                if self._advance is None:
                    self._cond.wait(remaining)
                    continue
            self._advance()

    # -- called by the message thread ---------------------------------------------------
    def convert(self, message: Any) -> R:
        """Turn one decoded line (a ``message_class``) into this sensor's reading."""
        raise NotImplementedError

    def update(self, msg: Message) -> None:
        """Take one ``SEN`` line: decode it through the codec table, convert, store, wake
        waiters, run callbacks."""
        try:
            reading = self.convert(decode_as(msg, self.message_class))
        except RemoteProtocolError as exc:
            self.parse_errors += 1
            log.warning("bad %s %r reading: %s", self.type_name, self.name, exc)
            return
        self.push(reading)

    def push(self, reading: R) -> None:
        """Store a reading as if it had arrived (used by update and by tests)."""
        with self._cond:
            self._latest = reading
            self.history.append(reading)
            self.count += 1
            callbacks = list(self._callbacks)
            self._cond.notify_all()
        for fn in callbacks:
            try:
                fn(reading)
            except Exception:
                self.callback_errors += 1
                log.exception("callback %r of %s %r failed", fn, self.type_name, self.name)

    def fail(self, error: SkeyeError) -> None:
        """The link is gone: wake every waiter with ``error``."""
        with self._cond:
            if self._error is None:
                self._error = error
            self._cond.notify_all()


# --- one class per sensor type -------------------------------------------------------------


class GroundTruthSensor(Sensor[GroundTruthReading]):
    """The vehicle's true pose (body origin), NED, 50 Hz by default."""

    type_name = "GroundTruth"
    message_class = SenGroundTruth

    def convert(self, message: Any) -> GroundTruthReading:
        s: SenGroundTruth = message
        return GroundTruthReading(
            s.time_s,
            s.location_ned_m,
            _rpy(s.orientation_rpy_rad),
            s.velocity_ned_m_s,
            s.angular_velocity_frd_rad_s,
        )


class InsSensor(Sensor[InsReading]):
    """The vehicle's own (drifting) estimate of its pose, as the onboard board sees it."""

    type_name = "INS"
    message_class = SenIns

    def convert(self, message: Any) -> InsReading:
        s: SenIns = message
        return InsReading(s.time_s, s.location_ned_m, _rpy(s.orientation_rpy_rad),
                          s.velocity_ned_m_s, s.position_sigma_ned_m)


class AccelerometerSensor(Sensor[AccelerometerReading]):
    """Specific force in the body frame (FRD), m/s^2: about (0, 0, -9.81) at rest."""

    type_name = "Accelerometer"
    message_class = SenAccelerometer

    def convert(self, message: Any) -> AccelerometerReading:
        s: SenAccelerometer = message
        return AccelerometerReading(s.time_s, s.proper_acceleration_frd_m_s2)


class GyroSensor(Sensor[GyroReading]):
    """Body rates p, q, r (FRD), rad/s."""

    type_name = "Gyro"
    message_class = SenGyro

    def convert(self, message: Any) -> GyroReading:
        s: SenGyro = message
        return GyroReading(s.time_s, s.angular_velocity_frd_rad_s)


class CompassSensor(Sensor[CompassReading]):
    """Magnetometer: heading (rad, wrapped to (-pi, pi]) and field in the body frame (uT)."""

    type_name = "MagneticCompass"
    message_class = SenMagneticCompass

    def convert(self, message: Any) -> CompassReading:
        s: SenMagneticCompass = message
        field = s.field_frd_ut if s.field_frd_ut is not None else (0.0, 0.0, 0.0)
        return CompassReading(s.time_s, wrap_pi(s.magnetic_angle_rad), field)


class BarometerSensor(Sensor[BarometerReading]):
    """Static pressure (Pa) and the pressure altitude it implies (m)."""

    type_name = "Barometer"
    message_class = SenBarometer

    def convert(self, message: Any) -> BarometerReading:
        s: SenBarometer = message
        return BarometerReading(s.time_s, s.pressure_pa, s.altitude_m)


class GpsSensor(Sensor[GpsReading]):
    """GPS fix: decimal degrees (``LatitudeDeg``) or USARSim's ``39,8.0341,N`` text."""

    type_name = "GPS"
    message_class = SenGps

    def convert(self, message: Any) -> GpsReading:
        s: SenGps = message
        if s.fix <= 0:
            return GpsReading(s.time_s, False, s.satellites, None, None, None, None)
        lat = self._degrees(s.latitude_deg, s.latitude, "Latitude")
        lon = self._degrees(s.longitude_deg, s.longitude, "Longitude")
        return GpsReading(s.time_s, True, s.satellites, lat, lon, s.altitude_m,
                          s.velocity_ned_m_s)

    @staticmethod
    def _degrees(degrees: float | None, text: str | None, text_key: str) -> float:
        if degrees is not None:
            return degrees
        if text is None:
            raise RemoteProtocolError(f"missing {{{text_key} ...}}")
        try:
            return from_degrees_minutes(text)
        except (ValueError, SkeyeError) as exc:
            raise RemoteProtocolError(f"{text_key}: {text!r} is not deg,min,hemisphere") from exc


class SonarSensor(Sensor[SonarReading]):
    """Ultrasonic range along the beam (m), clamped to the sensor's [MinRange, MaxRange]."""

    type_name = "Sonar"
    message_class = SenSonar

    def convert(self, message: Any) -> SonarReading:
        s: SenSonar = message
        return SonarReading(s.time_s, s.range_m)


class OpticalFlowSensor(Sensor[OpticalFlowReading]):
    """Optical-flow counts since the last reading and the surface quality (0..169)."""

    type_name = "OpticalFlow"
    message_class = SenOpticalFlow

    def convert(self, message: Any) -> OpticalFlowReading:
        s: SenOpticalFlow = message
        return OpticalFlowReading(s.time_s, s.delta_counts, s.quality)


class BatterySensor(Sensor[BatteryReading]):
    """Battery monitor: voltage (V), current (A), remaining charge (fraction 0..1)."""

    type_name = "Battery"
    message_class = SenBattery

    def convert(self, message: Any) -> BatteryReading:
        s: SenBattery = message
        return BatteryReading(s.time_s, s.voltage_v, s.current_a, s.remaining)


class MotorsSensor(Sensor[MotorsReading]):
    """Rotor speeds and speed commands (rad/s) and the total thrust (N)."""

    type_name = "Motors"
    message_class = SenMotors

    def convert(self, message: Any) -> MotorsReading:
        s: SenMotors = message
        thrust_n = math.nan if s.thrust_n is None else s.thrust_n
        return MotorsReading(s.time_s, s.speeds_rad_s, s.commands_rad_s or (), thrust_n)


class StatusSensor(Sensor[StatusReading]):
    """The robot's status line (``STA``): armed, landed, remaining battery life (s)."""

    type_name = "Status"
    message_class = Sta

    def convert(self, message: Any) -> StatusReading:
        s: Sta = message
        battery_s = math.inf if s.battery_s is None else float(s.battery_s)
        return StatusReading(s.time_s, s.armed, s.landed, battery_s, s.voltage_v)


class RawSensor(Sensor[RawReading]):
    """A sensor of a type this client has no class for: readings keep the raw fields."""

    type_name = "Raw"
    message_class = SenOther

    def __init__(self, name: str, type_name: str, **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.type_name = type_name  # type: ignore[misc]

    def convert(self, message: Any) -> RawReading:
        s: SenOther = message
        return RawReading(s.time_s, s.fields)


SENSOR_CLASSES: dict[str, type[Sensor[Any]]] = {
    cls.type_name.lower(): cls
    for cls in (
        GroundTruthSensor,
        InsSensor,
        AccelerometerSensor,
        GyroSensor,
        CompassSensor,
        BarometerSensor,
        GpsSensor,
        SonarSensor,
        OpticalFlowSensor,
        BatterySensor,
        MotorsSensor,
    )
}
"""Sensor class by the wire's ``{Type ...}`` (lower-case). Cameras live in :mod:`.camera`."""
