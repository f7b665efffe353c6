"""The MAVLink telemetry of a skeye vehicle, built from the airframe's snapshot and the boards.

How this works: pure functions: each takes a :class:`VehicleView` (one consistent look at the
vehicle: the airframe's snapshot, the flight state, the mode, home, the geodetic anchor) and the
codec, and returns one pymavlink message in the message's own units (the conversions from SI
are here, named). Positions: LOCAL_POSITION_NED is the onboard estimate in the world's NED frame
(the simulator's origin); GLOBAL_POSITION_INT is that estimate anchored to GPS as the AscTec
link's GPS_DATA_ADVANCED "best estimate" (``skeye.pilot.telemetry.GeoAnchor``), with altitudes
above mean sea level from the mean offset between the GPS fixes' and the estimate's altitudes;
GPS_RAW_INT is the receiver's own fix; GPS_GLOBAL_ORIGIN is the geodetic position of
LOCAL_POSITION_NED's origin as GLOBAL_POSITION_INT anchors it, so that origin + local = global.
Times (``time_boot_ms``, ``time_usec``) are vehicle time: sim time on the simulator, as
NAV_STATUS's, to the nearest microsecond (``time_boot_ms`` its whole milliseconds, as PX4 derives
it), so one instant has one stamp in every message and on both links;
SYSTEM_TIME's ``time_unix_usec`` is the host's wall clock (``VehicleView.unix_time_s``), as PX4
SITL reports its host's real-time clock while its boot time runs in lockstep.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mav

from skeye import __version__
from skeye.geo import GeoOrigin
from skeye.mavlink.codec import MavCodec, MavMessage
from skeye.mavlink.modes import Px4Mode, landed_state, system_status
from skeye.pilot.airframe import Snapshot
from skeye.wire.packet_defs import NavState

UINT16_MAX = 65535
INT16_MAX = 32767
UT_PER_GAUSS = 100.0
PA_PER_HPA = 100.0
SENSORS = (mav.MAV_SYS_STATUS_SENSOR_3D_GYRO | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL
           | mav.MAV_SYS_STATUS_SENSOR_3D_MAG | mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
           | mav.MAV_SYS_STATUS_SENSOR_GPS | mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
           | mav.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
           | mav.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
           | mav.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
           | mav.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL | mav.MAV_SYS_STATUS_GEOFENCE
           | mav.MAV_SYS_STATUS_SENSOR_BATTERY | mav.MAV_SYS_STATUS_PREARM_CHECK)
CAPABILITIES = (mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
                | mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
                | mav.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE)


@dataclass(frozen=True)
class VehicleView:
    """One consistent look at the vehicle for the telemetry builders."""

    snap: Snapshot
    state: NavState
    mode: Px4Mode
    armed: bool
    home_ned_m: tuple[float, float, float]
    origin: GeoOrigin | None  # the geodetic position of the estimate's NED origin (None: no GPS)
    healthy: bool  # the vehicle below answers (the simulator is there)
    bad_frames: int = 0
    mission_seq: int = 0
    mission_total: int = 0
    mission_state: int = mav.MISSION_STATE_NO_MISSION
    mission_active: bool = False
    unix_time_s: float = 0.0  # the host's wall clock (0: not known)

    @property
    def time_us(self) -> int:
        """The vehicle time in whole microseconds, the nearest (``time_usec``)."""
        return round(self.snap.time_s * 1e6)

    @property
    def time_ms(self) -> int:
        """``time_usec``'s whole milliseconds, as PX4 derives ``time_boot_ms`` from its
        microsecond clock, wrapping at 2^32 (``time_boot_ms``)."""
        return (self.time_us // 1000) & 0xFFFFFFFF

    @property
    def height_above_home_m(self) -> float:
        return self.home_ned_m[2] - self.snap.pos_ned_m[2]

    def geodetic(self, pos_ned_m: tuple[float, float, float]) -> tuple[float, float, float] | None:
        """(lat deg, lon deg, altitude AMSL m) of a NED position, or None without GPS."""
        if self.origin is None:
            return None
        return self.origin.to_geodetic(*pos_ned_m)


def _deg_e7(value_deg: float) -> int:
    return round(value_deg * 1e7)


def _cdeg_heading(yaw_rad: float) -> int:
    return round(math.degrees(yaw_rad) % 360.0 * 100) % 36000


def quaternion(roll: float, pitch: float, yaw: float) -> list[float]:
    """(w, x, y, z) of ZYX Euler angles (body FRD in NED), as ATTITUDE_QUATERNION orders it."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return [cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy]


def heartbeat(c: MavCodec, v: VehicleView) -> MavMessage:
    base = (mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mav.MAV_MODE_FLAG_STABILIZE_ENABLED
            | mav.MAV_MODE_FLAG_GUIDED_ENABLED)
    if v.armed:
        base |= mav.MAV_MODE_FLAG_SAFETY_ARMED
    if v.mode.value[0] == 4:
        base |= mav.MAV_MODE_FLAG_AUTO_ENABLED
    return c.mav.heartbeat_encode(mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_PX4, base,
                                  v.mode.custom_mode, system_status(v.state), 3)


def sys_status(c: MavCodec, v: VehicleView) -> MavMessage:
    health = SENSORS
    if v.snap.gps is None or not v.snap.gps.fix or v.origin is None:
        health &= ~mav.MAV_SYS_STATUS_SENSOR_GPS
    if not v.healthy:
        health = 0
    mv = min(UINT16_MAX - 1, max(0, round(v.snap.battery_v * 1e3)))
    return c.mav.sys_status_encode(SENSORS, SENSORS, health, 0, mv, -1, -1, 0,
                                   min(v.bad_frames, UINT16_MAX), 0, 0, 0, 0)


def battery_status(c: MavCodec, v: VehicleView) -> MavMessage:
    mv = min(UINT16_MAX - 1, max(0, round(v.snap.battery_v * 1e3)))
    cells = [mv] + [UINT16_MAX] * 9
    return c.mav.battery_status_encode(0, mav.MAV_BATTERY_FUNCTION_ALL, mav.MAV_BATTERY_TYPE_LIPO,
                                       INT16_MAX, cells, -1, -1, -1, -1)


def attitude(c: MavCodec, v: VehicleView) -> MavMessage:
    r, p, y = v.snap.rpy_rad
    wr, wp, wy = v.snap.rates_frd_rad_s
    return c.mav.attitude_encode(v.time_ms, r, p, y, wr, wp, wy)


def attitude_quaternion(c: MavCodec, v: VehicleView) -> MavMessage:
    q = quaternion(*v.snap.rpy_rad)
    wr, wp, wy = v.snap.rates_frd_rad_s
    return c.mav.attitude_quaternion_encode(v.time_ms, *q, wr, wp, wy, [0.0] * 4)


def local_position_ned(c: MavCodec, v: VehicleView) -> MavMessage:
    n, e, d = v.snap.pos_ned_m
    vn, ve, vd = v.snap.vel_ned_m_s
    return c.mav.local_position_ned_encode(v.time_ms, n, e, d, vn, ve, vd)


def global_position_int(c: MavCodec, v: VehicleView) -> MavMessage | None:
    geo = v.geodetic(v.snap.pos_ned_m)
    if geo is None:
        return None
    lat, lon, alt = geo
    vn, ve, vd = (round(x * 100) for x in v.snap.vel_ned_m_s)
    clamp = lambda x: max(-32768, min(32767, x))  # noqa: E731
    return c.mav.global_position_int_encode(
        v.time_ms, _deg_e7(lat), _deg_e7(lon), round(alt * 1e3),
        round(v.height_above_home_m * 1e3), clamp(vn), clamp(ve), clamp(vd),
        _cdeg_heading(v.snap.rpy_rad[2]))


def gps_raw_int(c: MavCodec, v: VehicleView) -> MavMessage:
    g = v.snap.gps
    usec = v.time_us
    if g is None or not g.fix:
        return c.mav.gps_raw_int_encode(usec, mav.GPS_FIX_TYPE_NO_FIX, 0, 0, 0, UINT16_MAX,
                                        UINT16_MAX, UINT16_MAX, UINT16_MAX,
                                        0 if g is None else g.satellites)
    vn, ve, _ = g.vel_ned_m_s
    speed = math.hypot(vn, ve)
    cog = _cdeg_heading(math.atan2(ve, vn)) if speed > 0.1 else UINT16_MAX
    return c.mav.gps_raw_int_encode(usec, mav.GPS_FIX_TYPE_3D_FIX, _deg_e7(g.latitude_deg),
                                    _deg_e7(g.longitude_deg), round(g.altitude_m * 1e3),
                                    UINT16_MAX, UINT16_MAX, min(UINT16_MAX - 1, round(speed * 100)),
                                    cog, min(255, g.satellites))


def altitude(c: MavCodec, v: VehicleView) -> MavMessage:
    geo = v.geodetic(v.snap.pos_ned_m)
    amsl = geo[2] if geo is not None else math.nan
    local = -v.snap.pos_ned_m[2]
    rel = v.height_above_home_m
    return c.mav.altitude_encode(v.time_us, v.snap.baro_altitude_m, amsl, local,
                                 rel, math.nan, rel)


def vfr_hud(c: MavCodec, v: VehicleView) -> MavMessage:
    vn, ve, vd = v.snap.vel_ned_m_s
    speed = math.hypot(vn, ve)
    geo = v.geodetic(v.snap.pos_ned_m)
    alt = geo[2] if geo is not None else -v.snap.pos_ned_m[2]
    heading = round(math.degrees(v.snap.rpy_rad[2]) % 360.0) % 360
    throttle = round(100 * max(0.0, min(1.0, v.snap.thrust_fraction)))
    return c.mav.vfr_hud_encode(speed, speed, heading, throttle, alt, -vd)


def extended_sys_state(c: MavCodec, v: VehicleView) -> MavMessage:
    return c.mav.extended_sys_state_encode(mav.MAV_VTOL_STATE_UNDEFINED, landed_state(v.state))


def home_position(c: MavCodec, v: VehicleView) -> MavMessage | None:
    geo = v.geodetic(v.home_ned_m)
    if geo is None:
        return None
    n, e, d = v.home_ned_m
    return c.mav.home_position_encode(_deg_e7(geo[0]), _deg_e7(geo[1]), round(geo[2] * 1e3),
                                      n, e, d, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
                                      v.time_us)


def gps_global_origin(c: MavCodec, v: VehicleView) -> MavMessage | None:
    """The geodetic position of LOCAL_POSITION_NED's origin (the one GLOBAL_POSITION_INT is
    computed from); ``time_usec`` the vehicle time of the estimate it belongs to."""
    if v.origin is None:
        return None
    o = v.origin
    return c.mav.gps_global_origin_encode(_deg_e7(o.latitude_deg), _deg_e7(o.longitude_deg),
                                          round(o.altitude_m * 1e3), v.time_us)


def system_time(c: MavCodec, v: VehicleView) -> MavMessage:
    """The host's wall clock and the vehicle's boot time (the other messages' ``time_boot_ms``)."""
    unix_us = round(v.unix_time_s * 1e6) if math.isfinite(v.unix_time_s) else 0
    return c.mav.system_time_encode(max(0, unix_us), v.time_ms)


def mission_current(c: MavCodec, v: VehicleView) -> MavMessage:
    return c.mav.mission_current_encode(v.mission_seq, v.mission_total, v.mission_state,
                                        1 if v.mission_active else 2)


def highres_imu(c: MavCodec, v: VehicleView) -> MavMessage:
    s = v.snap
    ax, ay, az = s.specific_force_frd_m_s2
    gx, gy, gz = s.rates_frd_rad_s
    mx, my, mz = (b / UT_PER_GAUSS for b in s.mag_field_frd_ut)
    return c.mav.highres_imu_encode(v.time_us, ax, ay, az, gx, gy, gz, mx, my, mz,
                                    s.baro_pressure_pa / PA_PER_HPA, 0.0, s.baro_altitude_m,
                                    25.0, 0x1FFF)


def scaled_pressure(c: MavCodec, v: VehicleView) -> MavMessage:
    return c.mav.scaled_pressure_encode(v.time_ms, v.snap.baro_pressure_pa / PA_PER_HPA, 0.0,
                                        2500)


def autopilot_version(c: MavCodec) -> MavMessage:
    major, minor, patch = (int(x) for x in [*__version__.split("."), "0", "0"][:3])
    version = (major << 24) | (minor << 16) | (patch << 8) | 255  # ..._TYPE_OFFICIAL
    return c.mav.autopilot_version_encode(CAPABILITIES, version, 0, 0, 0, [0] * 8, [0] * 8,
                                          [0] * 8, 0, 0, 0)


BUILDERS = {
    mav.MAVLINK_MSG_ID_HEARTBEAT: heartbeat,
    mav.MAVLINK_MSG_ID_SYS_STATUS: sys_status,
    mav.MAVLINK_MSG_ID_BATTERY_STATUS: battery_status,
    mav.MAVLINK_MSG_ID_ATTITUDE: attitude,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: attitude_quaternion,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: local_position_ned,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: global_position_int,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: gps_raw_int,
    mav.MAVLINK_MSG_ID_ALTITUDE: altitude,
    mav.MAVLINK_MSG_ID_VFR_HUD: vfr_hud,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: extended_sys_state,
    mav.MAVLINK_MSG_ID_HOME_POSITION: home_position,
    mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: gps_global_origin,
    mav.MAVLINK_MSG_ID_SYSTEM_TIME: system_time,
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: mission_current,
    mav.MAVLINK_MSG_ID_HIGHRES_IMU: highres_imu,
    mav.MAVLINK_MSG_ID_SCALED_PRESSURE: scaled_pressure,
}
"""Every streamed message's builder (``None`` from a builder: not available now, e.g. no GPS)."""
