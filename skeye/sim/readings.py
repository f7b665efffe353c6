"""What the physics produces: typed readings and events, handed to a robot's sink.

How this works: the engine (:mod:`skeye.sim.engine`), the robots and the cameras write no wire
text. Each physics step collects, per robot, the events it produced: a :class:`SensorSample`
for each sensor that was due (the sensor's own typed reading, see
:class:`skeye.sim.sensors.Reading`), a :class:`StatusReading` when the status is due, a
:class:`CameraFrame` when a camera rendered, a :class:`RobotCrashed` when the robot crashed (it
stays in the world, motors off), a :class:`RobotStopped` when the robot failed. When
the ``step()`` call ends the engine hands each robot's events, in order, to the robot's
:data:`ReadingSink` in one call. The control server's sink turns them into protocol lines
(:mod:`skeye.sim.stream`); an in-process user (a benchmark, a test, a learning environment) can
keep them as they are::

    events = []
    sim = Simulation(load_world("pad"), seed=7)
    sim.spawn("hummingbird", name="R1", sink=events.extend, start="Pad1")
    sim.step(1000)  # one second of sim time; events now holds every reading

Invariants: events are immutable; a sink is called on the thread that steps the simulation (the
engine thread under the server) and, for a realtime camera, on the render thread; it must not
block.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = [
    "CameraFrame",
    "Event",
    "ReadingSink",
    "RobotCrashed",
    "RobotStopped",
    "SensorSample",
    "StatusReading",
    "discard",
]


class SensorSample:
    """One reading of one mounted sensor.

    Attributes:
        type_name: the sensor's protocol Type (``INS``, ``Sonar``...).
        name: the sensor's name on its robot.
        reading: the typed reading (``time_s`` and the values, SI units), whose ``layout()``
            and ``values()`` give its protocol fields.
    """

    __slots__ = ("name", "reading", "type_name")

    def __init__(self, type_name: str, name: str, reading: Any) -> None:
        # Written out, not a dataclass: one is made per sample on the engine's hot path.
        self.type_name = type_name
        self.name = name
        self.reading = reading

    def __repr__(self) -> str:
        return f"SensorSample({self.type_name!r}, {self.name!r}, {self.reading!r})"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, SensorSample):
            return NotImplemented
        return (self.type_name, self.name, self.reading) == (
            other.type_name, other.name, other.reading)

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True)
class StatusReading:
    """A robot's status: battery life left (s), voltage (V), current (A), flight state."""

    robot: str
    time_s: float
    battery_s: float
    voltage_v: float
    current_a: float
    armed: bool
    landed: bool


@dataclass(frozen=True)
class CameraFrame:
    """Camera ``camera`` of the robot rendered frame number ``frame`` at ``time_s``."""

    time_s: float
    camera: str
    frame: int


@dataclass(frozen=True)
class RobotStopped:
    """The robot failed: ``command`` says where (``PHYSICS``, ``CAMERA``), ``reason`` why."""

    robot: str
    command: str
    reason: str


@dataclass(frozen=True)
class RobotCrashed:
    """The robot crashed (:mod:`skeye.sim.crash`): its motors stopped and it refuses ``DRIVE``
    until it is reset; ``cause`` says why."""

    robot: str
    time_s: float
    cause: str


Event = SensorSample | StatusReading | CameraFrame | RobotStopped | RobotCrashed
ReadingSink = Callable[[list[Event]], None]
"""Takes one robot's events of one ``step()`` call, in order (never an empty list)."""


def discard(events: list[Event]) -> None:
    """A sink that drops everything (a robot nobody listens to)."""
