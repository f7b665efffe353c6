"""Tests of AscTec integer scalings <-> SI: known values, clamps, round trips within one count."""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skeye.errors import LocalProtocolError
from skeye.wire import packet_units as sc
from skeye.wire.packet_defs import LAYOUTS, Field
from skeye.wire.packets import (
    CommandStreamParser,
    CtrlBits,
    CtrlInput,
    GotoGps,
    GpsData,
    GpsDataAdvanced,
    ImuCalcData,
    Message,
    MoveBy,
    MoveFrame,
    NavState,
    NavStatus,
    PadAction,
    PadMode,
    PadReport,
    VehicleStreamParser,
    Velocity,
    Waypoint,
    WaypointProps,
    encode,
)
from skeye.wire.scales import YAW_FULL_MDEG

DEG = math.pi / 180.0


def assert_fields_close(a: object, b: object) -> None:
    """Dataclasses of the same type with every field equal to within float rounding."""
    assert type(a) is type(b)
    for name, value in vars(b).items():
        if isinstance(value, int):
            assert getattr(a, name) == value, name
        else:
            assert getattr(a, name) == pytest.approx(value, rel=1e-12, abs=1e-12), name


# (SI -> counts, counts -> SI, SI value, counts) for values exact by definition.
KNOWN: list[tuple[Callable[[float], int], Callable[[int], float], float, int]] = [
    (sc.rad_to_mdeg, sc.mdeg_to_rad, math.pi / 2, 90_000),
    (sc.rad_to_mdeg, sc.mdeg_to_rad, -10 * DEG, -10_000),
    (sc.yaw_rad_to_mdeg, sc.yaw_mdeg_to_rad, -math.pi / 2, 270_000),
    (sc.rad_s_to_angvel_counts, sc.angvel_counts_to_rad_s, 10 * DEG, 648),  # 64.8 = 1 deg/s
    (sc.m_s2_to_acc_counts, sc.acc_counts_to_m_s2, 9.80665, 10_000),
    (sc.m_s2_to_acc_counts, sc.acc_counts_to_m_s2, -9.80665 / 2, -5_000),
    (sc.m_to_mm, sc.mm_to_m, 1.234, 1234),
    (sc.m_s_to_mm_s, sc.mm_s_to_m_s, -0.5, -500),
    (sc.m_to_dm, sc.dm_to_m, 12.3, 123),
    (sc.deg_to_deg_e7, sc.deg_e7_to_deg, 47.3977419, 473977419),
    (sc.angle_rad_to_stick, sc.stick_to_angle_rad, 2047 * 0.025 * DEG, 2047),
    (sc.angle_rad_to_stick, sc.stick_to_angle_rad, -10 * DEG, -400),
    (sc.yaw_rate_rad_s_to_stick, sc.stick_to_yaw_rate_rad_s, 12 * DEG, 100),
    (sc.thrust_fraction_to_counts, sc.thrust_counts_to_fraction, 1.0, 4095),
    (sc.thrust_fraction_to_counts, sc.thrust_counts_to_fraction, 0.0, 0),
    (sc.rad_s_to_mrad_s, sc.mrad_s_to_rad_s, -0.25, -250),
    (sc.s_to_ms, sc.ms_to_s, 2.5, 2500),
    (sc.s_to_cs, sc.cs_to_s, 3.0, 300),
    (sc.v_to_mv, sc.mv_to_v, 12.1, 12_100),
    (sc.fraction_to_quality, sc.quality_to_fraction, 0.87, 870),
    (sc.fraction_to_controller_thrust, sc.controller_thrust_to_fraction, 0.5, 100),
]


@pytest.mark.parametrize(("to_wire", "to_si", "si", "counts"), KNOWN)
def test_known_values(
    to_wire: Callable[[float], int], to_si: Callable[[int], float], si: float, counts: int
) -> None:
    assert to_wire(si) == counts
    assert to_si(counts) == pytest.approx(si, abs=1e-12)


def test_yaw_wraps_to_asctec_range() -> None:
    assert sc.yaw_rad_to_mdeg(2 * math.pi) == 0
    assert sc.yaw_rad_to_mdeg(-1e-9) == 0
    assert sc.yaw_rad_to_mdeg(-DEG) == 359_000
    assert sc.yaw_rad_to_mdeg(7 * math.pi) == 180_000
    assert sc.yaw_mdeg_to_rad(360_000) == pytest.approx(0.0, abs=1e-12)
    assert sc.yaw_mdeg_to_rad(270_000) == pytest.approx(-math.pi / 2)


def test_sticks_and_thrust_clamp() -> None:
    assert sc.angle_rad_to_stick(math.radians(80)) == 2047
    assert sc.angle_rad_to_stick(math.radians(-80)) == -2047
    assert sc.yaw_rate_rad_s_to_stick(10.0) == 2047
    assert sc.yaw_rate_rad_s_to_stick(-10.0) == -2047
    assert sc.thrust_fraction_to_counts(1.5) == 4095
    assert sc.thrust_fraction_to_counts(-0.1) == 0
    assert sc.stick_to_angle_rad(2047) == pytest.approx(math.radians(51.175))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_values_are_refused(bad: float) -> None:
    for to_wire, *_ in KNOWN:
        with pytest.raises(LocalProtocolError):
            to_wire(bad)


# Each pair with one count's size in SI, and the integer range checked.
PAIRS: list[tuple[Callable[[float], int], Callable[[int], float], float, int, int]] = [
    (sc.rad_to_mdeg, sc.mdeg_to_rad, 0.001 * DEG, -(2**31), 2**31 - 1),
    (sc.yaw_rad_to_mdeg, sc.yaw_mdeg_to_rad, 0.001 * DEG, 0, 359_999),
    (sc.rad_s_to_angvel_counts, sc.angvel_counts_to_rad_s, DEG / 64.8, -(2**31), 2**31 - 1),
    (sc.m_s2_to_acc_counts, sc.acc_counts_to_m_s2, 9.80665e-4, -(2**15), 2**15 - 1),
    (sc.m_to_mm, sc.mm_to_m, 1e-3, -(2**31), 2**31 - 1),
    (sc.m_s_to_mm_s, sc.mm_s_to_m_s, 1e-3, -(2**31), 2**31 - 1),
    (sc.deg_to_deg_e7, sc.deg_e7_to_deg, 1e-7, -1_800_000_000, 1_800_000_000),
    (sc.angle_rad_to_stick, sc.stick_to_angle_rad, 0.025 * DEG, -2047, 2047),
    (sc.yaw_rate_rad_s_to_stick, sc.stick_to_yaw_rate_rad_s, 0.12 * DEG, -2047, 2047),
    (sc.thrust_fraction_to_counts, sc.thrust_counts_to_fraction, 1 / 4095, 0, 4095),
    (sc.rad_s_to_mrad_s, sc.mrad_s_to_rad_s, 1e-3, -(2**15), 2**15 - 1),
]


@pytest.mark.parametrize(("to_wire", "to_si", "step", "lo", "hi"), PAIRS)
@settings(max_examples=50, deadline=None)
@given(data=st.data())
def test_counts_round_trip_exactly_and_si_within_half_a_count(
    to_wire: Callable[[float], int],
    to_si: Callable[[int], float],
    step: float,
    lo: int,
    hi: int,
    data: st.DataObject,
) -> None:
    counts = data.draw(st.integers(lo, hi))
    assert to_wire(to_si(counts)) == counts
    frac = data.draw(st.floats(-0.49, 0.49))
    si = to_si(counts) + frac * step
    if to_wire is sc.yaw_rad_to_mdeg:
        err = abs(sc.wrap_pi(to_si(to_wire(si)) - si))
    else:
        err = abs(to_si(to_wire(si)) - si)
    assert err <= 0.5 * step * (1 + 1e-9) + 1e-15


# --- whole structures ------------------------------------------------------------------------


def _imu_si(
    roll: float, pitch: float, yaw: float, vel: tuple[float, float, float], height: float
) -> sc.ImuCalcSi:
    return sc.ImuCalcSi(
        roll_rad=roll,
        pitch_rad=pitch,
        yaw_rad=yaw,
        roll_rate_rad_s=0.1,
        pitch_rate_rad_s=-0.2,
        yaw_rate_rad_s=0.3,
        acc_body_frd_m_s2=(0.1, -0.2, -9.7),
        acc_earth_ned_m_s2=(0.05, 0.0, 0.1),
        acc_angle_roll_rad=roll + 0.01,
        acc_angle_pitch_rad=pitch - 0.01,
        acc_absolute_m_s2=9.81,
        mag_field_raw=(120, -30, 400),
        mag_heading_rad=yaw,
        vel_ned_m_s=vel,
        height_m=height,
        climb_rate_m_s=-vel[2],
        baro_climb_rate_m_s=-vel[2] + 0.02,
        baro_height_m=height - 0.1,
    )


def _assert_imu_close(a: sc.ImuCalcSi, b: sc.ImuCalcSi) -> None:
    """Every field within one count of its scaling."""
    mdeg, angvel, acc, mm = 0.001 * DEG, DEG / 64.8, 9.80665e-4, 1e-3
    for name, tol in [
        ("roll_rad", mdeg),
        ("pitch_rad", mdeg),
        ("acc_angle_roll_rad", mdeg),
        ("acc_angle_pitch_rad", mdeg),
        ("roll_rate_rad_s", angvel),
        ("pitch_rate_rad_s", angvel),
        ("yaw_rate_rad_s", angvel),
        ("acc_absolute_m_s2", acc),
        ("height_m", mm),
        ("climb_rate_m_s", mm),
        ("baro_climb_rate_m_s", mm),
        ("baro_height_m", mm),
    ]:
        assert getattr(a, name) == pytest.approx(getattr(b, name), abs=tol), name
    for name in ("yaw_rad", "mag_heading_rad"):
        assert abs(sc.wrap_pi(getattr(a, name) - getattr(b, name))) <= mdeg, name
    for name, tol in [
        ("acc_body_frd_m_s2", acc),
        ("acc_earth_ned_m_s2", acc),
        ("vel_ned_m_s", mm),
    ]:
        assert getattr(a, name) == pytest.approx(getattr(b, name), abs=tol), name
    assert a.mag_field_raw == b.mag_field_raw


def _over_the_wire_imu(msg: ImuCalcData) -> ImuCalcData:
    (back,) = VehicleStreamParser().feed(encode(msg))
    assert isinstance(back, ImuCalcData)
    return back


def test_known_attitude_and_velocity_survive() -> None:
    si = _imu_si(math.radians(10), math.radians(-5), math.radians(-90), (1.5, -0.25, -0.1), 2.5)
    msg = sc.imu_calcdata_from_si(si)
    # FRD and "nick is pitch": the wire carries AscTec's integers.
    assert (msg.angle_roll, msg.angle_nick, msg.angle_yaw) == (10_000, -5_000, 270_000)
    assert (msg.speed_x, msg.speed_y, msg.speed_z) == (1500, -250, -100)
    assert (msg.height, msg.dheight) == (2500, 100)
    assert msg.acc_z_calib == round(-9.7 / 9.80665 * 10_000)
    _assert_imu_close(sc.imu_calcdata_to_si(_over_the_wire_imu(msg)), si)


angles = st.floats(-math.pi / 2, math.pi / 2)
speeds = st.floats(-30.0, 30.0)


@settings(max_examples=100, deadline=None)
@given(
    roll=st.floats(-math.pi, math.pi),
    pitch=angles,
    yaw=st.floats(-10.0, 10.0),
    vel=st.tuples(speeds, speeds, speeds),
    height=st.floats(-100.0, 5000.0),
)
def test_attitude_and_velocity_round_trip_within_one_count(
    roll: float, pitch: float, yaw: float, vel: tuple[float, float, float], height: float
) -> None:
    si = _imu_si(roll, pitch, yaw, vel, height)
    back = sc.imu_calcdata_to_si(_over_the_wire_imu(sc.imu_calcdata_from_si(si)))
    _assert_imu_close(back, si)


def test_imu_accelerations_saturate_like_a_sensor() -> None:
    si = _imu_si(0.0, 0.0, 0.0, (0.0, 0.0, 0.0), 0.0)
    hard = sc.ImuCalcSi(**{**si.__dict__, "acc_body_frd_m_s2": (0.0, 50.0, -5 * 9.80665)})
    msg = sc.imu_calcdata_from_si(hard)
    assert (msg.acc_y_calib, msg.acc_z_calib) == (32767, -32768)


@settings(max_examples=100, deadline=None)
@given(
    roll=st.floats(-0.8, 0.8),
    pitch=st.floats(-0.8, 0.8),
    rate=st.floats(-4.0, 4.0),
    thrust=st.floats(0.0, 1.0),
)
def test_ctrl_input_round_trip(roll: float, pitch: float, rate: float, thrust: float) -> None:
    msg = sc.ctrl_input_from_si(roll, pitch, rate, thrust)
    (back,) = CommandStreamParser().feed(encode(msg))
    assert isinstance(back, CtrlInput)
    si = sc.ctrl_input_to_si(back)
    assert si.roll_rad == pytest.approx(roll, abs=0.025 * DEG / 2 + 1e-12)
    assert si.pitch_rad == pytest.approx(pitch, abs=0.025 * DEG / 2 + 1e-12)
    assert si.yaw_rate_rad_s == pytest.approx(rate, abs=0.12 * DEG / 2 + 1e-12)
    assert si.thrust_fraction == pytest.approx(thrust, abs=0.5 / 4095 + 1e-12)
    assert si.ctrl == CtrlBits.PITCH | CtrlBits.ROLL | CtrlBits.YAW | CtrlBits.THRUST


def test_ctrl_input_full_stick() -> None:
    msg = sc.ctrl_input_from_si(math.radians(60), math.radians(-60), -9.0, 2.0, ctrl=0x1F)
    assert (msg.roll, msg.pitch, msg.yaw, msg.thrust, msg.ctrl) == (2047, -2047, -2047, 4095, 0x1F)


def test_gps_round_trip_and_axes() -> None:
    si = sc.GpsSi(47.3977419, 8.5455938, 488.2, 1.25, -0.5, math.radians(350), 2.5, 4.0, 0.3, 9, 3)
    msg = sc.gps_data_from_si(si)
    assert (msg.speed_x, msg.speed_y) == (1250, -500)  # x east, y north
    assert (msg.latitude, msg.longitude, msg.heading) == (473977419, 85455938, 350_000)
    (back,) = VehicleStreamParser().feed(encode(msg))
    assert isinstance(back, GpsData)
    got = sc.gps_data_to_si(back)
    assert got.latitude_deg == pytest.approx(si.latitude_deg, abs=1e-7)
    assert got.heading_rad == pytest.approx(sc.wrap_pi(si.heading_rad), abs=1e-5)
    assert (got.num_sv, got.status) == (9, 3)
    best = sc.GpsBestSi(47.39774, 8.54559, 1.2, -0.4)
    adv = sc.gps_data_advanced_from_si(si, best)
    gps_back, best_back = sc.gps_data_advanced_to_si(adv)
    assert gps_back == got
    assert best_back.longitude_deg == pytest.approx(best.longitude_deg, abs=1e-7)
    assert best_back.vel_north_m_s == pytest.approx(-0.4)


def test_nav_status_round_trip() -> None:
    si = sc.NavStatusSi(
        NavState.HOLDING, PadAction.HOLD, (3.2, -1.1, -1.5), -0.5, (0.1, 0.2, -0.3), 11.9, 12.345
    )
    msg = sc.nav_status_from_si(si)
    assert (msg.x, msg.y, msg.z, msg.vz, msg.battery, msg.time) == (
        3200,
        -1100,
        -1500,
        -300,
        11900,
        12345,
    )
    (back,) = VehicleStreamParser().feed(encode(msg))
    got = sc.nav_status_to_si(back)  # type: ignore[arg-type]
    assert got.state is NavState.HOLDING and got.pad_mode is PadAction.HOLD
    assert got.pos_ned_m == pytest.approx(si.pos_ned_m)
    assert got.yaw_rad == pytest.approx(si.yaw_rad, abs=1e-5)
    assert got.vel_ned_m_s == pytest.approx(si.vel_ned_m_s)
    assert (
        sc.nav_status_from_si(
            sc.NavStatusSi(NavState.FLYING, PadAction.OFF, (0, 0, 0), 0, (40.0, -40.0, 0), 0, 0)
        ).vx
        == 32767
    )


def test_pad_report_round_trip() -> None:
    si = sc.PadSi(True, 0b11, -0.12, 0.04, 1.8, 0.87, 98.765)
    msg = sc.pad_report_from_si(si)
    assert (msg.found, msg.dx, msg.dy, msg.quality, msg.frame_time) == (1, -120, 40, 870, 98765)
    assert sc.pad_report_to_si(msg) == si


def test_command_builders_round_trip() -> None:
    vel = sc.velocity_from_si((0.5, -0.25, -0.1), 0.3, 2.0)
    assert (vel.vx, vel.vy, vel.vz, vel.yaw_rate, vel.duration) == (500, -250, -100, 300, 2000)
    assert sc.velocity_to_si(vel) == sc.VelocitySi((0.5, -0.25, -0.1), 0.3, 2.0)
    move = sc.MoveBySi((1.0, -2.0, 0.3), math.radians(45), MoveFrame.WORLD_NED, 0.5)
    mb = sc.move_by_from_si(move)
    assert (mb.dx, mb.dy, mb.dz, mb.dyaw, mb.frame, mb.speed) == (1000, -2000, 300, 45000, 1, 500)
    assert sc.move_by_to_si(mb).dyaw_rad == pytest.approx(move.dyaw_rad)
    goto = sc.GotoGpsSi(47.3977419, 8.5455938, 5.0, 1.5)
    assert sc.goto_gps_to_si(sc.goto_gps_from_si(goto)) == goto
    assert sc.take_off_to_si(sc.take_off_from_si(1.5)) == 1.5
    with pytest.raises(LocalProtocolError):
        sc.take_off_from_si(0.0)
    pad = sc.PadModeSi(PadAction.LAND, 0.1, 0.3)
    assert sc.pad_mode_to_si(sc.pad_mode_from_si(pad)) == pad
    with pytest.raises(LocalProtocolError):
        sc.velocity_from_si((40.0, 0.0, 0.0), 0.0)


def test_waypoint_builders_relative_and_absolute() -> None:
    rel = sc.WaypointSi(WaypointProps.HEIGHT_ENABLED, 50, 3.0, 2.5, 10.0, -5.0, math.pi / 2, 10.0)
    wp = sc.waypoint_from_si(rel)
    assert (wp.X, wp.Y, wp.yaw, wp.time, wp.pos_acc, wp.height) == (
        10000,
        -5000,
        90000,
        300,
        2500,
        10000,
    )
    assert_fields_close(sc.waypoint_to_si(wp), rel)
    absolute = sc.WaypointSi(WaypointProps.ABSOLUTE, 50, 0.0, 1.0, 8.5455938, 47.3977419, 0.0, 5.0)
    wpa = sc.waypoint_from_si(absolute)
    assert (wpa.X, wpa.Y) == (85455938, 473977419)
    (back,) = CommandStreamParser().feed(encode(wpa))
    assert_fields_close(sc.waypoint_to_si(back), absolute)  # type: ignore[arg-type]


# --- the table: every scaled field and every SI view ------------------------------------------

SI_VIEWS: dict[type, type[Message]] = {
    sc.ImuCalcSi: ImuCalcData,
    sc.StickSi: CtrlInput,
    sc.GpsSi: GpsData,
    sc.GpsBestSi: GpsDataAdvanced,
    sc.NavStatusSi: NavStatus,
    sc.PadSi: PadReport,
    sc.VelocitySi: Velocity,
    sc.MoveBySi: MoveBy,
    sc.GotoGpsSi: GotoGps,
    sc.PadModeSi: PadMode,
    sc.WaypointSi: Waypoint,
}
SCALED = [(cls, f) for cls, lay in LAYOUTS.items() for f in lay.fields if f.scale is not None]


@pytest.mark.parametrize("view", SI_VIEWS, ids=lambda v: v.__name__)
def test_si_view_names_carry_the_unit_of_the_wire_field_they_read(view: type) -> None:
    """A view field reading a scaled wire field ends in that scale's unit suffix (``_m_s``...)."""
    table = {f.name: f for f in LAYOUTS[SI_VIEWS[view]].fields}
    checked = 0
    for name, mark in sc.view_fields(view):
        assert set(mark.names) <= set(table), (view.__name__, name)
        for scale in {table[n].scale for n in mark.names} - {None}:
            assert scale is not None
            if view is sc.WaypointSi and name in ("x", "y"):
                continue  # metres or degrees, by the ABSOLUTE flag
            assert name.endswith(scale.suffix), (view.__name__, name, scale.unit)
            checked += 1
    assert checked > 0


@pytest.mark.parametrize(
    ("cls", "field"), SCALED, ids=lambda x: getattr(x, "__name__", None) or x.name
)
@settings(max_examples=30, deadline=None)
@given(data=st.data())
def test_every_scaled_field_round_trips_its_counts(
    cls: type, field: Field, data: st.DataObject
) -> None:
    lo, hi = field.limits
    scale = field.scale
    assert scale is not None
    if scale.clamp is not None:
        lo, hi = max(lo, scale.clamp[0]), min(hi, scale.clamp[1])
    if scale.wrap:
        lo, hi = 0, YAW_FULL_MDEG - 1
    counts = data.draw(st.integers(lo, hi))
    assert scale.to_wire(scale.to_si(counts)) == counts
    assert sc.wire_value(cls, field.name, scale.to_si(counts)) == counts


def test_bad_si_values_are_refused_naming_the_field() -> None:
    si = _imu_si(0.0, 0.0, 0.0, (0.0, 0.0, 0.0), 0.0)
    with pytest.raises(LocalProtocolError, match=r"ImuCalcSi.vel_ned_m_s\[1\]"):
        sc.imu_calcdata_from_si(sc.ImuCalcSi(**{**si.__dict__, "vel_ned_m_s": (0.0, math.nan, 0)}))
    with pytest.raises(LocalProtocolError, match="needs 3 components"):
        sc.imu_calcdata_from_si(sc.ImuCalcSi(**{**si.__dict__, "vel_ned_m_s": (0.0, 1.0)}))
    with pytest.raises(LocalProtocolError, match=r"PadSi\.dx_m"):
        sc.pad_report_from_si(sc.PadSi(True, 0, "1.0", 0.0, 0.0, 0.0, 0.0))  # type: ignore[arg-type]
    with pytest.raises(LocalProtocolError, match="no wire field"):
        sc.wire_value(ImuCalcData, "nope", 1.0)
