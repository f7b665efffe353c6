"""Landing-pad vision in the pilot, end to end: camera frames from the image server, the
detector in the pilot, PAD packets to the ground, and PAD_MODE flying the vehicle."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import ExitStack

import pytest

from skeye.control.connection import connect
from skeye.link.vehicle import Vehicle
from skeye.pilot.cli import pad_vision_factory
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.wire.packet_units import pad_report_to_si
from skeye.wire.packets import PD, NavState, PadReport, SkeyeMask
from tests.sim.test_cameras import sim_with_images


@pytest.fixture
def pad_flight() -> Iterator[tuple[Vehicle, object, object, PilotServer]]:
    with ExitStack() as stack:
        # The oracle estimator (--estimator truth): this tests the pilot's landing logic and
        # centimetre checks on the estimate; outdoors the onboard estimate wanders with GPS.
        control, images, _cameras = stack.enter_context(
            sim_with_images(mode="lockstep", estimator="truth")
        )
        sim = stack.enter_context(
            connect(f"127.0.0.1:{control.port}", images=f"127.0.0.1:{images.port}")
        )
        robot = sim.spawn("hummingbird", start="Pad1")
        # Paced at 5x: NAV_STATUS streams on the wall clock, and an unpaced sim could finish
        # the 0.3 m move between two stream frames (FLYING never seen).
        pilot = stack.enter_context(
            PilotServer(SimAirframe(sim, robot), port=0, lockstep=True, lockstep_rate=5.0,
                        tick_s=0.05, vision=pad_vision_factory(sim, robot))
        )
        vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=10.0))
        yield vehicle, robot, control, pilot


def pad_at(vehicle: Vehicle) -> PadReport:
    msg = vehicle.wait_for(PD.PAD, timeout_s=60)
    assert isinstance(msg, PadReport)
    return msg


def test_pad_mode_land_from_1_5_m_and_0_3_m_off_centre(pad_flight):
    vehicle, robot, control, pilot = pad_flight
    vehicle.stream(0, int(SkeyeMask.NAV_STATUS | SkeyeMask.PAD), 0.05)
    vehicle.take_off(1.5)
    vehicle.wait_state(NavState.HOLDING, timeout_s=60)
    vehicle.move_by(forward_m=0.3)  # facing north: 0.3 m north of the pad centre
    vehicle.wait_state(NavState.FLYING, timeout_s=60)
    vehicle.wait_state(NavState.HOLDING, timeout_s=60)
    north, east, alt = robot.position()
    assert math.hypot(north - 0.3, east) < 0.1 and alt == pytest.approx(1.5, abs=0.15)
    report = pad_report_to_si(pad_at(vehicle))
    assert report.found and report.height_m == pytest.approx(1.5 - 0.036, abs=0.1)
    assert report.dx_m < -0.15  # the pad is behind the vehicle

    vehicle.pad_mode(2, deadband_m=0.05, max_speed_m_s=0.3)
    vehicle.wait_state(NavState.LANDING, timeout_s=120)
    vehicle.wait_state(NavState.LANDED, timeout_s=120)
    north, east, alt = control.runner.call(lambda sim: tuple(sim.body_state("R1").pos_ned_m))
    assert math.hypot(north, east) < 0.05, (north, east)
    assert pilot.vision is not None and pilot.vision.stats.detections > 20
