"""End to end: Vehicle -> link (TCP or a serial pty pair) -> skeye pilot -> skeye.control -> sim.

The same flight runs on both links: take off, move by 1 m, GPS goto, land, with the telemetry
checked against the simulator's ground truth. The simulator runs in lockstep and the pilot
drives its clock at 5x real time (``lockstep_rate=5``), so a flight takes a few seconds of wall
time. Not unpaced: NAV_STATUS streams on the wall clock (the radio link's time), and an unpaced
compiled simulator finishes a 1 m move between two 50 ms stream frames, so the FLYING state
would never be seen.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import ExitStack
from typing import Any

import pytest

from skeye.control.connection import connect
from skeye.errors import CommandRejected
from skeye.geo import GeoOrigin
from skeye.link.transport import pty_null_modem
from skeye.link.vehicle import Vehicle
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.wire.packet_units import gps_data_to_si, imu_calcdata_to_si, nav_status_to_si
from skeye.wire.packets import PD, ImuCalcData, NavState, PollMask, SkeyeMask
from tests.sim.conftest import running_sim

POS_TOL_M = 0.25  # INS estimate vs ground truth over a short flight
ATT_TOL_RAD = 0.05
VIBRATION_RMS_M_S2 = 1.1  # the accelerometer's in-flight vibration, RMS per axis at 200 Hz
# (docs/physics.md, "In-flight vibration"; the board's 50 Hz readings average it down)
ACC_SAMPLES = 8


@pytest.fixture(params=["tcp", "serial"])
def flight(request) -> Iterator[tuple[Vehicle, object]]:
    with ExitStack() as stack:
        # The oracle estimator (--estimator truth): these checks compare the packets' estimate
        # with ground truth at 0.25 m, which the GPS-aided onboard estimate does not meet.
        server = stack.enter_context(running_sim(mode="lockstep", seed=3, estimator="truth"))
        sim = stack.enter_context(connect(f"127.0.0.1:{server.port}", timeout_s=10.0))
        robot = sim.spawn("hummingbird", start="Pad1")
        airframe = SimAirframe(sim, robot)
        kwargs: dict[str, Any] = {"lockstep": True, "lockstep_rate": 5.0, "tick_s": 0.05}
        if request.param == "tcp":
            pilot = stack.enter_context(PilotServer(airframe, port=0, **kwargs))
            uri = pilot.address
        else:
            side_a, side_b = stack.enter_context(pty_null_modem())
            stack.enter_context(
                PilotServer(airframe, port=None, serial_uri=f"serial://{side_a}", **kwargs)
            )
            uri = f"serial://{side_b}?baud=57600"
        vehicle = stack.enter_context(Vehicle.open(uri, timeout_s=5.0))
        yield vehicle, robot


def check_against_ground_truth(vehicle: Vehicle, robot) -> None:
    nav = nav_status_to_si(vehicle.wait_state(NavState.HOLDING, NavState.LANDED, timeout_s=5))
    gt = robot.ground_truth.latest
    assert math.dist(nav.pos_ned_m, gt.position_ned_m) < POS_TOL_M, (nav, gt)
    calc_msg = vehicle.poll(int(PollMask.IMU_CALCDATA))[PD.IMU_CALCDATA]
    assert isinstance(calc_msg, ImuCalcData)
    calc = imu_calcdata_to_si(calc_msg)
    gt = robot.ground_truth.latest
    assert calc.height_m == pytest.approx(-gt.position_ned_m[2], abs=POS_TOL_M)
    assert calc.roll_rad == pytest.approx(gt.rpy_rad[0], abs=ATT_TOL_RAD)
    assert calc.pitch_rad == pytest.approx(gt.rpy_rad[1], abs=ATT_TOL_RAD)
    yaw_err = math.remainder(calc.yaw_rad - gt.rpy_rad[2], 2 * math.pi)
    assert abs(yaw_err) < ATT_TOL_RAD
    # Hovering: the accelerometer feels about 1 g up (body z down: -1 g), under the rotors'
    # vibration: the mean of readings a NAV_STATUS frame apart, within 4 of its sigmas.
    acc_z = [calc.acc_body_frd_m_s2[2]]
    while len(acc_z) < ACC_SAMPLES:
        vehicle.wait_for(PD.NAV_STATUS, timeout_s=5)
        msg = vehicle.poll(int(PollMask.IMU_CALCDATA))[PD.IMU_CALCDATA]
        assert isinstance(msg, ImuCalcData)
        acc_z.append(imu_calcdata_to_si(msg).acc_body_frd_m_s2[2])
    assert sum(acc_z) / len(acc_z) == pytest.approx(
        -9.81, abs=4 * VIBRATION_RMS_M_S2 / math.sqrt(ACC_SAMPLES)), acc_z


def test_take_off_move_goto_land(flight):
    vehicle, robot = flight
    vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.05)
    with pytest.raises(CommandRejected) as info:
        vehicle.land()  # refused while landed
    assert info.value.code == 4

    vehicle.take_off(1.0)
    vehicle.wait_state(NavState.HOLDING, timeout_s=20)
    check_against_ground_truth(vehicle, robot)
    assert robot.position()[2] == pytest.approx(1.0, abs=0.15)
    ll = vehicle.poll(int(PollMask.LL_STATUS))[PD.LL_STATUS]
    assert ll.flying == 1 and ll.motors_on == 1
    assert ll.battery_voltage_1 == pytest.approx(robot.battery.latest.voltage_v * 1000, abs=100)

    n0, e0, _ = robot.position()
    vehicle.move_by(forward_m=1.0)
    vehicle.wait_state(NavState.FLYING, timeout_s=5)
    vehicle.wait_state(NavState.HOLDING, timeout_s=20)
    n1, e1, _ = robot.position()
    assert math.hypot(n1 - n0 - 1.0, e1 - e0) < POS_TOL_M  # facing north at spawn
    check_against_ground_truth(vehicle, robot)

    gps = gps_data_to_si(vehicle.poll(int(PollMask.GPS_DATA))[PD.GPS_DATA])
    assert gps.status == 3 and gps.num_sv > 0
    here = GeoOrigin(gps.latitude_deg, gps.longitude_deg, 0.0)
    lat, lon, _ = here.to_geodetic(-1.0, 1.0, 0.0)  # 1 m south-east of the fix
    vehicle.goto_gps(lat, lon, height_m=1.2, speed_m_s=0.8)
    vehicle.wait_state(NavState.FLYING, timeout_s=5)
    vehicle.wait_state(NavState.HOLDING, timeout_s=20)
    n2, e2, alt2 = robot.position()
    # GPS noise moves the end point, as on a real vehicle: metre-level tolerance.
    assert math.hypot(n2 - (n1 - 1.0), e2 - (e1 + 1.0)) < 1.0
    assert alt2 == pytest.approx(1.2 + robot.home_ned_m[2] * -1, abs=0.2)
    check_against_ground_truth(vehicle, robot)

    vehicle.land()
    vehicle.wait_state(NavState.LANDED, timeout_s=30)
    assert robot.position()[2] < 0.2
    ll = vehicle.poll(int(PollMask.LL_STATUS))[PD.LL_STATUS]
    assert ll.flying == 0
    check_against_ground_truth(vehicle, robot)
