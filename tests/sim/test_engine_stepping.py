"""Engine stepping: readings as precompiled SEN/STA lines, shared INS estimates, wrenches kept."""

from __future__ import annotations

import numpy as np
import pytest

from skeye.sim.engine import Simulation
from skeye.sim.readings import Event, SensorSample
from skeye.sim.stream import StreamEncoder
from skeye.sim.world import load_world
from skeye.wire.sim_lines import format_message, parse_line


@pytest.mark.parametrize("world", ["pad", "indoor"])  # indoor: GPS without a fix
def test_every_sensor_line_matches_format_message(world: str) -> None:
    events: list[Event] = []
    sim = Simulation(load_world(world), seed=3)
    robot = sim.spawn("hummingbird", name="R1", sink=events.extend, location_ned_m=(0, 0, -1))
    sim.step(1000)
    assert events, "a second of flight streams sensor readings"
    encoder = StreamEncoder()
    lines = encoder.encode(events)
    seen = set()
    for sched in robot.sensors:
        reading = sched.sensor.last
        assert reading is not None, f"{sched.sensor.type_name} was never sampled"
        expected = format_message(
            "SEN",
            ("Time", reading.time_s),
            ("Type", sched.sensor.type_name),
            ("Name", sched.mount.name),
            *reading.fields(),
        )
        sample = SensorSample(sched.sensor.type_name, sched.mount.name, reading)
        assert encoder.sample_line(sample) == expected
        seen.add(sched.sensor.type_name)
        # ... and the line the client got for that time is that line.
        assert expected in lines
    assert {"GroundTruth", "INS", "GPS", "Sonar", "OpticalFlow", "Motors"} <= seen
    status = encoder.status_line(robot.status(sim.time_s))
    battery, *rest = robot.status_fields()  # USARSim's STA starts {Time} {Battery}
    assert status == format_message(
        "STA", ("Time", sim.time_s), battery, ("Name", "R1"), *rest,
    )
    assert parse_line(status.decode().strip()).get_bool("Armed") is True


def test_ins_stream_reports_the_estimate_the_board_flies_on() -> None:
    """At a time where both the board and the INS stream run, they share one estimate: the
    board estimator's, fed by this instant's readings before the INS reports."""
    sim = Simulation(load_world("pad"), seed=5, estimator="onboard")
    robot = sim.spawn("hummingbird", name="R1", sink=lambda events: None,
                      location_ned_m=(0, 0, -1))
    assert robot.estimator is not None
    sim.step(200)  # 200 steps: a multiple of the board's 4, the INS's and the IMU's 20
    est = robot.estimator.estimate()
    reading = robot.ins.last
    assert reading is not None and reading.time_s == pytest.approx(sim.time_s)
    assert reading.location_ned_m == est.pos_ned_m
    assert reading.velocity_ned_m_s == est.vel_ned_m_s


def test_truth_estimator_ins_shares_the_oracle_estimate_with_the_board() -> None:
    """With the oracle (``--estimator truth``) the board and the INS stream share one estimate
    (the drift processes advance once per instant, not once per consumer)."""
    sim = Simulation(load_world("pad"), seed=5, estimator="truth")
    robot = sim.spawn("hummingbird", name="R1", sink=lambda events: None,
                      location_ned_m=(0, 0, -1))
    ins = robot.ins
    sim.step(200)  # 200 steps: a multiple of both the board's 4 and the INS stream's 20
    est = ins.estimate_now(sim.body_state("R1"))
    reading = ins.last
    assert reading is not None and reading.time_s == pytest.approx(sim.time_s)
    assert reading.location_ned_m == est.pos_ned_m
    assert reading.velocity_ned_m_s == est.vel_ned_m_s


def test_a_spawn_keeps_the_other_robots_wrench() -> None:
    """Spawning rebuilds MuJoCo's data; the hovering robot keeps the wrench its board set
    (the board sets it only every fourth step), so it never free-falls for a step or three."""
    sim = Simulation(load_world("pad"), seed=1)
    sim.spawn("hummingbird", name="R1", sink=lambda events: None, location_ned_m=(0, 0, -1))
    sim.step(203)  # between two board ticks
    before = sim.data.xfrc_applied[sim._slots["R1"].body_id].copy()
    assert before[2] > 0.9 * 0.68 * 9.81  # lifting
    sim.spawn("hummingbird", name="R2", sink=lambda events: None, location_ned_m=(3, 0, -1))
    assert np.array_equal(sim.data.xfrc_applied[sim._slots["R1"].body_id], before)
    # A robot spawned in the air has its wrench from its first step on.
    assert sim.data.xfrc_applied[sim._slots["R2"].body_id][2] > 0.9 * 0.68 * 9.81
