"""Vehicle telemetry as the page shows it: packet messages -> one JSON-ready dict, in SI.

How this works: ``telemetry_json(latest)`` takes the newest message of each descriptor (what
``skeye.link.Vehicle.latest`` holds) and converts each through ``skeye.wire.packet_units`` (the one
module where the wire's integer scalings become SI); the page never sees a wire unit. A
structure that has not arrived is ``None`` in the result, never a made-up zero. Heights are
positive up; positions and velocities world NED (north, east, down) as NAV_STATUS carries them;
angles in degrees for display, named ``_deg``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from skeye.wire.packet_units import (
    dm_to_m,
    gps_data_advanced_to_si,
    gps_data_to_si,
    imu_calcdata_to_si,
    mv_to_v,
    nav_status_to_si,
    pad_report_to_si,
    truth_to_si,
)
from skeye.wire.packets import (
    GPS_FIX_VALID,
    PD,
    CurrentWay,
    GpsData,
    GpsDataAdvanced,
    Health,
    ImuCalcData,
    LlStatus,
    Message,
    NavigationStatus,
    NavStatus,
    PadReport,
    Truth,
    VehicleInfo,
)


def _deg(angle_rad: float) -> float:
    return round(math.degrees(angle_rad), 3)


def _r(value: float, digits: int = 4) -> float:
    return round(float(value), digits)


def _vec(v: tuple[float, float, float], digits: int = 4) -> list[float]:
    return [_r(x, digits) for x in v]


def nav_json(msg: NavStatus) -> dict[str, Any]:
    """NAV_STATUS: flight state, pad mode, NED position, height, yaw, velocity, battery, time."""
    si = nav_status_to_si(msg)
    north, east, down = si.pos_ned_m
    return {
        "state": si.state.name.lower(),
        "pad_mode": si.pad_mode.name.lower(),
        "north_m": _r(north),
        "east_m": _r(east),
        "height_m": _r(-down),
        "yaw_deg": _deg(si.yaw_rad),
        "vel_ned_m_s": _vec(si.vel_ned_m_s),
        "speed_m_s": _r(math.hypot(si.vel_ned_m_s[0], si.vel_ned_m_s[1])),
        "climb_m_s": _r(-si.vel_ned_m_s[2]),
        "battery_v": _r(si.battery_v, 3),
        "time_s": _r(si.time_s, 3),
        # the estimate's own 1-sigma (horizontal DRMS, vertical); None: the vehicle states none
        "sigma_h_m": _r(si.sigma_h_m) if msg.sigma_h else None,
        "sigma_v_m": _r(si.sigma_v_m) if msg.sigma_v else None,
    }


def truth_json(msg: Truth) -> dict[str, Any]:
    """TRUTH: a simulated vehicle's true position (NAV_STATUS's frame) and heading."""
    si = truth_to_si(msg)
    north, east, down = si.pos_ned_m
    return {
        "north_m": _r(north),
        "east_m": _r(east),
        "height_m": _r(-down),
        "yaw_deg": _deg(si.yaw_rad),
        "time_s": _r(si.time_s, 3),
    }


def vehicle_json(msg: VehicleInfo) -> dict[str, Any]:
    """VEHICLE: whether the vehicle is simulated, and the pilot's line naming it."""
    return {"simulated": bool(msg.simulated), "description": msg.description}


def imu_json(msg: ImuCalcData) -> dict[str, Any]:
    """IMU_CALCDATA: attitude, rates, accelerations, heights (fused and barometric)."""
    si = imu_calcdata_to_si(msg)
    return {
        "roll_deg": _deg(si.roll_rad),
        "pitch_deg": _deg(si.pitch_rad),
        "yaw_deg": _deg(si.yaw_rad),
        "rates_deg_s": [
            _deg(si.roll_rate_rad_s),
            _deg(si.pitch_rate_rad_s),
            _deg(si.yaw_rate_rad_s),
        ],
        "acc_body_frd_m_s2": _vec(si.acc_body_frd_m_s2, 3),
        "acc_absolute_m_s2": _r(si.acc_absolute_m_s2, 3),
        "mag_heading_deg": _deg(si.mag_heading_rad),
        "vel_ned_m_s": _vec(si.vel_ned_m_s),
        "height_m": _r(si.height_m),
        "climb_m_s": _r(si.climb_rate_m_s),
        "baro_height_m": _r(si.baro_height_m),
    }


def status_json(msg: LlStatus) -> dict[str, Any]:
    """LL_STATUS: battery, flying / motors flags, flight mode bits, up time, CPU cycles."""
    return {
        "battery_v": _r(mv_to_v(msg.battery_voltage_1), 3),
        "flying": bool(msg.flying),
        "motors_on": bool(msg.motors_on),
        "flight_mode": msg.flightMode,
        "height_control": bool(msg.flightMode & 0x02),
        "position_control": bool(msg.flightMode & 0x04),
        "compass_enabled": bool(msg.compass_enabled),
        "checksum_errors": msg.chksum_error,
        "cpu_load_hz": msg.cpu_load,
        "up_time_s": msg.up_time,
    }


def gps_json(msg: GpsData | GpsDataAdvanced) -> dict[str, Any]:
    """GPS_DATA: position, height, velocity, accuracy, satellites, fix; from GPS_DATA_ADVANCED
    also the vehicle's position estimate (``estimate_latitude_deg``/``_longitude_deg``, None
    from plain GPS_DATA)."""
    si = gps_data_to_si(msg)
    best = gps_data_advanced_to_si(msg)[1] if isinstance(msg, GpsDataAdvanced) else None
    return {
        "estimate_latitude_deg": None if best is None else round(best.latitude_deg, 7),
        "estimate_longitude_deg": None if best is None else round(best.longitude_deg, 7),
        "latitude_deg": round(si.latitude_deg, 7),
        "longitude_deg": round(si.longitude_deg, 7),
        "height_m": _r(si.height_m, 3),
        "vel_north_m_s": _r(si.vel_north_m_s),
        "vel_east_m_s": _r(si.vel_east_m_s),
        "heading_deg": _deg(si.heading_rad),
        "horizontal_accuracy_m": _r(si.horizontal_accuracy_m, 3),
        "vertical_accuracy_m": _r(si.vertical_accuracy_m, 3),
        "num_sv": si.num_sv,
        "fix": si.status == GPS_FIX_VALID,
    }


def pad_json(msg: PadReport) -> dict[str, Any]:
    """PAD: whether the pad is seen, which rings, centre offset (body FRD), height, quality."""
    si = pad_report_to_si(msg)
    return {
        "found": si.found,
        "rings": [i + 1 for i in range(8) if si.rings & (1 << i)],
        "dx_m": _r(si.dx_m),
        "dy_m": _r(si.dy_m),
        "height_m": _r(si.height_m),
        "quality": _r(si.quality, 3),
        "frame_time_s": _r(si.frame_time_s, 3),
        "vision_too_slow": si.vision_too_slow,
    }


def waypoint_json(msg: CurrentWay) -> dict[str, Any]:
    """CURRENT_WAY: navigation status bits (docs/protocols/packets.md: reached, reached and
    waited, within 20 m, aborted) and distance to the waypoint."""
    status = NavigationStatus(msg.navigation_status)
    return {
        "reached": bool(status & NavigationStatus.REACHED),
        "waited": bool(status & NavigationStatus.REACHED_AND_WAITED),  # its time to stay over
        "within_20m": bool(status & NavigationStatus.WITHIN_20M),
        "aborted": bool(status & NavigationStatus.ABORTED),
        "busy": bool(msg.status),
        "distance_m": _r(dm_to_m(msg.distance_to_wp), 1),
    }


def health_json(msg: Health) -> dict[str, Any]:
    """HEALTH: ``ok``, ``crashed`` or ``lost``, and why (the pilot's words)."""
    return {"status": msg.status.name.lower(), "reason": msg.reason}


def telemetry_json(latest: Mapping[PD, Message]) -> dict[str, Any]:
    """Every section the page shows; a section is None until its structure has arrived."""

    def get(pd: PD, cls: type[Message]) -> Any:
        msg = latest.get(pd)
        return msg if isinstance(msg, cls) else None

    nav = get(PD.NAV_STATUS, NavStatus)
    imu = get(PD.IMU_CALCDATA, ImuCalcData)
    status = get(PD.LL_STATUS, LlStatus)
    gps = get(PD.GPS_DATA_ADVANCED, GpsDataAdvanced) or get(PD.GPS_DATA, GpsData)
    pad = get(PD.PAD, PadReport)
    way = get(PD.CURRENT_WAY, CurrentWay)
    health = get(PD.HEALTH, Health)
    vehicle = get(PD.VEHICLE, VehicleInfo)
    truth = get(PD.TRUTH, Truth)
    simulated = vehicle is not None and bool(vehicle.simulated)
    return {
        "vehicle": None if vehicle is None else vehicle_json(vehicle),
        # the simulator's truth, only while the vehicle says it is simulated
        "truth": truth_json(truth) if truth is not None and simulated else None,
        "health": None if health is None else health_json(health),
        "nav": None if nav is None else nav_json(nav),
        "imu": None if imu is None else imu_json(imu),
        "status": None if status is None else status_json(status),
        "gps": None if gps is None else gps_json(gps),
        "pad": None if pad is None else pad_json(pad),
        "waypoint": None if way is None else waypoint_json(way),
    }


__all__ = [
    "gps_json",
    "health_json",
    "imu_json",
    "nav_json",
    "pad_json",
    "status_json",
    "telemetry_json",
    "truth_json",
    "vehicle_json",
    "waypoint_json",
]
