"""Telemetry synthesis on its own: structures from a snapshot and the boards' status, no boards."""

from __future__ import annotations

from dataclasses import replace

from skeye.pilot.telemetry import BoardStatus, Telemetry
from skeye.wire.packets import (
    POLL_MASK_ALL,
    CtrlBits,
    CtrlInput,
    CurrentWay,
    ImuRawData,
    LlStatus,
    NavState,
    NavStatus,
    PadAction,
    RcData,
    encode,
)
from tests.pilot.fake_airframe import FakeAirframe

IDLE = BoardStatus(
    state=NavState.LANDED,
    pad_mode=PadAction.OFF,
    sticks=CtrlInput(0, 0, 0, 0, 0),
    motors_on=False,
    motion_pending=False,
    checksum_errors=0,
    home_ned_m=(0.0, 0.0, 0.0),
    waypoint=None,
    waypoint_target=None,
    waypoint_status=0,
)


def test_a_poll_depends_only_on_the_snapshot_and_the_status() -> None:
    snap = FakeAirframe().snapshot()
    telemetry = Telemetry(snap)
    first = [encode(m) for m in telemetry.poll(POLL_MASK_ALL, snap, IDLE)]
    assert len(first) == 8
    assert [encode(m) for m in telemetry.poll(POLL_MASK_ALL, snap, IDLE)] == first


def test_status_shows_in_the_structures() -> None:
    snap = replace(FakeAirframe().snapshot(), time_s=12.5, landed=False, armed=True)
    telemetry = Telemetry(replace(snap, time_s=2.0))
    status = replace(
        IDLE,
        state=NavState.HOLDING,
        sticks=CtrlInput(100, -200, 300, 1000, int(CtrlBits.PITCH | CtrlBits.HEIGHT_CONTROL)),
        checksum_errors=300,
        waypoint_target=(3.0, 4.0, 0.0),
        home_ned_m=(0.0, 0.0, 1.0),
        motor_time_s=10.4,  # up_time: the seconds the motors have turned
    )
    ll, rc, way = telemetry.poll(0x0001 | 0x0008 | 0x0100, snap, status)
    assert isinstance(ll, LlStatus) and isinstance(rc, RcData) and isinstance(way, CurrentWay)
    assert (ll.flightMode, ll.chksum_error, ll.up_time, ll.flying) == (0x07, 255, 10, 1)
    assert ll.battery_voltage_1 == 12400
    # AscTec's order: pitch, roll, thrust, yaw, serial enable, mode switch (GPS: holding)
    assert rc.channels_in == (2148, 1848, 1000, 2348, 4095, 4095, 0, 0)
    assert way.distance_to_wp == 50 and way.navigation_status & 0x04  # 5 m, within 20 m
    nav = telemetry.nav_status(snap, status)
    assert isinstance(nav, NavStatus) and nav.z == -1000 and nav.state is NavState.HOLDING


def test_imu_rawdata_saturates_like_a_sensor() -> None:
    snap = replace(
        FakeAirframe().snapshot(),
        rates_frd_rad_s=(100.0, -100.0, 0.0),
        specific_force_frd_m_s2=(0.0, 0.0, -50.0),
    )
    (raw,) = Telemetry(snap).poll(0x0002, snap, IDLE)
    assert isinstance(raw, ImuRawData)
    assert (raw.gyro_x, raw.gyro_y, raw.acc_z) == (32767, -32768, -32768)


def test_a_waypoint_beyond_the_fields_range_reads_as_that_far_or_more() -> None:
    # CURRENT_WAY's distance_to_wp (dm, uint16) holds 6553.5 m: a waypoint farther (an
    # envelope widened past 3.3 km) reads as the field's top, the structure is still sent
    snap = FakeAirframe().snapshot()
    n, e, d = snap.pos_ned_m
    status = replace(IDLE, waypoint_target=(n + 7000.0, e, d))
    telemetry = Telemetry(snap)
    (way,) = telemetry.poll(0x0100, snap, status)
    assert isinstance(way, CurrentWay) and way.distance_to_wp == 0xFFFF
    near = replace(IDLE, waypoint_target=(n + 6000.0, e, d))
    (way,) = telemetry.poll(0x0100, snap, near)
    assert way.distance_to_wp == 60000


def test_the_vehicle_clock_wraps_in_its_fields_as_a_uint32_of_ms() -> None:
    # On a real airframe (asctec-ll://, mavlink:// in real time) the vehicle's clock is the
    # host's monotonic clock, its uptime: past 49.7 days NAV_STATUS's time (uint32 ms) was out
    # of range, and NAV_STATUS was left out of the telemetry for good. It wraps, as MAVLink's
    # time_boot_ms does.
    uptime_s = 58 * 86400.0
    snap = replace(FakeAirframe().snapshot(), time_s=uptime_s)
    nav = Telemetry(snap).nav_status(snap, IDLE)
    assert isinstance(nav, NavStatus)
    assert nav.time == round(uptime_s * 1000) % 2**32
    encode(nav)  # and it goes on the wire
