"""Readings to protocol lines: the control server's side of the physics' sinks.

How this works: a :class:`StreamEncoder` turns a robot's events (:mod:`skeye.sim.readings`) into
the ``SEN``, ``STA`` and ``ERR`` lines of docs/protocols/simulator.md, through the typed codec
table (:mod:`skeye.wire.sim`). The stream writes the same shapes of line many times a second, so
each shape (a sensor's layout, a robot's status line) is compiled once into a
:class:`~skeye.wire.sim_format.LineFormat` and cached; rare events go through
:func:`skeye.wire.sim.encode`. :func:`text_sink` wraps a bytes callback (a client's queue) into
a :data:`~skeye.sim.readings.ReadingSink`: one call of the sink, one chunk of bytes.
"""

from __future__ import annotations

from collections.abc import Callable

from skeye.sim.readings import (
    CameraFrame,
    Event,
    ReadingSink,
    RobotCrashed,
    RobotStopped,
    SensorSample,
    StatusReading,
)
from skeye.wire import sim as wire
from skeye.wire.sim_format import Layout, LineFormat
from skeye.wire.sim_messages import CRASH_COMMAND, Err, SenCamera, Sta

__all__ = ["CRASH_COMMAND", "StreamEncoder", "text_sink"]  # CRASH_COMMAND: skeye.wire's


class StreamEncoder:
    """Encodes events into lines, caching one compiled format per line shape."""

    def __init__(self) -> None:
        self._sen: dict[tuple[str, str, int], tuple[Layout, LineFormat]] = {}
        self._sta: dict[str, LineFormat] = {}

    def sample_line(self, sample: SensorSample) -> bytes:
        """``SEN {Time t} {Type T} {Name n} ...`` of one sensor reading."""
        reading = sample.reading
        layout = reading.layout()
        key = (sample.type_name, sample.name, id(layout))
        entry = self._sen.get(key)
        if entry is None or entry[0] is not layout:
            fmt = wire.sen_line_format(sample.type_name, sample.name, layout)
            entry = self._sen[key] = (layout, fmt)
        return entry[1].format((reading.time_s, *reading.values()))

    def status_line(self, status: StatusReading) -> bytes:
        """``STA {Time t} {Battery n} {Name n} ...`` of a robot's status."""
        fmt = self._sta.get(status.robot)
        if fmt is None:
            fmt = self._sta[status.robot] = wire.line_format(Sta, {"Name": status.robot})
        # Whole seconds, as USARSim's Battery.ExpectedLifeTime (int(energy / discharge rate)).
        return fmt.format((status.time_s, int(status.battery_s), status.voltage_v,
                           status.current_a, status.armed, status.landed))

    def encode(self, events: list[Event]) -> bytes:
        """The lines of ``events``, in order, as one chunk."""
        lines = []
        for event in events:
            if isinstance(event, SensorSample):
                lines.append(self.sample_line(event))
            elif isinstance(event, StatusReading):
                lines.append(self.status_line(event))
            elif isinstance(event, CameraFrame):
                lines.append(wire.encode(SenCamera(event.time_s, event.camera, event.frame)))
            elif isinstance(event, RobotStopped):
                lines.append(wire.encode(Err(event.command, event.robot, event.reason)))
            elif isinstance(event, RobotCrashed):
                reason = f"crashed: {event.cause}"
                lines.append(wire.encode(Err(CRASH_COMMAND, event.robot, reason)))
            else:
                raise TypeError(f"not a simulator event: {event!r}")  # a bug in the engine
        return b"".join(lines)


def text_sink(outbox: Callable[[bytes], None]) -> ReadingSink:
    """A sink that hands each batch of events to ``outbox`` as protocol lines (one chunk)."""
    encoder = StreamEncoder()

    def sink(events: list[Event]) -> None:
        outbox(encoder.encode(events))

    return sink
