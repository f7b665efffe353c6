"""One simulated vehicle seen from the pilot's side, in-process: readings, airframe, camera.

How this works: the pilot sees a simulated robot through the control protocol: the sensors'
``SEN`` lines become the control interface's typed readings, and
:meth:`skeye.pilot.sim_airframe.SimAirframe.snapshot` makes the boards'
:class:`~skeye.pilot.airframe.Snapshot` of the newest of each. Here the same robot runs in this
process (:class:`skeye.sim.engine.Simulation`, no socket): :class:`BoardView` is the robot's
reading sink; it keeps the newest reading of the same sensors (the first mounted one of each
type, as the control interface's ``robot.ins``, ``robot.gyro`` ... are) and builds the same
snapshot from them by the same rules (angles wrapped to (-pi, pi], the barometric climb rate,
the thrust fraction). The only difference is the wire's rounding of each number, which a test
measures against a real ``SimAirframe`` (tests/gym/test_board.py).

:class:`InProcessAirframe` is the pilot's :class:`~skeye.pilot.airframe.Airframe` on that robot:
velocity and stick set-points go to the robot's board as a ``DRIVE`` would put them;
:class:`InProcessCamera` is its downward camera as the pilot's vision reads it (the newest frame
of the simulator's :class:`~skeye.sim.image_server.FrameBuffer`, in BGR as the image client
gives it). Together they let :class:`skeye.pilot.vision.PadVision` itself run on the robot, so
the pad detection a policy observes is the pilot's, frame for frame.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from skeye.errors import SkeyeError
from skeye.pilot.airframe import BaroClimb, GpsFix, Snapshot
from skeye.robots.config import RobotConfig
from skeye.sim.engine import Simulation
from skeye.sim.image_server import FrameBuffer
from skeye.sim.readings import CameraFrame, Event, RobotStopped, SensorSample, StatusReading

GRAVITY_M_S2 = 9.80665
_TYPES = ("GroundTruth", "INS", "Gyro", "Accelerometer", "MagneticCompass", "Barometer", "GPS",
          "Battery", "Motors")


def wrap_pi(angle_rad: float) -> float:
    """An angle wrapped to (-pi, pi] (the wire sends [0, 2 pi); the control interface wraps)."""
    wrapped = math.remainder(angle_rad, 2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


class BoardView:
    """A robot's reading sink: the newest reading of each sensor the pilot reads, its status,
    its camera's newest frame, and why it stopped (if it did)."""

    def __init__(self, config: RobotConfig) -> None:
        self.names: dict[str, str] = {}  # type -> the first mounted sensor of it, by name
        for mount in config.sensors:
            for type_name in _TYPES:
                if mount.type_name.lower() == type_name.lower():
                    self.names.setdefault(type_name, mount.name)
        self.latest: dict[str, Any] = {}
        self.ins_readings: deque[Any] = deque(maxlen=16)  # the newest INS readings
        self.status: StatusReading | None = None
        self.frame: CameraFrame | None = None
        self.stopped: str | None = None
        self._mass_kg = config.airframe.mass_kg
        self._baro_climb = BaroClimb()

    def sink(self, events: list[Event]) -> None:
        names, latest = self.names, self.latest
        for event in events:
            if isinstance(event, SensorSample):
                if names.get(event.type_name) == event.name:
                    latest[event.type_name] = event.reading
                    if event.type_name == "INS":
                        self.ins_readings.append(event.reading)
            elif isinstance(event, StatusReading):
                self.status = event
            elif isinstance(event, CameraFrame):
                self.frame = event
            elif isinstance(event, RobotStopped):
                self.stopped = event.reason

    def rpy_rad(self) -> tuple[float, float, float]:
        """The INS attitude, wrapped (the vision's fallback when it has no pose history)."""
        ins = self.latest.get("INS") or self.latest.get("GroundTruth")
        if ins is None:
            return (0.0, 0.0, 0.0)
        r, p, y = ins.orientation_rad
        return (wrap_pi(r), wrap_pi(p), wrap_pi(y))

    def snapshot(self, now_s: float) -> Snapshot:
        """The boards' snapshot, by :meth:`SimAirframe.snapshot`'s rules, at sim time now."""
        get = self.latest.get
        ins, gt = get("INS"), get("GroundTruth")
        pose = ins or gt
        if pose is None:
            raise SkeyeError("no INS or GroundTruth reading yet: step the simulation first")
        vel = pose.velocity_ned_m_s or (gt.velocity_ned_m_s if gt else None) or (0.0, 0.0, 0.0)
        gyro, acc, compass = get("Gyro"), get("Accelerometer"), get("MagneticCompass")
        baro, gps, battery, motors = get("Barometer"), get("GPS"), get("Battery"), get("Motors")
        status = self.status
        if baro is not None:
            self._baro_climb.update(baro.time_s, baro.altitude_m)
        fix = None
        if gps is not None:
            if gps.fix > 0:
                fix = GpsFix(True, gps.satellites, gps.latitude_deg or 0.0,
                             gps.longitude_deg or 0.0, gps.altitude_m or 0.0,
                             gps.velocity_ned_m_s or (0.0, 0.0, 0.0))
            else:
                fix = GpsFix(False, gps.satellites, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0))
        thrust_fraction = 0.0
        if motors is not None and math.isfinite(motors.thrust_n):
            max_thrust_n = 2.0 * self._mass_kg * GRAVITY_M_S2  # SimAirframe's, from Mass
            thrust_fraction = max(0.0, min(1.0, motors.thrust_n / max_thrust_n))
        roll, pitch, yaw = pose.orientation_rad
        rpy = (wrap_pi(roll), wrap_pi(pitch), wrap_pi(yaw))
        return Snapshot(
            time_s=max(pose.time_s, now_s),
            pos_ned_m=pose.location_ned_m,
            rpy_rad=rpy,
            vel_ned_m_s=vel,
            rates_frd_rad_s=gyro.angular_velocity_rad_s if gyro else (0.0, 0.0, 0.0),
            specific_force_frd_m_s2=(
                acc.proper_acceleration_m_s2 if acc else (0.0, 0.0, -GRAVITY_M_S2)
            ),
            mag_field_frd_ut=compass.field_ut if compass else (0.0, 0.0, 0.0),
            mag_heading_rad=wrap_pi(compass.magnetic_angle_rad) if compass else rpy[2],
            baro_pressure_pa=baro.pressure_pa if baro else 101325.0,
            baro_altitude_m=baro.altitude_m if baro else -pose.location_ned_m[2],
            baro_climb_m_s=self._baro_climb.climb_m_s,
            gps=fix,
            battery_v=(battery.voltage_v if battery
                       else (status.voltage_v if status and status.voltage_v else 0.0)),
            armed=status.armed if status else False,
            landed=status.landed if status else True,
            thrust_fraction=thrust_fraction,
            pos_sigma_ned_m=getattr(ins, "position_sigma_ned_m", None) if ins else None,
            truth_ned_m=gt.location_ned_m if gt else None,
            truth_yaw_rad=wrap_pi(gt.orientation_rad[2]) if gt else None,
        )


class InProcessAirframe:
    """The pilot's :class:`~skeye.pilot.airframe.Airframe` on a robot of an in-process
    :class:`Simulation`: set-points only (velocity, sticks, hover). Take-off, fly-to, turn and
    landing are the control interface's motions, which run on a client: asked of this one,
    they are refused with a :class:`SkeyeError` saying so."""

    def __init__(self, sim: Simulation, name: str, view: BoardView) -> None:
        self.sim = sim
        self.name = name
        self.view = view
        self._velocity_until_s: float | None = None

    @property
    def robot(self) -> Any:
        robot = self.sim.robots.get(self.name)
        if robot is None:
            raise SkeyeError(f"robot {self.name} stopped: {self.view.stopped or 'removed'}")
        return robot

    @property
    def busy(self) -> bool:
        return False

    def snapshot(self) -> Snapshot:
        return self.view.snapshot(self.sim.time_s)

    def describe(self) -> str:
        return f"{self.name} in an in-process simulation"

    def _refuse(self, what: str) -> None:
        raise SkeyeError(f"{what} is a motion of the control interface; the in-process "
                         "vehicle takes set-points only (set_velocity, attitude, hover)")

    def take_off(self, altitude_m: float) -> None:
        self._refuse("take_off")

    def fly_to(self, north_m: float, east_m: float, altitude_m: float, speed_m_s: float) -> None:
        self._refuse("fly_to")

    def fly_to_gps(self, latitude_deg: float, longitude_deg: float, altitude_m: float,
                   speed_m_s: float) -> None:
        self._refuse("fly_to_gps")

    def turn_by(self, yaw_rad: float) -> None:
        self._refuse("turn_by")

    def land(self) -> None:
        self._refuse("land")

    def set_velocity(self, forward_m_s: float, right_m_s: float, up_m_s: float,
                     yaw_rate_rad_s: float, duration_s: float | None, *,
                     gps_mode: bool = False) -> None:
        self.robot.drive(attitude=False, forward_m_s=forward_m_s, right_m_s=right_m_s,
                         up_m_s=up_m_s, yaw_rate_rad_s=yaw_rate_rad_s, gps_mode=gps_mode)
        self._velocity_until_s = None if duration_s is None else self.sim.time_s + duration_s

    def hover(self) -> None:
        self.set_velocity(0.0, 0.0, 0.0, 0.0, None)

    def attitude(self, roll_rad: float, pitch_rad: float, yaw_rate_rad_s: float,
                 thrust_fraction: float, height_mode: bool = False) -> None:
        self._velocity_until_s = None
        self.robot.drive(attitude=True, roll_rad=roll_rad, pitch_rad=pitch_rad,
                         yaw_rate_rad_s=yaw_rate_rad_s, thrust=thrust_fraction,
                         height_mode=height_mode)

    def reset(self) -> str:
        """A crashed vehicle comes back with the episode (``env.reset()``), not through the
        boards: refused, naming that."""
        raise SkeyeError("an environment's vehicle comes back with env.reset(), not RESET")

    def advance(self, seconds: float) -> None:
        """Let ``seconds`` of sim time pass (whole physics steps); a timed velocity ends in
        a hover."""
        steps = max(0, round(seconds / self.sim.dt))
        if steps:
            self.sim.step(steps)
        if self._velocity_until_s is not None and self.sim.time_s >= self._velocity_until_s:
            self.hover()


@dataclass(frozen=True)
class FrameInfo:
    """A frame as the pilot's camera announces it: its number and capture time."""

    frame: int
    time_s: float


@dataclass(frozen=True)
class FrameImage:
    """A fetched frame as the pilot's image client gives it (BGR)."""

    frame: int
    time_s: float
    bgr: np.ndarray


class InProcessCamera:
    """The robot's downward camera as :class:`~skeye.pilot.vision.PadVision` reads it."""

    def __init__(self, buffer: FrameBuffer, key: str) -> None:
        self.buffer = buffer
        self.key = key  # "robot/camera", the FrameBuffer's name

    @property
    def latest(self) -> FrameInfo | None:
        frame = self.buffer.latest(self.key)
        return None if frame is None else FrameInfo(frame.number, frame.sim_time_s)

    def image(self) -> FrameImage:
        frame = self.buffer.latest(self.key)
        if frame is None:
            raise SkeyeError(f"camera {self.key}: no frame yet")
        return FrameImage(frame.number, frame.sim_time_s,
                          cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR))


@dataclass(frozen=True)
class _Attitude:
    rpy_rad: tuple[float, float, float]


class _Ins:
    def __init__(self, view: BoardView) -> None:
        self._view = view

    @property
    def latest(self) -> _Attitude | None:
        if "INS" not in self._view.latest and "GroundTruth" not in self._view.latest:
            return None
        return _Attitude(self._view.rpy_rad())


class VisionRobot:
    """What :class:`~skeye.pilot.vision.PadVision` reads of its robot: ``camera`` and ``ins``."""

    def __init__(self, camera: InProcessCamera, view: BoardView) -> None:
        self.camera = camera
        self.ins = _Ins(view)
