"""The pilot's side of an AscTec LL board, sans-IO (skeye.pilot.ll_control): the estimate from
the polled structures, and the sticks for each motion, checked against the board's own reading
of them (the pilot's boards, which the simulator's LL board is)."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from skeye.pilot.airframe import VehicleLimits
from skeye.pilot.boards import BoardSettings, OnboardBoards
from skeye.pilot.ll_control import GPS_STICKS, LLEstimate, StickPilot, Sticks, Velocity, nav_state
from skeye.wire.packet_units import (
    GpsBestSi,
    GpsSi,
    ImuCalcSi,
    gps_data_advanced_from_si,
    imu_calcdata_from_si,
)
from skeye.wire.packets import PD, CtrlInput, LlStatus, NavState
from tests.pilot.fake_airframe import FakeAirframe

LIMITS = VehicleLimits(3.0, 1.5, 1.745)


def imu(vel_ned=(0.0, 0.0, 0.0), height=1.0, rpy=(0.0, 0.0, 0.0)) -> object:
    return imu_calcdata_from_si(ImuCalcSi(
        roll_rad=rpy[0], pitch_rad=rpy[1], yaw_rad=rpy[2], roll_rate_rad_s=0.0,
        pitch_rate_rad_s=0.0, yaw_rate_rad_s=0.0, acc_body_frd_m_s2=(0.0, 0.0, -9.81),
        acc_earth_ned_m_s2=(0.0, 0.0, 0.0), acc_angle_roll_rad=0.0, acc_angle_pitch_rad=0.0,
        acc_absolute_m_s2=9.81, mag_field_raw=(2000, 0, 4000), mag_heading_rad=rpy[2],
        vel_ned_m_s=vel_ned, height_m=height, climb_rate_m_s=-vel_ned[2],
        baro_climb_rate_m_s=0.0, baro_height_m=height))


def status(flying: bool = True, motors: bool = True) -> LlStatus:
    return LlStatus(12400, 12400, 0, 1000, 1, 0, int(flying), int(motors), 1, 3)


def gps(lat: float, lon: float) -> object:
    return gps_data_advanced_from_si(GpsSi(lat, lon, 300.0, 0.0, 0.0, 0.0, 2.5, 5.0, 0.2, 9, 3),
                                     GpsBestSi(lat, lon, 0.0, 0.0))


def test_the_estimate_integrates_the_velocity_and_takes_the_rest_from_the_structures():
    est = LLEstimate()
    est.update({PD.LL_STATUS: status(), PD.IMU_CALCDATA: imu((1.0, -0.5, 0.0), 2.0,
                                                            (0.1, -0.05, math.radians(350)))},
               10.0)
    est.update({PD.IMU_CALCDATA: imu((1.0, -0.5, 0.0), 2.0, (0.1, -0.05, 0.2))}, 10.5)
    snap = est.snapshot()
    assert snap.pos_ned_m == pytest.approx((0.5, -0.25, -2.0), abs=1e-3)
    assert snap.vel_ned_m_s == pytest.approx((1.0, -0.5, 0.0), abs=1e-3)
    assert snap.rpy_rad == pytest.approx((0.1, -0.05, 0.2), abs=1e-4)
    assert snap.time_s == 10.5 and snap.armed and not snap.landed
    assert snap.battery_v == pytest.approx(12.4) and snap.mag_field_frd_ut == (20.0, 0.0, 40.0)


def test_the_first_fix_does_not_move_the_estimate_and_later_ones_pull_it_slowly():
    est = LLEstimate()
    est.update({PD.LL_STATUS: status(), PD.IMU_CALCDATA: imu((0.2, 0.0, 0.0))}, 0.0)
    est.update({PD.IMU_CALCDATA: imu((0.2, 0.0, 0.0))}, 5.0)  # 1 m north, no fix yet
    est.update({PD.GPS_DATA_ADVANCED: gps(49.0, 8.0), PD.IMU_CALCDATA: imu((0.0, 0.0, 0.0))},
               5.0)
    assert est.snapshot().pos_ned_m[0] == pytest.approx(1.0, abs=1e-3)
    assert est.snapshot().gps is not None and est.snapshot().gps.fix
    # The GPS estimate says 1 m further north (0.9 s later): the pull takes 0.9 / 30 of it.
    north_1m = 49.0 + 1.0 / 111_200.0
    est.update({PD.GPS_DATA_ADVANCED: gps(north_1m, 8.0), PD.IMU_CALCDATA: imu()}, 5.9)
    assert est.snapshot().pos_ned_m[0] == pytest.approx(1.0 + 0.9 / 30.0, abs=2e-3)


def board_reading(sticks: CtrlInput) -> tuple[str, tuple[float, ...]]:
    """What the pilot's boards (the emulated LL board) make of ``sticks``, motors running."""
    air = FakeAirframe()
    boards = OnboardBoards(air, BoardSettings(max_speed_m_s=3.0, max_climb_m_s=1.5))
    boards.motors_on = True
    air.snap = replace(air.snap, armed=True, landed=False)
    boards.flight._state = NavState.HOLDING
    boards.handle(sticks, 0.0)
    return air.calls[-1]


@pytest.mark.parametrize(("velocity", "reading"), [
    ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),  # centred: the board holds (its height too)
    ((3.0, 0.0, 0.0), (3.0, 0.0, 0.0)),
    ((0.0, -1.5, 0.0), (0.0, -1.5, 0.0)),
    ((0.3, 0.2, -0.4), (0.3, 0.2, -0.4)),
    ((9.0, 0.0, 5.0), (3.0, 0.0, 1.5)),  # beyond full stick: clamped
])
def test_velocity_sticks_are_read_back_as_the_velocities(velocity, reading):
    pilot = StickPilot(LIMITS)
    sticks = pilot.velocity_sticks(*velocity, 0.0)
    assert sticks.ctrl == GPS_STICKS
    name, args = board_reading(sticks)
    assert name == "set_velocity"
    assert args[:3] == pytest.approx(reading, abs=1e-3)  # 1.5 mm/s a count


def snap_of(est_armed: bool, landed: bool, time_s: float = 0.0, alt: float = 0.08):
    air = FakeAirframe()
    return replace(air.snap, armed=est_armed, landed=landed, time_s=time_s,
                   pos_ned_m=(0.0, 0.0, -alt))


def test_a_take_off_gives_the_gesture_until_the_motors_run_then_climbs_and_holds():
    pilot = StickPilot(LIMITS)
    ground = snap_of(False, True)
    pilot.take_off(nav_state(ground), 1.08, armed=False)
    assert pilot.busy
    assert pilot.sticks(ground) == CtrlInput(0, 0, -2047, 0, GPS_STICKS)  # the gesture
    armed = snap_of(True, True, 1.0)
    climb = pilot.sticks(armed)
    assert climb.thrust > 2048 and climb.pitch == 0 and climb.roll == 0 and pilot.busy
    there = snap_of(True, False, 5.0, 1.08)
    for t in range(40):  # at the height and still: arrived, the target held
        pilot.sticks(replace(there, time_s=5.0 + 0.05 * t))
    assert not pilot.busy


def test_a_landing_leaves_the_board_to_stop_the_motors_then_gestures():
    pilot = StickPilot(LIMITS)
    air = snap_of(True, False, 0.0, 1.0)
    pilot.land(nav_state(air))
    assert pilot.sticks(air).thrust < 2048 and pilot.busy  # descending
    # Down: every axis to the board (ctrl 0), which stops its motors itself ...
    assert pilot.sticks(snap_of(True, True, 5.0)) == CtrlInput(0, 0, 0, 0, 0) and pilot.busy
    assert pilot.sticks(snap_of(True, True, 7.9)) == CtrlInput(0, 0, 0, 0, 0)
    off = snap_of(False, True, 6.1)
    assert pilot.sticks(off) == CtrlInput(0, 0, 0, 0, GPS_STICKS) and not pilot.busy
    # ... and the gesture only for a board that has not, 3 s on.
    pilot.land(nav_state(air))
    pilot.sticks(snap_of(True, True, 10.0))
    assert pilot.sticks(snap_of(True, True, 13.1)) == CtrlInput(0, 0, -2047, 0, GPS_STICKS)


def test_stick_flight_starts_the_motors_first_and_a_timed_velocity_ends():
    pilot = StickPilot(LIMITS)
    pilot.set(Sticks(0.1, 0.0, 0.0, 0.6, False))
    assert pilot.sticks(snap_of(False, True)) == CtrlInput(0, 0, -2047, 0, GPS_STICKS)
    sticks = pilot.sticks(snap_of(True, True))
    assert sticks.ctrl == 0x0F and sticks.thrust == round(0.6 * 4095) and sticks.roll > 0
    pilot.set(Velocity(0.5, 0.0, 0.0, 0.0, until_s=2.0))
    assert pilot.sticks(snap_of(True, False, 1.0)).pitch < 0  # forward: stick forward
    assert pilot.sticks(snap_of(True, False, 2.0)) == pilot.velocity_sticks(0.0, 0.0, 0.0, 0.0)
