"""Telemetry of the emulated boards: the AscTec structures and NAV_STATUS from a sensor snapshot.

How this works: ``Telemetry`` builds every structure a poll or the stream asks for from one
``Snapshot`` of the airframe (the onboard estimate and the sensors, in SI) and a ``BoardStatus``,
the few facts of the boards' own state a structure reports (flight state, last sticks, motion
and waypoint progress). It holds only ``GeoAnchor``, the fused position estimate that
GPS_DATA_ADVANCED reports; everything else is computed fresh, so a poll changes nothing but
that anchor. SI becomes wire units through ``skeye.wire.packet_units`` and the scales of
``packet_defs.LAYOUTS``.

Units: IMU_RAWDATA, which AscTec leaves in uncalibrated ADC counts, carries the calibrated
scalings of IMU_CALCDATA (gyro 64.8 counts per deg/s, acc 10000 = 1 g) and the field in
0.01 uT, pressure
in Pa; the simulator has no temperature model, so both temperature fields report 25.00 degC
(2500).

Heights: IMU_CALCDATA ``height`` (fused) and ``height_reference`` ("measured by the pressure
sensor") are both above the world origin: the pressure height is zeroed on the fused height
while the motors are off and frozen when they start, as ArduPilot and PX4 zero the barometer
on the ground before arming (``Telemetry.observe``), so it then moves as the barometer says.
LL_STATUS ``flying`` is 1 while the motors turn (idling included: AscTec drivers read it as
"motors on"), ``up_time`` the seconds they have turned ("Time motors are turning", the
header's comment). CONTROLLER_OUTPUT carries the sticks scaled as the header's 0..200 =
-100..+100 % (thrust 0..200 = 0..100 %).
No value stops the telemetry: a structure that a snapshot's values cannot fill (a NaN, a
figure beyond its field: a tumbling or runaway vehicle) is left out of that answer, counted in
``Telemetry.unfit`` by structure, and logged once per structure; the others still go out.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

from skeye.errors import SkeyeError
from skeye.geo import GeoOrigin
from skeye.pilot.airframe import GpsFix, Snapshot
from skeye.wire.packet_defs import GPS_FIX_VALID, NavState
from skeye.wire.packet_units import (
    STICK_MAX,
    GpsBestSi,
    GpsSi,
    ImuCalcSi,
    NavStatusSi,
    TruthSi,
    gps_data_advanced_from_si,
    gps_data_from_si,
    imu_calcdata_from_si,
    nav_status_from_si,
    truth_from_si,
    wire_value,
)
from skeye.wire.packets import (
    ControllerOutput,
    CtrlBits,
    CtrlInput,
    CurrentWay,
    ImuRawData,
    LlStatus,
    Message,
    NavigationStatus,
    PadAction,
    PollMask,
    RcData,
    Waypoint,
)
from skeye.wire.scales import clamp

log = logging.getLogger(__name__)

TEMPERATURE_CENTI_DEGC = 2500
CPU_LOAD_CYCLES_S = 1000
INT16 = (-(2**15), 2**15 - 1)
WAYPOINT_NEAR_M = 20.0
SIGMA_FLOOR_M = 0.001  # NAV_STATUS's sigma resolution; 0 on the wire means "not known"
SIGMA_TOP_M = 65.535  # its uint16 mm field's top (saturated)
# The GPS receiver's stated horizontal accuracy: 2.5 m CEP (u-blox LEA-6 data sheet, the
# simulated receiver's figure too: docs/physics.md), as GPS_DATA reports it. For a circular
# normal error CEP = 1.1774 sigma per axis, so its DRMS (sqrt(var_n + var_e)) is
# sqrt(2) * 2.5 / 1.1774 = 3.0 m.
GPS_CEP_M = 2.5
GPS_DRMS_M = math.sqrt(2.0) * GPS_CEP_M / 1.1774

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class BoardStatus:
    """What the structures report of the boards' own state, at one poll."""

    state: NavState
    pad_mode: PadAction
    sticks: CtrlInput  # the last CTRL_INPUT
    motors_on: bool  # started by the stick gesture or a take-off
    motion_pending: bool  # an autonomous motion is under way
    checksum_errors: int
    home_ned_m: Vec3  # where the vehicle rested before its last take-off
    waypoint: Waypoint | None  # the uploaded one
    waypoint_target: Vec3 | None  # NED, the current waypoint (None: none is current)
    waypoint_status: int  # NavigationStatus bits the boards latched (0x01, 0x02, 0x08)
    motor_time_s: float = 0.0  # sim time the motors have turned (LL_STATUS up_time)


class GeoAnchor:
    """The vehicle's position estimate in latitude/longitude: its INS position (NED, smooth,
    drifting slowly) anchored to the GPS by the mean offset between every fix and
    the INS position at that time. A single fix wanders metres (multipath, 300 s correlation);
    the mean of many is steadier, and the estimate moves only as the INS says the vehicle moved.
    This is what GPS_DATA_ADVANCED reports as its "best estimate". The altitude above mean sea
    level of the NED origin is anchored the same way (the mean of each fix's altitude plus the
    INS down coordinate), so one anchor, reset with the telemetry when the vehicle is reset or
    respawned, places the whole local frame on the globe."""

    def __init__(self) -> None:
        self.origin: GeoOrigin | None = None  # the first fix: where offsets are measured from
        self.fixes = 0
        self._sum_n = 0.0
        self._sum_e = 0.0
        self._sum_alt = 0.0
        self._last: tuple[float, float, float] | None = None

    def add(self, fix: GpsFix | None, pos_ned_m: tuple[float, float, float]) -> None:
        """Take the snapshot's fix if it is a new one."""
        if fix is None or not fix.fix:
            return
        key = (fix.latitude_deg, fix.longitude_deg, fix.altitude_m)
        if key == self._last:
            return
        self._last = key
        if self.origin is None:
            self.origin = GeoOrigin(fix.latitude_deg, fix.longitude_deg, 0.0)
        n, e, _ = self.origin.to_ned(fix.latitude_deg, fix.longitude_deg, 0.0)
        self._sum_n += n - pos_ned_m[0]
        self._sum_e += e - pos_ned_m[1]
        self._sum_alt += fix.altitude_m + pos_ned_m[2]
        self.fixes += 1

    def estimate(self, pos_ned_m: tuple[float, float, float]) -> tuple[float, float] | None:
        """(latitude, longitude) of the INS position, or None before the first fix."""
        if self.origin is None or self.fixes == 0:
            return None
        n = pos_ned_m[0] + self._sum_n / self.fixes
        e = pos_ned_m[1] + self._sum_e / self.fixes
        lat, lon, _ = self.origin.to_geodetic(n, e, 0.0)
        return lat, lon

    @property
    def origin_amsl_m(self) -> float | None:
        """Altitude above mean sea level of the NED origin (None before the first fix)."""
        return self._sum_alt / self.fixes if self.fixes else None


# RC_DATA channel[4] and [5] (sdk.h): the serial interface is what commands the simulated
# vehicle, so it is always enabled; the mode switch follows the board's flight mode.
RC_SERIAL_ENABLED = 4095
RC_MODE_MANUAL, RC_MODE_HEIGHT, RC_MODE_GPS = 0, 2048, 4095


def _percent_200(stick: int) -> int:
    """A stick (-2047..2047) as CONTROLLER_OUTPUT's "0..200 = -100..+100 %"."""
    return clamp(round(100 + stick * 100 / STICK_MAX), 0, 200)


def _sigma_on_wire(sigma_m: float) -> float:
    """A stated 1-sigma as NAV_STATUS carries it: at least 1 mm (0 means "not known"), a
    diverged filter's NaN as "not known", an infinite one at the field's top."""
    if math.isnan(sigma_m):
        return 0.0
    return min(SIGMA_TOP_M, max(SIGMA_FLOOR_M, sigma_m))


class Telemetry:
    """Builds the vehicle's structures; ``poll`` answers a poll mask, ``nav_status`` NAV_STATUS."""

    def __init__(self, first: Snapshot) -> None:
        self.geo = GeoAnchor()
        self.geo.add(first.gps, first.pos_ned_m)
        self._baro_offset_m = first.baro_altitude_m - first.altitude_m
        self.unfit: Counter[str] = Counter()  # structures left out: values they cannot carry

    def observe(self, snap: Snapshot, motors_running: bool) -> None:
        """Every tick: while the motors are off the pressure height is zeroed on the fused
        height (``height_reference`` reads ``height`` on the ground); running, it is kept."""
        if not motors_running:
            self._baro_offset_m = snap.baro_altitude_m - snap.altitude_m

    def built(self, name: str, build: Callable[[], Message]) -> Message | None:
        """``build()``, or None (counted, logged once per structure) when the snapshot's values
        do not fit the structure."""
        try:
            return build()
        except (SkeyeError, ArithmeticError, ValueError) as exc:
            self.unfit[name] += 1
            if self.unfit[name] == 1:
                log.warning("telemetry: %s left out, a value does not fit it (said once): %s",
                            name, exc)
            return None

    def poll(self, mask: int, snap: Snapshot, status: BoardStatus) -> list[Message]:
        """One frame per requested structure, in mask-bit order."""
        builders = {
            PollMask.LL_STATUS: self._ll_status,
            PollMask.IMU_RAWDATA: self._imu_raw,
            PollMask.IMU_CALCDATA: self._imu_calc,
            PollMask.RC_DATA: self._rc_data,
            PollMask.CONTROLLER_OUTPUT: self._controller_output,
            PollMask.GPS_DATA: self._gps,
            PollMask.CURRENT_WAY: self._current_way,
            PollMask.GPS_DATA_ADVANCED: self._gps_advanced,
        }
        out = []
        for bit, build in builders.items():
            if mask & bit:
                msg = self.built(bit.name or "", partial(build, snap, status))
                if msg is not None:
                    out.append(msg)
        return out

    def _ll_status(self, snap: Snapshot, status: BoardStatus) -> LlStatus:
        battery_mv = wire_value(LlStatus, "battery_voltage_1", snap.battery_v)
        flight_mode = 0x01  # attitude control always on
        ctrl = status.sticks.ctrl
        if status.state is not NavState.LANDED and (
            ctrl & CtrlBits.HEIGHT_CONTROL or not ctrl & CtrlBits.THRUST  # thrust bit off: held
        ):
            flight_mode |= 0x02
        if status.motion_pending or status.state in (NavState.HOLDING, NavState.FAILSAFE):
            flight_mode |= 0x06  # height and position hold
        return LlStatus(
            battery_voltage_1=battery_mv,
            battery_voltage_2=battery_mv,
            status=0,
            cpu_load=CPU_LOAD_CYCLES_S,
            compass_enabled=1,
            chksum_error=min(255, status.checksum_errors),
            flying=int(snap.armed or status.motors_on),  # motors turning, idle included
            motors_on=int(snap.armed or status.motors_on),
            flightMode=flight_mode,
            up_time=clamp(int(status.motor_time_s), *INT16),  # "Time motors are turning"
        )

    def imu_si(self, snap: Snapshot) -> ImuCalcSi:
        """IMU_CALCDATA's quantities in SI from the snapshot."""
        roll, pitch, yaw = snap.rpy_rad
        p, q, r = snap.rates_frd_rad_s
        f = snap.specific_force_frd_m_s2
        # Earth-frame acceleration: rotate specific force to NED and add gravity back (z down).
        cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
        cy, sy = math.cos(yaw), math.sin(yaw)
        rot = (
            (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
            (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
            (-sp, cp * sr, cp * cr),
        )
        acc_ned = tuple(sum(rot[i][j] * f[j] for j in range(3)) for i in range(3))
        acc_earth = (acc_ned[0], acc_ned[1], acc_ned[2] + 9.80665)
        fx, fy, fz = f
        acc_roll = math.atan2(-fy, -fz) if (fy or fz) else 0.0
        acc_pitch = math.atan2(fx, math.hypot(fy, fz)) if (fx or fy or fz) else 0.0
        vn, ve, vd = snap.vel_ned_m_s
        return ImuCalcSi(
            roll_rad=roll,
            pitch_rad=pitch,
            yaw_rad=yaw,
            roll_rate_rad_s=p,
            pitch_rate_rad_s=q,
            yaw_rate_rad_s=r,
            acc_body_frd_m_s2=f,
            acc_earth_ned_m_s2=(acc_earth[0], acc_earth[1], acc_earth[2]),
            acc_angle_roll_rad=acc_roll,
            acc_angle_pitch_rad=acc_pitch,
            acc_absolute_m_s2=math.sqrt(fx * fx + fy * fy + fz * fz),
            mag_field_raw=tuple(round(b * 100) for b in snap.mag_field_frd_ut),  # type: ignore[arg-type]
            mag_heading_rad=snap.mag_heading_rad,
            vel_ned_m_s=(vn, ve, vd),
            height_m=snap.altitude_m,
            climb_rate_m_s=-vd,
            baro_climb_rate_m_s=snap.baro_climb_m_s,
            baro_height_m=snap.baro_altitude_m - self._baro_offset_m,
        )

    def _imu_calc(self, snap: Snapshot, status: BoardStatus) -> Message:
        return imu_calcdata_from_si(self.imu_si(snap))

    def _imu_raw(self, snap: Snapshot, status: BoardStatus) -> ImuRawData:
        p, q, r = snap.rates_frd_rad_s
        ax, ay, az = snap.specific_force_frd_m_s2
        mx, my, mz = (clamp(round(b * 100), *INT16) for b in snap.mag_field_frd_ut)
        return ImuRawData(
            pressure=round(snap.baro_pressure_pa),
            gyro_x=wire_value(ImuRawData, "gyro_x", p),
            gyro_y=wire_value(ImuRawData, "gyro_y", q),
            gyro_z=wire_value(ImuRawData, "gyro_z", r),
            mag_x=mx,
            mag_y=my,
            mag_z=mz,
            acc_x=wire_value(ImuRawData, "acc_x", ax),
            acc_y=wire_value(ImuRawData, "acc_y", ay),
            acc_z=wire_value(ImuRawData, "acc_z", az),
            temp_gyro=TEMPERATURE_CENTI_DEGC,
            temp_ADC=TEMPERATURE_CENTI_DEGC,
        )

    def _rc_data(self, snap: Snapshot, status: BoardStatus) -> RcData:
        # No RC transmitter in the simulation: the channels show the serial stick input, in
        # AscTec's order (sdk.h, RO_RC_DATA / RO_ALL_DATA: channel[0] pitch, [1] roll,
        # [2] thrust, [3] yaw, [4] serial interface enable (> 2048 enabled), [5] mode switch
        # (0 manual, 2048 height control, 4095 GPS + height control); range 0..4095).
        s = status.sticks
        mode = self._ll_status(snap, status).flightMode
        switch = RC_MODE_GPS if mode & 0x04 else RC_MODE_HEIGHT if mode & 0x02 else RC_MODE_MANUAL
        channels = (s.pitch + 2048, s.roll + 2048, s.thrust, s.yaw + 2048,
                    RC_SERIAL_ENABLED, switch, 0, 0)
        return RcData(channels_in=channels, channels_out=channels, lock=0)

    def _controller_output(self, snap: Snapshot, status: BoardStatus) -> ControllerOutput:
        s = status.sticks
        return ControllerOutput(
            nick=_percent_200(s.pitch),
            roll=_percent_200(s.roll),
            yaw=_percent_200(s.yaw),
            thrust=wire_value(ControllerOutput, "thrust", snap.thrust_fraction),
        )

    def _gps_si(self, snap: Snapshot) -> GpsSi:
        g = snap.gps
        if g is None or not g.fix:
            return GpsSi(
                0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0 if g is None else g.satellites, 0
            )
        vn, ve, _ = g.vel_ned_m_s
        heading = math.atan2(ve, vn) if math.hypot(vn, ve) > 0.1 else snap.rpy_rad[2]
        return GpsSi(
            latitude_deg=g.latitude_deg,
            longitude_deg=g.longitude_deg,
            height_m=g.altitude_m,
            vel_east_m_s=ve,
            vel_north_m_s=vn,
            heading_rad=heading,
            horizontal_accuracy_m=GPS_CEP_M,
            vertical_accuracy_m=5.0,
            speed_accuracy_m_s=0.2,
            num_sv=g.satellites,
            status=GPS_FIX_VALID,
        )

    def _gps(self, snap: Snapshot, status: BoardStatus) -> Message:
        return gps_data_from_si(self._gps_si(snap))

    def _gps_advanced(self, snap: Snapshot, status: BoardStatus) -> Message:
        gps = self._gps_si(snap)
        self.geo.add(snap.gps, snap.pos_ned_m)
        here = self.geo.estimate(snap.pos_ned_m)
        lat, lon = here if here is not None else (gps.latitude_deg, gps.longitude_deg)
        vn, ve, _ = snap.vel_ned_m_s  # the INS velocity, as the position
        best = GpsBestSi(lat, lon, ve, vn)
        return gps_data_advanced_from_si(gps, best)

    def _current_way(self, snap: Snapshot, status: BoardStatus) -> CurrentWay:
        """CURRENT_WAY: the boards' latched bits (``OnboardBoards._waypoint_progress``), with
        0x04 and ``distance_to_wp`` from the estimate to the current waypoint (0 and clear
        when none is current)."""
        nav_status = status.waypoint_status
        distance_m = 0.0
        target = status.waypoint_target
        if target is not None:
            n, e, d = snap.pos_ned_m
            distance_m = math.dist((n, e, d), target)
            if distance_m <= WAYPOINT_NEAR_M:
                nav_status |= int(NavigationStatus.WITHIN_20M)
        wp = status.waypoint
        return CurrentWay(
            dummy1=0,
            properties=0 if wp is None else wp.properties,
            nr_of_wp=0 if wp is None else 1,
            current_wp=0 if wp is None else 1,
            current_wp_memlocation=0,
            status=int(status.motion_pending),
            dummy2=0,
            navigation_status=nav_status,
            distance_to_wp=wire_value(CurrentWay, "distance_to_wp", distance_m),  # saturates
        )

    def nav_status(self, snap: Snapshot, status: BoardStatus) -> Message:
        """NAV_STATUS from the onboard estimate. North and east are from the world origin; down
        is from the ground at home (where the vehicle rested before its last take-off), so
        ``-down`` is the height above ground that TAKE_OFF and GOTO_GPS heights mean: 0 when
        landed there, 1.5 after "take off to 1.5 m"."""
        north, east, down = snap.pos_ned_m
        sigma_h = sigma_v = 0.0  # not known
        if snap.pos_sigma_ned_m is not None:
            sn, se, sd = snap.pos_sigma_ned_m
            var_h = sn * sn + se * se
            if snap.gps is not None and snap.gps.fix:
                # GPS-aided, the estimate is tied to the receiver, whose error the filter
                # takes for white noise though it wanders over minutes: its covariance alone
                # then claims centimetres where the truth is metres away (bench_estimator,
                # docs/physics.md). The receiver's own stated accuracy is added.
                var_h += GPS_DRMS_M * GPS_DRMS_M
            sigma_h = _sigma_on_wire(math.sqrt(var_h))
            sigma_v = _sigma_on_wire(sd)
        return nav_status_from_si(
            NavStatusSi(
                state=status.state,
                pad_mode=status.pad_mode,
                pos_ned_m=(north, east, down - status.home_ned_m[2]),
                yaw_rad=snap.rpy_rad[2],
                vel_ned_m_s=snap.vel_ned_m_s,
                battery_v=snap.battery_v,
                time_s=max(0.0, snap.time_s),
                sigma_h_m=sigma_h,
                sigma_v_m=sigma_v,
            )
        )

    def truth(self, snap: Snapshot, status: BoardStatus) -> Message:
        """TRUTH: a simulated vehicle's true position, in NAV_STATUS's frame (down from the
        ground at home); only for an airframe that knows its truth (never a real vehicle)."""
        if snap.truth_ned_m is None:
            raise SkeyeError("TRUTH: this vehicle's airframe knows no truth (a real vehicle)")
        north, east, down = snap.truth_ned_m
        return truth_from_si(
            TruthSi(
                pos_ned_m=(north, east, down - status.home_ned_m[2]),
                yaw_rad=snap.truth_yaw_rad if snap.truth_yaw_rad is not None else 0.0,
                time_s=max(0.0, snap.time_s),
            )
        )
