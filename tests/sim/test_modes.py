"""The board's modes beyond the two DRIVE forms: height mode and GPS mode (engine API)."""

from __future__ import annotations

import math

from skeye.sim.engine import Simulation
from skeye.sim.world import load_world


def test_height_mode_holds_the_height_estimate_and_climbs_off_centre() -> None:
    sim = Simulation(load_world("indoor"), seed=4, estimator="onboard")
    robot = sim.spawn("hummingbird", name="R1", sink=lambda events: None,
                      location_ned_m=(0.0, 0.0, -1.5))
    robot.drive(attitude=True, height_mode=True, thrust=0.5)
    sim.step(5000)
    assert abs(-sim.body_state("R1").pos_ned_m[2] - 1.5) < 0.1
    robot.drive(thrust=0.7)  # 0.2 above centre: 0.4 x 1.5 m/s = 0.6 m/s up
    sim.step(1500)
    assert -sim.body_state("R1").pos_ned_m[2] > 2.0
    robot.drive(thrust=0.5)
    sim.step(1000)
    held = -sim.body_state("R1").pos_ned_m[2]
    sim.step(3000)
    assert abs(-sim.body_state("R1").pos_ned_m[2] - held) < 0.1


def test_gps_mode_holds_the_position_estimate_outdoors_only() -> None:
    """Centred sticks in GPS mode hold the position estimate where they were centred; indoors
    (no fix) the same command is plain velocity hold."""
    for world, holds in (("pad", True), ("indoor", False)):
        sim = Simulation(load_world(world), seed=4, estimator="onboard")
        robot = sim.spawn("hummingbird", name="R1", sink=lambda events: None,
                          location_ned_m=(0.0, 0.0, -1.5))
        assert robot.estimator is not None
        robot.drive(gps_mode=True)
        sim.step(3000)
        hold = robot.controller.hold_north_m, robot.controller.hold_east_m
        assert (hold[0] is not None) is holds
        if holds:
            assert hold[0] is not None and hold[1] is not None
            sim.step(20000)
            n, e, _ = robot.estimator.estimate().pos_ned_m
            assert math.hypot(n - hold[0], e - hold[1]) < 0.3
