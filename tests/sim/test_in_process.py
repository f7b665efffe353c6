"""Stepping the simulator in-process: no server, no runner, no socket; typed readings out."""

from __future__ import annotations

import socket

import pytest

from skeye.sim.engine import Simulation
from skeye.sim.readings import Event, SensorSample, StatusReading
from skeye.sim.sensors import GroundTruthReading, SonarReading
from skeye.sim.stream import StreamEncoder, text_sink
from skeye.sim.world import load_world
from skeye.wire import sim as wire
from skeye.wire.sim_lines import parse_line
from skeye.wire.sim_messages import SenGroundTruth, Sta


def _no_sockets(*args: object, **kwargs: object) -> None:
    raise AssertionError("in-process stepping opened a socket")


def test_a_simulation_steps_without_sockets_and_yields_typed_readings(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(socket, "socket", _no_sockets)
    events: list[Event] = []
    sim = Simulation(load_world("pad"), seed=4)
    sim.spawn("hummingbird", name="R1", sink=events.extend, start="Pad1")
    robot = sim.robots["R1"]
    robot.drive(up_m_s=0.5)
    sim.step(2000)
    assert sim.time_s == pytest.approx(2.0)
    truth = [e.reading for e in events
             if isinstance(e, SensorSample) and e.type_name == "GroundTruth"]
    assert len(truth) == 100  # 50 Hz for 2 s
    assert all(isinstance(r, GroundTruthReading) for r in truth)
    assert [r.time_s for r in truth] == sorted(r.time_s for r in truth)
    assert truth[-1].location_ned_m[2] < truth[0].location_ned_m[2] - 0.3  # it climbed
    sonar = [e.reading for e in events if isinstance(e, SensorSample) and e.type_name == "Sonar"]
    assert sonar and all(isinstance(r, SonarReading) for r in sonar)
    status = [e for e in events if isinstance(e, StatusReading)]
    assert status and status[-1].armed and not status[-1].landed and status[-1].robot == "R1"


def test_each_step_call_hands_each_robot_one_batch() -> None:
    batches: list[list[Event]] = []
    sim = Simulation(load_world("pad"), seed=4)
    sim.spawn("hummingbird", name="R1", sink=batches.append, location_ned_m=(0, 0, -1))
    sim.step(100)
    sim.step(100)
    assert len(batches) == 2 and all(batches)


def test_the_same_seed_gives_the_same_readings_and_the_lines_the_server_sends() -> None:
    """Typed readings, encoded, are byte for byte what a text sink (the server's) gets."""
    events: list[Event] = []
    chunks: list[bytes] = []
    for sink in (events.extend, text_sink(chunks.append)):
        sim = Simulation(load_world("pad"), seed=9)
        sim.spawn("hummingbird", name="R1", sink=sink, location_ned_m=(0, 0, -1))
        sim.step(500)
    assert StreamEncoder().encode(events) == b"".join(chunks)
    lines = b"".join(chunks).decode().splitlines()
    decoded = [wire.decode(parse_line(line)) for line in lines]
    truth = [m for m in decoded if isinstance(m, SenGroundTruth)]
    samples = [e.reading for e in events
               if isinstance(e, SensorSample) and e.type_name == "GroundTruth"]
    assert len(truth) == len(samples) > 0
    assert truth[-1].location_ned_m == pytest.approx(samples[-1].location_ned_m, abs=1e-6)
    assert any(isinstance(m, Sta) and m.name == "R1" for m in decoded)
