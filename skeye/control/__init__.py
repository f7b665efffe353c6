"""skeye.control: the Python interface to the simulator (docs/control.md): a connection with a
message thread and a command thread, one class per sensor,
PI motion control and robot classes, so a flight is a few lines::

    with skeye.connect("127.0.0.1:3000") as sim:
        copter = sim.spawn("hummingbird", start="Pad1")
        copter.take_off(1.0)
        copter.fly_to(north_m=2.0, east_m=1.0, altitude_m=1.5)
        copter.land()
"""

from skeye.control.camera import CameraImage, CameraSensor
from skeye.control.clock import Clock, LockstepClock, RealtimeClock
from skeye.control.connection import Connection, Pose, connect, parse_address
from skeye.control.motion import (
    DriveCommand,
    MotionCancelled,
    MotionConfig,
    MotionFailed,
    PIController,
    PIGains,
)
from skeye.control.robots import AirRobot, FlightState, Hummingbird, Robot
from skeye.control.sensors import Reading, Sensor
from skeye.errors import LinkClosed

__all__ = [
    "AirRobot",
    "CameraImage",
    "CameraSensor",
    "Clock",
    "Connection",
    "DriveCommand",
    "FlightState",
    "Hummingbird",
    "LinkClosed",
    "LockstepClock",
    "MotionCancelled",
    "MotionConfig",
    "MotionFailed",
    "PIController",
    "PIGains",
    "Pose",
    "Reading",
    "RealtimeClock",
    "Robot",
    "Sensor",
    "connect",
    "parse_address",
]
