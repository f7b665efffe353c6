"""AscTec integer scalings <-> SI: the one place the vehicle packet protocol's units convert.

How this works: each scaled wire quantity has a pair of named converters (``rad_to_mdeg`` /
``mdeg_to_rad`` ...). "To wire" converters round to the nearest count and refuse NaN or
infinity with ``LocalProtocolError``; only the stick and thrust converters clamp, because the
protocol defines a stick range and full stick is a legitimate request. Structure helpers
(``imu_calcdata_from_si`` / ``imu_calcdata_to_si`` ...) build and read whole messages from small
frozen SI dataclasses; when building they saturate int16 sensor fields (accelerations, NAV_STATUS
velocities) at their wire limits, as a real sensor saturates, so a hard landing cannot crash the
telemetry.

Frames: AscTec's IMU body frame is x forward, y right, z down (FRD), the same as the simulator
protocol's; "nick" is pitch. Earth-frame vectors (IMU_CALCDATA acc_x/y/z and speed_x/y/z,
NAV_STATUS x/y/z and vx/vy/vz) are world NED: x north, y east, z down. GPS_DATA is the
exception the protocol names: speed_x is east, speed_y north. ``height`` fields are positive up.
Yaw on the wire is 0..360000 (1/1000 deg, clockwise from north); yaw in SI is wrapped to
[-pi, pi).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from skeye.errors import LocalProtocolError
from skeye.wire.packet_defs import (
    CtrlBits,
    CtrlInput,
    GotoGps,
    GpsData,
    GpsDataAdvanced,
    ImuCalcData,
    MoveBy,
    MoveFrame,
    NavState,
    NavStatus,
    PadAction,
    PadMode,
    PadReport,
    TakeOff,
    Velocity,
    Waypoint,
)

G_M_S2 = 9.80665  # standard gravity; AscTec's 10000 counts
ACC_COUNTS_PER_G = 10_000
ANGVEL_DEG_S_PER_COUNT = 0.015
STICK_DEG_PER_COUNT = 0.025
STICK_YAW_DEG_S_PER_COUNT = 0.120
STICK_MAX = 2047
THRUST_MAX = 4095
CONTROLLER_THRUST_MAX = 200
YAW_FULL_MDEG = 360_000
INT16 = (-(2**15), 2**15 - 1)

Vec3 = tuple[float, float, float]


def _count(value: float, what: str) -> int:
    """Round to the nearest integer count; NaN or infinity is a caller error."""
    if not math.isfinite(value):
        raise LocalProtocolError(f"{what} must be finite, got {value!r}")
    return round(value)


def _clamp(value: int, lo: int, hi: int) -> int:
    return lo if value < lo else hi if value > hi else value


def _vec3(v: Sequence[float], what: str) -> Vec3:
    if len(v) != 3:
        raise LocalProtocolError(f"{what} needs 3 components, got {len(v)}")
    return (float(v[0]), float(v[1]), float(v[2]))


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


# --- angles -------------------------------------------------------------------------------


def mdeg_to_rad(mdeg: int) -> float:
    """1/1000 degree -> radians."""
    return math.radians(mdeg / 1000.0)


def rad_to_mdeg(angle_rad: float) -> int:
    """Radians -> 1/1000 degree (no wrapping: for roll, pitch, relative yaw)."""
    return _count(math.degrees(angle_rad) * 1000.0, "angle_rad")


def yaw_rad_to_mdeg(yaw_rad: float) -> int:
    """Yaw radians -> 1/1000 degree wrapped to 0..359999, as AscTec sends it."""
    return rad_to_mdeg(yaw_rad) % YAW_FULL_MDEG


def yaw_mdeg_to_rad(mdeg: int) -> float:
    """Yaw 1/1000 degree (0..360000) -> radians in [-pi, pi)."""
    return wrap_pi(mdeg_to_rad(mdeg))


def angvel_counts_to_rad_s(counts: int) -> float:
    """IMU angular velocity counts (0.015 deg/s each) -> rad/s."""
    return math.radians(counts * ANGVEL_DEG_S_PER_COUNT)


def rad_s_to_angvel_counts(rate_rad_s: float) -> int:
    """rad/s -> IMU angular velocity counts (0.015 deg/s each)."""
    return _count(math.degrees(rate_rad_s) / ANGVEL_DEG_S_PER_COUNT, "rate_rad_s")


def mrad_s_to_rad_s(mrad_s: int) -> float:
    """mrad/s -> rad/s."""
    return mrad_s / 1000.0


def rad_s_to_mrad_s(rate_rad_s: float) -> int:
    """rad/s -> mrad/s."""
    return _count(rate_rad_s * 1000.0, "rate_rad_s")


# --- acceleration, length, speed, time, voltage ----------------------------------------------


def acc_counts_to_m_s2(counts: int) -> float:
    """Acceleration counts (10000 = 1 g) -> m/s^2."""
    return counts * G_M_S2 / ACC_COUNTS_PER_G


def m_s2_to_acc_counts(acc_m_s2: float) -> int:
    """m/s^2 -> acceleration counts (10000 = 1 g)."""
    return _count(acc_m_s2 * ACC_COUNTS_PER_G / G_M_S2, "acc_m_s2")


def mm_to_m(mm: int) -> float:
    """Millimetres -> metres."""
    return mm / 1000.0


def m_to_mm(length_m: float) -> int:
    """Metres -> millimetres."""
    return _count(length_m * 1000.0, "length_m")


def mm_s_to_m_s(mm_s: int) -> float:
    """mm/s -> m/s."""
    return mm_s / 1000.0


def m_s_to_mm_s(speed_m_s: float) -> int:
    """m/s -> mm/s."""
    return _count(speed_m_s * 1000.0, "speed_m_s")


def dm_to_m(dm: int) -> float:
    """Decimetres (CURRENT_WAY distance_to_wp) -> metres."""
    return dm / 10.0


def m_to_dm(length_m: float) -> int:
    """Metres -> decimetres."""
    return _count(length_m * 10.0, "length_m")


def deg_e7_to_deg(deg_e7: int) -> float:
    """Degrees x 1e7 (latitude, longitude) -> degrees."""
    return deg_e7 / 1e7


def deg_to_deg_e7(angle_deg: float) -> int:
    """Degrees -> degrees x 1e7."""
    return _count(angle_deg * 1e7, "angle_deg")


def ms_to_s(ms: int) -> float:
    """Milliseconds -> seconds."""
    return ms / 1000.0


def s_to_ms(time_s: float) -> int:
    """Seconds -> milliseconds."""
    return _count(time_s * 1000.0, "time_s")


def cs_to_s(cs: int) -> float:
    """1/100 s (WAYPOINT time) -> seconds."""
    return cs / 100.0


def s_to_cs(time_s: float) -> int:
    """Seconds -> 1/100 s."""
    return _count(time_s * 100.0, "time_s")


def mv_to_v(mv: int) -> float:
    """Millivolts -> volts."""
    return mv / 1000.0


def v_to_mv(voltage_v: float) -> int:
    """Volts -> millivolts."""
    return _count(voltage_v * 1000.0, "voltage_v")


def quality_to_fraction(quality: int) -> float:
    """PAD quality 0..1000 -> 0..1."""
    return quality / 1000.0


def fraction_to_quality(fraction: float) -> int:
    """0..1 -> PAD quality 0..1000 (clamped)."""
    return _clamp(_count(fraction * 1000.0, "quality fraction"), 0, 1000)


def controller_thrust_to_fraction(thrust: int) -> float:
    """CONTROLLER_OUTPUT thrust 0..200 -> 0..1."""
    return thrust / CONTROLLER_THRUST_MAX


def fraction_to_controller_thrust(fraction: float) -> int:
    """0..1 -> CONTROLLER_OUTPUT thrust 0..200 (clamped)."""
    counts = _count(fraction * CONTROLLER_THRUST_MAX, "thrust fraction")
    return _clamp(counts, 0, CONTROLLER_THRUST_MAX)


# --- sticks (CTRL_INPUT) -------------------------------------------------------------------


def stick_to_angle_rad(stick: int) -> float:
    """Roll/pitch stick counts -> commanded angle (0.025 deg per count)."""
    return math.radians(stick * STICK_DEG_PER_COUNT)


def angle_rad_to_stick(angle_rad: float) -> int:
    """Commanded roll/pitch angle -> stick counts, clamped to -2047..2047 (about 51 deg)."""
    counts = _count(math.degrees(angle_rad) / STICK_DEG_PER_COUNT, "angle_rad")
    return _clamp(counts, -STICK_MAX, STICK_MAX)


def stick_to_yaw_rate_rad_s(stick: int) -> float:
    """Yaw stick counts -> commanded yaw rate (0.120 deg/s per count)."""
    return math.radians(stick * STICK_YAW_DEG_S_PER_COUNT)


def yaw_rate_rad_s_to_stick(rate_rad_s: float) -> int:
    """Commanded yaw rate -> yaw stick counts, clamped to -2047..2047."""
    counts = _count(math.degrees(rate_rad_s) / STICK_YAW_DEG_S_PER_COUNT, "rate_rad_s")
    return _clamp(counts, -STICK_MAX, STICK_MAX)


def thrust_counts_to_fraction(thrust: int) -> float:
    """Thrust stick 0..4095 -> 0..1."""
    return thrust / THRUST_MAX


def thrust_fraction_to_counts(fraction: float) -> int:
    """0..1 -> thrust stick 0..4095 (clamped)."""
    return _clamp(_count(fraction * THRUST_MAX, "thrust fraction"), 0, THRUST_MAX)


# --- whole structures ----------------------------------------------------------------------


@dataclass(frozen=True)
class ImuCalcSi:
    """IMU_CALCDATA in SI. Angles and rates about body FRD axes; earth vectors NED."""

    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    roll_rate_rad_s: float
    pitch_rate_rad_s: float
    yaw_rate_rad_s: float
    acc_body_frd_m_s2: Vec3  # calibrated, body frame
    acc_earth_ned_m_s2: Vec3
    acc_angle_roll_rad: float  # attitude from the accelerometer alone
    acc_angle_pitch_rad: float
    acc_absolute_m_s2: float
    mag_field_raw: tuple[int, int, int]  # Hx, Hy, Hz: direction only, passed through unscaled
    mag_heading_rad: float
    vel_ned_m_s: Vec3
    height_m: float  # fused, positive up
    climb_rate_m_s: float  # dheight, positive up
    baro_climb_rate_m_s: float  # dheight_reference
    baro_height_m: float  # height_reference


def _sat16(counts: int) -> int:
    return _clamp(counts, *INT16)


def imu_calcdata_from_si(si: ImuCalcSi) -> ImuCalcData:
    """Build IMU_CALCDATA from SI values (int16 accelerations saturate at +-3.27 g)."""
    ab = _vec3(si.acc_body_frd_m_s2, "acc_body_frd_m_s2")
    ae = _vec3(si.acc_earth_ned_m_s2, "acc_earth_ned_m_s2")
    v = _vec3(si.vel_ned_m_s, "vel_ned_m_s")
    hx, hy, hz = si.mag_field_raw
    return ImuCalcData(
        angle_nick=rad_to_mdeg(si.pitch_rad),
        angle_roll=rad_to_mdeg(si.roll_rad),
        angle_yaw=yaw_rad_to_mdeg(si.yaw_rad),
        angvel_nick=rad_s_to_angvel_counts(si.pitch_rate_rad_s),
        angvel_roll=rad_s_to_angvel_counts(si.roll_rate_rad_s),
        angvel_yaw=rad_s_to_angvel_counts(si.yaw_rate_rad_s),
        acc_x_calib=_sat16(m_s2_to_acc_counts(ab[0])),
        acc_y_calib=_sat16(m_s2_to_acc_counts(ab[1])),
        acc_z_calib=_sat16(m_s2_to_acc_counts(ab[2])),
        acc_x=_sat16(m_s2_to_acc_counts(ae[0])),
        acc_y=_sat16(m_s2_to_acc_counts(ae[1])),
        acc_z=_sat16(m_s2_to_acc_counts(ae[2])),
        acc_angle_nick=rad_to_mdeg(si.acc_angle_pitch_rad),
        acc_angle_roll=rad_to_mdeg(si.acc_angle_roll_rad),
        acc_absolute_value=m_s2_to_acc_counts(si.acc_absolute_m_s2),
        Hx=hx,
        Hy=hy,
        Hz=hz,
        mag_heading=yaw_rad_to_mdeg(si.mag_heading_rad),
        speed_x=m_s_to_mm_s(v[0]),
        speed_y=m_s_to_mm_s(v[1]),
        speed_z=m_s_to_mm_s(v[2]),
        height=m_to_mm(si.height_m),
        dheight=m_s_to_mm_s(si.climb_rate_m_s),
        dheight_reference=m_s_to_mm_s(si.baro_climb_rate_m_s),
        height_reference=m_to_mm(si.baro_height_m),
    )


def imu_calcdata_to_si(msg: ImuCalcData) -> ImuCalcSi:
    """Read IMU_CALCDATA in SI."""
    return ImuCalcSi(
        roll_rad=mdeg_to_rad(msg.angle_roll),
        pitch_rad=mdeg_to_rad(msg.angle_nick),
        yaw_rad=yaw_mdeg_to_rad(msg.angle_yaw),
        roll_rate_rad_s=angvel_counts_to_rad_s(msg.angvel_roll),
        pitch_rate_rad_s=angvel_counts_to_rad_s(msg.angvel_nick),
        yaw_rate_rad_s=angvel_counts_to_rad_s(msg.angvel_yaw),
        acc_body_frd_m_s2=(
            acc_counts_to_m_s2(msg.acc_x_calib),
            acc_counts_to_m_s2(msg.acc_y_calib),
            acc_counts_to_m_s2(msg.acc_z_calib),
        ),
        acc_earth_ned_m_s2=(
            acc_counts_to_m_s2(msg.acc_x),
            acc_counts_to_m_s2(msg.acc_y),
            acc_counts_to_m_s2(msg.acc_z),
        ),
        acc_angle_roll_rad=mdeg_to_rad(msg.acc_angle_roll),
        acc_angle_pitch_rad=mdeg_to_rad(msg.acc_angle_nick),
        acc_absolute_m_s2=acc_counts_to_m_s2(msg.acc_absolute_value),
        mag_field_raw=(msg.Hx, msg.Hy, msg.Hz),
        mag_heading_rad=yaw_mdeg_to_rad(msg.mag_heading),
        vel_ned_m_s=(mm_s_to_m_s(msg.speed_x), mm_s_to_m_s(msg.speed_y), mm_s_to_m_s(msg.speed_z)),
        height_m=mm_to_m(msg.height),
        climb_rate_m_s=mm_s_to_m_s(msg.dheight),
        baro_climb_rate_m_s=mm_s_to_m_s(msg.dheight_reference),
        baro_height_m=mm_to_m(msg.height_reference),
    )


@dataclass(frozen=True)
class StickSi:
    """CTRL_INPUT in SI: commanded attitude, yaw rate and thrust fraction."""

    roll_rad: float
    pitch_rad: float
    yaw_rate_rad_s: float
    thrust_fraction: float
    ctrl: CtrlBits


_ALL_STICKS = CtrlBits.PITCH | CtrlBits.ROLL | CtrlBits.YAW | CtrlBits.THRUST


def ctrl_input_from_si(
    roll_rad: float,
    pitch_rad: float,
    yaw_rate_rad_s: float,
    thrust_fraction: float,
    ctrl: int = _ALL_STICKS,
) -> CtrlInput:
    """Build CTRL_INPUT from SI commands (sticks and thrust clamp to their ranges)."""
    return CtrlInput(
        pitch=angle_rad_to_stick(pitch_rad),
        roll=angle_rad_to_stick(roll_rad),
        yaw=yaw_rate_rad_s_to_stick(yaw_rate_rad_s),
        thrust=thrust_fraction_to_counts(thrust_fraction),
        ctrl=ctrl,
    )


def ctrl_input_to_si(msg: CtrlInput) -> StickSi:
    """Read CTRL_INPUT in SI."""
    return StickSi(
        roll_rad=stick_to_angle_rad(msg.roll),
        pitch_rad=stick_to_angle_rad(msg.pitch),
        yaw_rate_rad_s=stick_to_yaw_rate_rad_s(msg.yaw),
        thrust_fraction=thrust_counts_to_fraction(msg.thrust),
        ctrl=CtrlBits(msg.ctrl),
    )


@dataclass(frozen=True)
class GpsSi:
    """GPS_DATA in SI (velocities east/north, as the structure carries them)."""

    latitude_deg: float
    longitude_deg: float
    height_m: float
    vel_east_m_s: float
    vel_north_m_s: float
    heading_rad: float
    horizontal_accuracy_m: float
    vertical_accuracy_m: float
    speed_accuracy_m_s: float
    num_sv: int
    status: int  # GPS_FIX_VALID (0x03) = valid fix


def gps_data_from_si(si: GpsSi) -> GpsData:
    """Build GPS_DATA from SI values."""
    return GpsData(
        latitude=deg_to_deg_e7(si.latitude_deg),
        longitude=deg_to_deg_e7(si.longitude_deg),
        height=m_to_mm(si.height_m),
        speed_x=m_s_to_mm_s(si.vel_east_m_s),
        speed_y=m_s_to_mm_s(si.vel_north_m_s),
        heading=yaw_rad_to_mdeg(si.heading_rad),
        horizontal_accuracy=m_to_mm(si.horizontal_accuracy_m),
        vertical_accuracy=m_to_mm(si.vertical_accuracy_m),
        speed_accuracy=m_s_to_mm_s(si.speed_accuracy_m_s),
        numSV=si.num_sv,
        status=si.status,
    )


def gps_data_to_si(msg: GpsData | GpsDataAdvanced) -> GpsSi:
    """Read GPS_DATA (or the GPS_DATA part of GPS_DATA_ADVANCED) in SI."""
    return GpsSi(
        latitude_deg=deg_e7_to_deg(msg.latitude),
        longitude_deg=deg_e7_to_deg(msg.longitude),
        height_m=mm_to_m(msg.height),
        vel_east_m_s=mm_s_to_m_s(msg.speed_x),
        vel_north_m_s=mm_s_to_m_s(msg.speed_y),
        heading_rad=yaw_mdeg_to_rad(msg.heading),
        horizontal_accuracy_m=mm_to_m(msg.horizontal_accuracy),
        vertical_accuracy_m=mm_to_m(msg.vertical_accuracy),
        speed_accuracy_m_s=mm_s_to_m_s(msg.speed_accuracy),
        num_sv=msg.numSV,
        status=msg.status,
    )


@dataclass(frozen=True)
class GpsBestSi:
    """GPS_DATA_ADVANCED's fused best estimates in SI."""

    latitude_deg: float
    longitude_deg: float
    vel_east_m_s: float
    vel_north_m_s: float


def gps_data_advanced_from_si(gps: GpsSi, best: GpsBestSi) -> GpsDataAdvanced:
    """Build GPS_DATA_ADVANCED from the receiver solution and the fused estimate."""
    base = gps_data_from_si(gps)
    return GpsDataAdvanced(
        **{k: getattr(base, k) for k in base.__dataclass_fields__},
        latitude_best_estimate=deg_to_deg_e7(best.latitude_deg),
        longitude_best_estimate=deg_to_deg_e7(best.longitude_deg),
        speed_x_best_estimate=m_s_to_mm_s(best.vel_east_m_s),
        speed_y_best_estimate=m_s_to_mm_s(best.vel_north_m_s),
    )


def gps_data_advanced_to_si(msg: GpsDataAdvanced) -> tuple[GpsSi, GpsBestSi]:
    """Read GPS_DATA_ADVANCED in SI: (receiver solution, fused best estimate)."""
    return gps_data_to_si(msg), GpsBestSi(
        latitude_deg=deg_e7_to_deg(msg.latitude_best_estimate),
        longitude_deg=deg_e7_to_deg(msg.longitude_best_estimate),
        vel_east_m_s=mm_s_to_m_s(msg.speed_x_best_estimate),
        vel_north_m_s=mm_s_to_m_s(msg.speed_y_best_estimate),
    )


@dataclass(frozen=True)
class NavStatusSi:
    """NAV_STATUS in SI (world NED)."""

    state: NavState
    pad_mode: PadAction
    pos_ned_m: Vec3
    yaw_rad: float
    vel_ned_m_s: Vec3
    battery_v: float
    time_s: float


def nav_status_from_si(si: NavStatusSi) -> NavStatus:
    """Build NAV_STATUS from SI values (int16 velocities saturate at +-32.767 m/s)."""
    p = _vec3(si.pos_ned_m, "pos_ned_m")
    v = _vec3(si.vel_ned_m_s, "vel_ned_m_s")
    return NavStatus(
        state=si.state,
        pad_mode=si.pad_mode,
        x=m_to_mm(p[0]),
        y=m_to_mm(p[1]),
        z=m_to_mm(p[2]),
        yaw=yaw_rad_to_mdeg(si.yaw_rad),
        vx=_sat16(m_s_to_mm_s(v[0])),
        vy=_sat16(m_s_to_mm_s(v[1])),
        vz=_sat16(m_s_to_mm_s(v[2])),
        battery=v_to_mv(si.battery_v),
        time=s_to_ms(si.time_s),
    )


def nav_status_to_si(msg: NavStatus) -> NavStatusSi:
    """Read NAV_STATUS in SI."""
    return NavStatusSi(
        state=msg.state,
        pad_mode=msg.pad_mode,
        pos_ned_m=(mm_to_m(msg.x), mm_to_m(msg.y), mm_to_m(msg.z)),
        yaw_rad=yaw_mdeg_to_rad(msg.yaw),
        vel_ned_m_s=(mm_s_to_m_s(msg.vx), mm_s_to_m_s(msg.vy), mm_s_to_m_s(msg.vz)),
        battery_v=mv_to_v(msg.battery),
        time_s=ms_to_s(msg.time),
    )


@dataclass(frozen=True)
class PadSi:
    """PAD in SI: pad centre offset in body FRD, height, identified rings, quality 0..1."""

    found: bool
    rings: int
    dx_m: float
    dy_m: float
    height_m: float
    quality: float
    frame_time_s: float


def pad_report_from_si(si: PadSi) -> PadReport:
    """Build PAD from SI values."""
    return PadReport(
        found=int(si.found),
        rings=si.rings,
        dx=m_to_mm(si.dx_m),
        dy=m_to_mm(si.dy_m),
        height=m_to_mm(si.height_m),
        quality=fraction_to_quality(si.quality),
        frame_time=s_to_ms(si.frame_time_s),
    )


def pad_report_to_si(msg: PadReport) -> PadSi:
    """Read PAD in SI."""
    return PadSi(
        found=bool(msg.found),
        rings=msg.rings,
        dx_m=mm_to_m(msg.dx),
        dy_m=mm_to_m(msg.dy),
        height_m=mm_to_m(msg.height),
        quality=quality_to_fraction(msg.quality),
        frame_time_s=ms_to_s(msg.frame_time),
    )


# --- skeye and AscTec commands ----------------------------------------------------------------


@dataclass(frozen=True)
class VelocitySi:
    """VELOCITY in SI: body FRD velocity, yaw rate, duration (0 = until replaced)."""

    vel_frd_m_s: Vec3
    yaw_rate_rad_s: float
    duration_s: float


def velocity_from_si(
    vel_frd_m_s: Sequence[float], yaw_rate_rad_s: float, duration_s: float = 0.0
) -> Velocity:
    """Build VELOCITY (raises LocalProtocolError beyond +-32.767 m/s or 65.535 s)."""
    v = _vec3(vel_frd_m_s, "vel_frd_m_s")
    return Velocity(
        vx=m_s_to_mm_s(v[0]),
        vy=m_s_to_mm_s(v[1]),
        vz=m_s_to_mm_s(v[2]),
        yaw_rate=rad_s_to_mrad_s(yaw_rate_rad_s),
        duration=s_to_ms(duration_s),
    )


def velocity_to_si(msg: Velocity) -> VelocitySi:
    """Read VELOCITY in SI."""
    return VelocitySi(
        vel_frd_m_s=(mm_s_to_m_s(msg.vx), mm_s_to_m_s(msg.vy), mm_s_to_m_s(msg.vz)),
        yaw_rate_rad_s=mrad_s_to_rad_s(msg.yaw_rate),
        duration_s=ms_to_s(msg.duration),
    )


@dataclass(frozen=True)
class MoveBySi:
    """MOVE_BY in SI: displacement in ``frame`` (body FRD or world NED), yaw change, speed."""

    delta_m: Vec3
    dyaw_rad: float
    frame: MoveFrame
    speed_m_s: float


def move_by_from_si(si: MoveBySi) -> MoveBy:
    """Build MOVE_BY from SI values."""
    d = _vec3(si.delta_m, "delta_m")
    return MoveBy(
        dx=m_to_mm(d[0]),
        dy=m_to_mm(d[1]),
        dz=m_to_mm(d[2]),
        dyaw=rad_to_mdeg(si.dyaw_rad),
        frame=si.frame,
        speed=m_s_to_mm_s(si.speed_m_s),
    )


def move_by_to_si(msg: MoveBy) -> MoveBySi:
    """Read MOVE_BY in SI."""
    return MoveBySi(
        delta_m=(mm_to_m(msg.dx), mm_to_m(msg.dy), mm_to_m(msg.dz)),
        dyaw_rad=mdeg_to_rad(msg.dyaw),
        frame=msg.frame,
        speed_m_s=mm_s_to_m_s(msg.speed),
    )


@dataclass(frozen=True)
class GotoGpsSi:
    """GOTO_GPS in SI."""

    latitude_deg: float
    longitude_deg: float
    height_m: float  # above home
    speed_m_s: float


def goto_gps_from_si(si: GotoGpsSi) -> GotoGps:
    """Build GOTO_GPS from SI values."""
    return GotoGps(
        latitude=deg_to_deg_e7(si.latitude_deg),
        longitude=deg_to_deg_e7(si.longitude_deg),
        height=m_to_mm(si.height_m),
        speed=m_s_to_mm_s(si.speed_m_s),
    )


def goto_gps_to_si(msg: GotoGps) -> GotoGpsSi:
    """Read GOTO_GPS in SI."""
    return GotoGpsSi(
        latitude_deg=deg_e7_to_deg(msg.latitude),
        longitude_deg=deg_e7_to_deg(msg.longitude),
        height_m=mm_to_m(msg.height),
        speed_m_s=mm_s_to_m_s(msg.speed),
    )


def take_off_from_si(height_m: float) -> TakeOff:
    """Build TAKE_OFF to ``height_m`` (must round to at least 1 mm)."""
    return TakeOff(height=m_to_mm(height_m))


def take_off_to_si(msg: TakeOff) -> float:
    """TAKE_OFF's target height in metres."""
    return mm_to_m(msg.height)


@dataclass(frozen=True)
class PadModeSi:
    """PAD_MODE in SI."""

    mode: PadAction
    deadband_m: float
    max_speed_m_s: float


def pad_mode_from_si(si: PadModeSi) -> PadMode:
    """Build PAD_MODE from SI values."""
    return PadMode(
        mode=si.mode, deadband=m_to_mm(si.deadband_m), max_speed=m_s_to_mm_s(si.max_speed_m_s)
    )


def pad_mode_to_si(msg: PadMode) -> PadModeSi:
    """Read PAD_MODE in SI."""
    return PadModeSi(
        mode=msg.mode, deadband_m=mm_to_m(msg.deadband), max_speed_m_s=mm_s_to_m_s(msg.max_speed)
    )


@dataclass(frozen=True)
class WaypointSi:
    """WAYPOINT in SI. ``x``/``y`` are metres, or longitude/latitude degrees when
    ``properties`` has ABSOLUTE."""

    properties: int  # WaypointProps
    max_speed_percent: int
    hold_time_s: float
    position_accuracy_m: float
    x: float
    y: float
    yaw_rad: float
    height_m: float


def waypoint_from_si(si: WaypointSi) -> Waypoint:
    """Build WAYPOINT from SI values (checksum is added on encode)."""
    absolute = bool(si.properties & 0x01)
    return Waypoint(
        properties=si.properties,
        max_speed=si.max_speed_percent,
        time=s_to_cs(si.hold_time_s),
        pos_acc=m_to_mm(si.position_accuracy_m),
        X=deg_to_deg_e7(si.x) if absolute else m_to_mm(si.x),
        Y=deg_to_deg_e7(si.y) if absolute else m_to_mm(si.y),
        yaw=yaw_rad_to_mdeg(si.yaw_rad),
        height=m_to_mm(si.height_m),
    )


def waypoint_to_si(msg: Waypoint) -> WaypointSi:
    """Read WAYPOINT in SI."""
    absolute = bool(msg.properties & 0x01)
    return WaypointSi(
        properties=msg.properties,
        max_speed_percent=msg.max_speed,
        hold_time_s=cs_to_s(msg.time),
        position_accuracy_m=mm_to_m(msg.pos_acc),
        x=deg_e7_to_deg(msg.X) if absolute else mm_to_m(msg.X),
        y=deg_e7_to_deg(msg.Y) if absolute else mm_to_m(msg.Y),
        yaw_rad=yaw_mdeg_to_rad(msg.yaw),
        height_m=mm_to_m(msg.height),
    )
