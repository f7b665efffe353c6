"""The sensors a robot carries: created from the simulator's configuration, found by type.

How this works: :class:`RobotSensors` is the sensor half of :class:`~skeye.control.robots.Robot`
(a base class, so ``copter.ins`` and ``copter.sensor("GPS")`` read naturally). A sensor object is
made the first time its ``(type, name)`` is seen, from ``CONF {Sensors ...}`` or a ``SEN`` line,
under the robot's lock; the ``sensors`` dict is replaced, never changed in place, so readers need
no lock. Sensor classes are in :mod:`skeye.control.sensors` and :mod:`skeye.control.camera`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, ClassVar

from skeye.errors import LinkTimeout, LocalProtocolError

from .camera import CameraSensor
from .host import RobotHost
from .sensors import (
    SENSOR_CLASSES,
    AccelerometerSensor,
    BarometerSensor,
    BatterySensor,
    CompassSensor,
    GpsSensor,
    GroundTruthSensor,
    GyroSensor,
    InsSensor,
    MotorsSensor,
    OpticalFlowSensor,
    RawSensor,
    Sensor,
    SonarSensor,
    StatusSensor,
)

FEEDBACK_TYPES = {"ins": "ins", "ground_truth": "groundtruth"}
"""Navigation feedback a motion may fly on -> the sensor type that gives it."""


class RobotSensors:
    """A robot's mounted sensors (see the module comment); the base of ``Robot``."""

    class_name: ClassVar[str]
    name: str
    connection: RobotHost
    mounted: list[tuple[str, str]]
    sensors: dict[tuple[str, str], Sensor[Any]]
    status: StatusSensor
    _advance: Callable[[], None] | None
    _lock: threading.RLock

    def _sensor(self, type_name: str, sensor_name: str) -> Sensor[Any]:
        key = (type_name.lower(), sensor_name.lower())
        sensor = self.sensors.get(key)
        if sensor is not None:
            return sensor
        with self._lock:
            sensor = self.sensors.get(key)
            if sensor is None:
                kwargs: dict[str, Any] = {"advance": self._advance}
                if key[0] == "camera":
                    conn = self.connection
                    images = conn.image_client if conn.images_address is not None else None
                    sensor = CameraSensor(sensor_name, images=images, robot_name=self.name,
                                          **kwargs)
                elif key[0] in SENSOR_CLASSES:
                    sensor = SENSOR_CLASSES[key[0]](sensor_name, **kwargs)
                else:
                    sensor = RawSensor(sensor_name, type_name, **kwargs)
                self.sensors = {**self.sensors, key: sensor}  # copy-on-write for lock-free reads
        return sensor

    # -- sensors ---------------------------------------------------------------------------
    def _find(self, type_key: str, name: str | None = None) -> Sensor[Any] | None:
        for (t, n), sensor in self.sensors.items():
            if t == type_key and (name is None or n == name.lower()):
                return sensor
        return None

    def sensor(self, type_name: str, name: str | None = None) -> Sensor[Any]:
        """The mounted sensor of a type (the first one, unless ``name`` says which)."""
        found = self._find(type_name.lower(), name)
        if found is None:
            mounted = ", ".join(f"{t}:{n}" for t, n in self.mounted) or "none"
            raise LocalProtocolError(
                f"{self.name} ({self.class_name}) has no {type_name} sensor"
                + (f" named {name!r}" if name else "") + f"; mounted: {mounted}"
            )
        return found

    @property
    def ground_truth(self) -> GroundTruthSensor:
        return self.sensor("GroundTruth")  # type: ignore[return-value]

    @property
    def ins(self) -> InsSensor:
        return self.sensor("INS")  # type: ignore[return-value]

    @property
    def accelerometer(self) -> AccelerometerSensor:
        return self.sensor("Accelerometer")  # type: ignore[return-value]

    imu = accelerometer

    @property
    def gyro(self) -> GyroSensor:
        return self.sensor("Gyro")  # type: ignore[return-value]

    @property
    def compass(self) -> CompassSensor:
        return self.sensor("MagneticCompass")  # type: ignore[return-value]

    @property
    def barometer(self) -> BarometerSensor:
        return self.sensor("Barometer")  # type: ignore[return-value]

    @property
    def gps(self) -> GpsSensor:
        return self.sensor("GPS")  # type: ignore[return-value]

    @property
    def sonar(self) -> SonarSensor:
        return self.sensor("Sonar")  # type: ignore[return-value]

    @property
    def optical_flow(self) -> OpticalFlowSensor:
        return self.sensor("OpticalFlow")  # type: ignore[return-value]

    @property
    def battery(self) -> BatterySensor:
        return self.sensor("Battery")  # type: ignore[return-value]

    @property
    def motors(self) -> MotorsSensor:
        return self.sensor("Motors")  # type: ignore[return-value]

    @property
    def camera(self) -> CameraSensor:
        return self.sensor("Camera")  # type: ignore[return-value]

    def position(self) -> tuple[float, float, float]:
        """``(north_m, east_m, altitude_m)`` from ground truth (altitude up positive): where
        the simulator has the vehicle."""
        reading = self.ground_truth.latest
        if reading is None:
            raise LinkTimeout(f"{self.name}: no ground-truth reading yet")
        n, e, d = reading.position_ned_m
        return (n, e, -d)

    def estimated_position(self) -> tuple[float, float, float]:
        """``(north_m, east_m, altitude_m)`` from the board's own estimate (INS): where the
        vehicle believes it is, and what its motions fly on (it drifts from :meth:`position`
        as a real estimate does: docs/physics.md)."""
        reading = self.ins.latest
        if reading is None:
            raise LinkTimeout(f"{self.name}: no INS reading yet")
        n, e, d = reading.position_ned_m
        return (n, e, -d)

    @property
    def landed(self) -> bool:
        """What the vehicle's last status line said."""
        status = self.status.latest
        return True if status is None else status.landed
