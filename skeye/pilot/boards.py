"""The three onboard boards, emulated: proxy, low-level board and onboard computer, sans I/O.

How this works: ``OnboardBoards.handle(event, now_s)`` takes one decoded command (or decode
error) from ``CommandStreamParser`` and returns the packets to send back; ``tick(now_s)``
advances everything that depends on time (flight-state progress from the airframe, the
stick gesture, the link-loss failsafe, streamed telemetry) and returns packets to push. The
time is an argument (wall-clock seconds, monotonic), so tests drive it; the boards own no
socket, thread or clock. The caller serialises calls (one lock in the server).

Answers: every skeye command gets a RESULT (0 ok, or the code of what is wrong); AscTec
commands get their ack, or a RESULT naming the command's PD when refused; a poll gets one frame
per requested structure. Decode errors that name a command get that command's RESULT; unknown
``>*>`` command letters get RESULT(0x00, bad value); frames too broken to name anything are only
counted. Refusals come from the flight-state table (``skeye.pilot.states``): code 4 "refused in
this state", code 5 "busy".

Link loss: while airborne, no packet for ``link_timeout_s`` -> FAILSAFE (hover), then after
``land_timeout_s`` more -> LANDING. A packet arriving in FAILSAFE stops the land countdown; the
vehicle keeps holding until ground control commands it.

Flight envelope (``skeye.pilot.envelope``, like PX4's geofence): every command with a target
is checked against a ceiling above home and a radius around it and refused with RESULT code 3
and a reason when outside; stick and open-ended velocity input is limited at the envelope's
edge, not refused (a full-thrust stick in height mode means the maximum climb rate, and holds
height at the ceiling); a vehicle beyond a limit that still moves outward is stopped (HOLDING).

Units: the wire's AscTec scalings are converted in ``skeye.wire.packet_units``; IMU_RAWDATA, which
AscTec leaves in uncalibrated ADC counts, carries the calibrated scalings of IMU_CALCDATA
(gyro 0.015 deg/s, acc 10000 = 1 g) and the field in 0.01 uT, pressure in Pa; the simulator
has no temperature model, so both temperature fields report 25.00 degC (2500).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from skeye.errors import LocalProtocolError, SkeyeError
from skeye.geo import GeoOrigin
from skeye.pilot.airframe import Airframe, GpsFix, Snapshot
from skeye.pilot.envelope import FlightEnvelope
from skeye.pilot.pad import PadController
from skeye.pilot.states import FlightEvent, FlightStateMachine, IllegalTransition
from skeye.wire.packet_defs import GPS_FIX_VALID, NavState
from skeye.wire.packet_units import (
    STICK_MAX,
    THRUST_MAX,
    GpsBestSi,
    GpsSi,
    ImuCalcSi,
    NavStatusSi,
    fraction_to_controller_thrust,
    gps_data_advanced_from_si,
    gps_data_from_si,
    imu_calcdata_from_si,
    m_s2_to_acc_counts,
    m_to_dm,
    nav_status_from_si,
    rad_s_to_angvel_counts,
    stick_to_angle_rad,
    stick_to_yaw_rate_rad_s,
    v_to_mv,
)
from skeye.wire.packets import (
    PD,
    Ack,
    Clock,
    ComeHome,
    CommandError,
    CommandEvent,
    ControllerOutput,
    CtrlBits,
    CtrlInput,
    CurrentWay,
    EndFlight,
    ErrorKind,
    FrameError,
    GotoGps,
    Hold,
    ImuRawData,
    Land,
    Launch,
    LlStatus,
    Message,
    MoveBy,
    MoveFrame,
    NavigationStatus,
    PadMode,
    Poll,
    PollMask,
    RcData,
    Result,
    ResultCode,
    SkeyeMask,
    Stream,
    TakeOff,
    Velocity,
    Waypoint,
    WaypointGoto,
    WaypointProps,
)

NO_COMMAND_PD = 0x00  # RESULT.command_pd when the answer names no command
GESTURE_HOLD_S = 1.0  # thrust 0 + full yaw held this long starts or stops the motors
GESTURE_YAW_MIN = 2000  # "full yaw": |yaw stick| at least this (of 2047)
GESTURE_THRUST_MAX = 50  # "thrust 0": thrust stick at most this (of 4095)
TEMPERATURE_CENTI_DEGC = 2500
CPU_LOAD_CYCLES_S = 1000
INT16 = (-(2**15), 2**15 - 1)
WAYPOINT_NEAR_M = 20.0


@dataclass(frozen=True)
class BoardSettings:
    """Tunables of the emulated vehicle."""

    link_timeout_s: float = 2.0
    land_timeout_s: float = 20.0
    launch_height_m: float = 1.0  # >*>wl climbs this high
    default_speed_m_s: float = 1.0  # a command's speed field of 0 means this
    # The robot file's [controller] max_speed_m_s (skeye pilot sets it): a faster MOVE_BY or
    # GOTO_GPS is refused; full stick in GPS mode; WAYPOINT max_speed 100 %.
    max_speed_m_s: float = 3.0
    max_climb_m_s: float = 1.5  # full thrust stick in height / GPS mode
    envelope: FlightEnvelope = field(default_factory=FlightEnvelope)  # ceiling, radius


class GeoAnchor:
    """The vehicle's position estimate in latitude/longitude: its INS position (NED, smooth,
    drifting millimetres a minute) anchored to the GPS by the mean offset between every fix and
    the INS position at that time. A single fix wanders metres (multipath, 30 s correlation);
    the mean of many is steadier, and the estimate moves only as the INS says the vehicle moved.
    This is what GPS_DATA_ADVANCED reports as its "best estimate"."""

    def __init__(self) -> None:
        self.origin: GeoOrigin | None = None  # the first fix: where offsets are measured from
        self.fixes = 0
        self._sum_n = 0.0
        self._sum_e = 0.0
        self._last: tuple[float, float] | None = None

    def add(self, fix: GpsFix | None, pos_ned_m: tuple[float, float, float]) -> None:
        """Take the snapshot's fix if it is a new one."""
        if fix is None or not fix.fix or (fix.latitude_deg, fix.longitude_deg) == self._last:
            return
        self._last = (fix.latitude_deg, fix.longitude_deg)
        if self.origin is None:
            self.origin = GeoOrigin(fix.latitude_deg, fix.longitude_deg, 0.0)
        n, e, _ = self.origin.to_ned(fix.latitude_deg, fix.longitude_deg, 0.0)
        self._sum_n += n - pos_ned_m[0]
        self._sum_e += e - pos_ned_m[1]
        self.fixes += 1

    def estimate(self, pos_ned_m: tuple[float, float, float]) -> tuple[float, float] | None:
        """(latitude, longitude) of the INS position, or None before the first fix."""
        if self.origin is None or self.fixes == 0:
            return None
        n = pos_ned_m[0] + self._sum_n / self.fixes
        e = pos_ned_m[1] + self._sum_e / self.fixes
        lat, lon, _ = self.origin.to_geodetic(n, e, 0.0)
        return lat, lon


def _sat16(v: int) -> int:
    return max(INT16[0], min(INT16[1], v))


def _frd_to_ned(vec_frd: tuple[float, float, float], yaw_rad: float) -> tuple[float, float]:
    """Horizontal part of a yaw-frame vector in NED (roll/pitch ignored: a level move)."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return (c * vec_frd[0] - s * vec_frd[1], s * vec_frd[0] + c * vec_frd[1])


class OnboardBoards:
    """The vehicle as ground control sees it, on top of an ``Airframe``."""

    def __init__(
        self,
        airframe: Airframe,
        settings: BoardSettings | None = None,
        pad: PadController | None = None,
        now_s: float = 0.0,
    ) -> None:
        self.airframe = airframe
        self.settings = settings or BoardSettings()
        self.pad = pad or PadController()
        self.flight = FlightStateMachine()
        self.errors: Counter[str] = Counter()  # by ErrorKind value, plus "refused"
        self.commands = 0
        snap = airframe.snapshot()
        self.home_ned_m = snap.pos_ned_m
        self._start_sim_s = snap.time_s
        self.motors_on = snap.armed
        self._last_packet_s = now_s
        self._failsafe_since_s: float | None = None
        self._velocity_until_s: float | None = None  # wall time a timed VELOCITY ends
        self._motion_pending = False  # an autonomous motion whose end is airframe.busy
        self._sticks = CtrlInput(0, 0, 0, 0, 0)
        self._gesture_since_s: float | None = None
        self._gesture_done = False
        self._waypoint: Waypoint | None = None
        self._waypoint_target: tuple[float, float, float] | None = None  # NED
        self._waypoint_status = 0
        self._stream: Stream | None = None
        self._stream_next_s = 0.0
        self.envelope_stops = 0  # times the envelope stopped a vehicle moving out
        self.envelope_reason = ""  # why, the last time
        self.clock_until_s = 0.0  # sim time granted by CLOCK (used with --ground-clock)
        self.geo = GeoAnchor()
        self.geo.add(snap.gps, snap.pos_ned_m)

    # -- state ---------------------------------------------------------------------------
    @property
    def state(self) -> NavState:
        return self.flight.state

    def _fire(self, event: FlightEvent) -> NavState:
        return self.flight.fire(event)

    # -- packets in ----------------------------------------------------------------------
    def handle(self, event: CommandEvent, now_s: float) -> list[Message]:
        """Answer one parsed command or decode error."""
        self._last_packet_s = now_s
        if self.state is NavState.FAILSAFE:
            self._failsafe_since_s = None  # ground control is back: stop the land countdown
        if isinstance(event, CommandError):
            self.errors[event.code.name.lower()] += 1
            return [event.result()]
        if isinstance(event, FrameError):
            self.errors[event.kind.value] += 1
            if event.kind is ErrorKind.UNKNOWN_PD:
                return [Result(NO_COMMAND_PD, ResultCode.BAD_VALUE, event.reason)]
            return []
        self.commands += 1
        if isinstance(event, Poll):
            return self.poll(event.mask)
        pd = event_pd(event)
        try:
            reply = self._dispatch(event, now_s)
        except IllegalTransition as exc:
            self.errors["refused"] += 1
            return [Result(pd, exc.code, str(exc))]
        except _Refused as exc:
            self.errors["refused"] += 1
            return [Result(pd, exc.code, exc.reason)]
        except LocalProtocolError as exc:  # beyond the vehicle's limits
            self.errors["refused"] += 1
            return [Result(pd, ResultCode.BAD_VALUE, str(exc)[: Result.MAX_REASON_BYTES // 4])]
        except SkeyeError as exc:  # the vehicle cannot do it now (no GPS fix, stale sensor)
            self.errors["refused"] += 1
            return [Result(pd, ResultCode.REFUSED, str(exc)[: Result.MAX_REASON_BYTES // 4])]
        return [reply]

    def _dispatch(self, msg: Message, now_s: float) -> Message:
        pd = event_pd(msg)
        ok = Result(pd, ResultCode.OK, "")
        if isinstance(msg, CtrlInput):
            self._ctrl_input(msg, now_s)
            return Ack(PD.CTRL_INPUT)
        if isinstance(msg, Waypoint):
            self._waypoint = msg
            return Ack(PD.WAYPOINT)
        if isinstance(msg, WaypointGoto):
            self._goto_waypoint()
            return Ack(PD.WAYPOINT_GOTO)
        if isinstance(msg, Launch):
            self._take_off(self.settings.launch_height_m)
            return Ack(PD.LAUNCH)
        if isinstance(msg, EndFlight):
            self._land()
            return Ack(PD.END_FLIGHT)
        if isinstance(msg, ComeHome):
            self._come_home()
            return Ack(PD.COME_HOME)
        if isinstance(msg, TakeOff):
            self._take_off(msg.height / 1000.0)
        elif isinstance(msg, Land):
            self._land()
        elif isinstance(msg, Hold):
            self.flight.check(FlightEvent.HOLD)
            self.airframe.hover()
            self._fire(FlightEvent.HOLD)
            self._end_motion()
        elif isinstance(msg, Velocity):
            self._velocity(msg, now_s)
        elif isinstance(msg, MoveBy):
            self._move_by(msg)
        elif isinstance(msg, GotoGps):
            self._goto_gps(msg)
        elif isinstance(msg, PadMode):
            self.pad.set_mode(msg)
        elif isinstance(msg, Stream):
            self._stream = msg if msg.period > 0 else None
            self._stream_next_s = now_s
        elif isinstance(msg, Clock):
            self.clock_until_s = msg.until / 1000.0
        else:
            raise _Refused(ResultCode.BAD_VALUE, f"{type(msg).__name__} is not a command")
        return ok

    # -- commands ------------------------------------------------------------------------
    def _end_motion(self) -> None:
        self._motion_pending = False
        self._velocity_until_s = None
        self._waypoint_target = None

    def _check_envelope(self, home_ned_m: tuple[float, float, float],
                        target_ned_m: tuple[float, float, float]) -> None:
        reason = self.settings.envelope.check_target(home_ned_m, target_ned_m)
        if reason is not None:
            raise _Refused(ResultCode.BAD_VALUE, reason)

    def _gps_target_ned(self, snap: Snapshot, lat_deg: float, lon_deg: float,
                        altitude_m: float) -> tuple[float, float, float] | None:
        """A GPS target in NED through the latest fix (None without a fix: the airframe
        refuses the move itself then)."""
        g = snap.gps
        if g is None or not g.fix or not -90.0 < g.latitude_deg < 90.0:
            return None
        dn, de, _ = GeoOrigin(g.latitude_deg, g.longitude_deg).to_ned(lat_deg, lon_deg, 0.0)
        return (snap.pos_ned_m[0] + dn, snap.pos_ned_m[1] + de, -altitude_m)

    def _take_off(self, height_m: float) -> None:
        self.flight.check(FlightEvent.TAKE_OFF)
        snap = self.airframe.snapshot()
        n, e, d = snap.pos_ned_m
        self._check_envelope(snap.pos_ned_m, (n, e, d - height_m))  # home is here
        self.airframe.take_off(snap.altitude_m + height_m)
        self.home_ned_m = snap.pos_ned_m
        self._fire(FlightEvent.TAKE_OFF)
        self._end_motion()
        self.motors_on = True

    def land(self) -> None:
        """Start a landing where the vehicle is (LAND, >*>we, a pad landing's touchdown)."""
        self._land()

    def _land(self) -> None:
        self.flight.check(FlightEvent.LAND)
        self.airframe.land()
        self._fire(FlightEvent.LAND)
        self._end_motion()

    def _start_motion(self, start: Callable[[], None]) -> None:
        """Check the state allows a move, start it on the airframe, then change state."""
        self.flight.check(FlightEvent.MOVE)
        start()
        self._fire(FlightEvent.MOVE)
        self._end_motion()
        self._motion_pending = True

    def _speed(self, speed_mm_s: int) -> float:
        """A command's speed (0: the default); over the vehicle's limit it is refused, never
        silently capped."""
        speed = speed_mm_s / 1000.0 if speed_mm_s > 0 else self.settings.default_speed_m_s
        limit = self.settings.max_speed_m_s
        if speed > limit + 1e-9:
            raise _Refused(
                ResultCode.BAD_VALUE,
                f"speed {speed:g} m/s is over this vehicle's limit of {limit:g} m/s",
            )
        return speed

    def _velocity(self, msg: Velocity, now_s: float) -> None:
        self.flight.check(FlightEvent.MOVE)
        duration_s = msg.duration / 1000.0 if msg.duration else None
        if duration_s is not None:  # where it ends; open-ended ones are stopped at the edge
            snap = self.airframe.snapshot()
            vn, ve = _frd_to_ned((msg.vx / 1000.0, msg.vy / 1000.0, 0.0), snap.rpy_rad[2])
            n, e, d = snap.pos_ned_m
            end = (n + vn * duration_s, e + ve * duration_s, d + msg.vz / 1000.0 * duration_s)
            self._check_envelope(self.home_ned_m, end)
        self.airframe.set_velocity(
            msg.vx / 1000.0, msg.vy / 1000.0, -msg.vz / 1000.0, msg.yaw_rate / 1000.0, duration_s
        )
        self._fire(FlightEvent.MOVE)
        self._end_motion()
        self._velocity_until_s = None if duration_s is None else now_s + duration_s

    def _move_by(self, msg: MoveBy) -> None:
        self.flight.check(FlightEvent.MOVE)
        snap = self.airframe.snapshot()
        delta = (msg.dx / 1000.0, msg.dy / 1000.0, msg.dz / 1000.0)
        if msg.frame is MoveFrame.BODY_FRD:
            dn, de = _frd_to_ned(delta, snap.rpy_rad[2])
        else:
            dn, de = delta[0], delta[1]
        dyaw_rad = math.radians(msg.dyaw / 1000.0)
        if delta == (0.0, 0.0, 0.0):
            if dyaw_rad == 0.0:
                raise _Refused(ResultCode.BAD_VALUE, "MOVE_BY of zero distance and zero yaw")
            self._start_motion(lambda: self.airframe.turn_by(dyaw_rad))
            return
        n, e, d = snap.pos_ned_m
        speed = self._speed(msg.speed)
        self._check_envelope(self.home_ned_m, (n + dn, e + de, d + delta[2]))
        self._start_motion(lambda: self.airframe.fly_to(n + dn, e + de, -(d + delta[2]), speed))

    def _goto_gps(self, msg: GotoGps) -> None:
        self.flight.check(FlightEvent.MOVE)
        altitude_m = -self.home_ned_m[2] + msg.height / 1000.0
        lat, lon, speed = msg.latitude / 1e7, msg.longitude / 1e7, self._speed(msg.speed)
        target = self._gps_target_ned(self.airframe.snapshot(), lat, lon, altitude_m)
        self._check_envelope(self.home_ned_m, target or (*self.home_ned_m[:2], -altitude_m))
        self._start_motion(lambda: self.airframe.fly_to_gps(lat, lon, altitude_m, speed))

    def _goto_waypoint(self) -> None:
        wp = self._waypoint
        if wp is None:
            raise _Refused(ResultCode.REFUSED, "no waypoint uploaded (send >*>ws first)")
        self.flight.check(FlightEvent.MOVE)
        snap = self.airframe.snapshot()
        speed = self.settings.max_speed_m_s * max(wp.max_speed, 1) / 100.0
        altitude_m = (
            -self.home_ned_m[2] + wp.height / 1000.0
            if wp.properties & WaypointProps.HEIGHT_ENABLED
            else snap.altitude_m
        )
        if wp.properties & WaypointProps.ABSOLUTE:
            lat, lon = wp.Y / 1e7, wp.X / 1e7
            target = self._gps_target_ned(snap, lat, lon, altitude_m)
            self._check_envelope(self.home_ned_m, target or (*self.home_ned_m[:2], -altitude_m))
            self._start_motion(lambda: self.airframe.fly_to_gps(lat, lon, altitude_m, speed))
        else:  # X east, Y north, mm from home
            n = self.home_ned_m[0] + wp.Y / 1000.0
            e = self.home_ned_m[1] + wp.X / 1000.0
            self._check_envelope(self.home_ned_m, (n, e, -altitude_m))
            self._start_motion(lambda: self.airframe.fly_to(n, e, altitude_m, speed))
            self._waypoint_target = (n, e, -altitude_m)
        self._waypoint_status = 0

    def _come_home(self) -> None:
        self.flight.check(FlightEvent.MOVE)
        snap = self.airframe.snapshot()
        n, e, _ = self.home_ned_m
        speed = self.settings.default_speed_m_s
        self._start_motion(lambda: self.airframe.fly_to(n, e, snap.altitude_m, speed))

    def _ctrl_input(self, msg: CtrlInput, now_s: float) -> None:
        self._sticks = msg
        gesture = msg.thrust <= GESTURE_THRUST_MAX and abs(msg.yaw) >= GESTURE_YAW_MIN
        if not gesture:
            self._gesture_since_s = None
            self._gesture_done = False
        elif self._gesture_since_s is None:
            self._gesture_since_s = now_s
        self._check_gesture(now_s)
        if not self.motors_on or gesture:
            return  # the low-level board ignores the sticks until the motors run
        bits = CtrlBits(msg.ctrl)
        if not bits:
            return  # no axis taken from the serial input
        if self.state is NavState.LANDED and msg.thrust <= GESTURE_THRUST_MAX:
            return  # motors idling on the ground
        self.flight.check(FlightEvent.STICKS)
        self._end_motion()
        self._fly_sticks(msg, bits)
        self._fire(FlightEvent.STICKS)

    def _fly_sticks(self, msg: CtrlInput, bits: CtrlBits) -> None:
        if bits & (CtrlBits.HEIGHT_CONTROL | CtrlBits.GPS_POSITION_CONTROL):
            # Height / GPS modes: sticks command velocities (thrust centred = hold height).
            # Full stick = the vehicle's maximum speed / climb rate, limited (not refused) at
            # the flight envelope's edge.
            full = self.settings.max_speed_m_s
            fwd = -msg.pitch / STICK_MAX * full if bits & CtrlBits.PITCH else 0.0
            right = msg.roll / STICK_MAX * full if bits & CtrlBits.ROLL else 0.0
            up = (
                max(-1.0, min(1.0, (msg.thrust - THRUST_MAX / 2) / (THRUST_MAX / 2)))
                * self.settings.max_climb_m_s
                if bits & CtrlBits.THRUST
                else 0.0
            )
            yaw = stick_to_yaw_rate_rad_s(msg.yaw) if bits & CtrlBits.YAW else 0.0
            snap = self.airframe.snapshot()
            fwd, right, up = self.settings.envelope.limit_body_velocity(
                self.home_ned_m, snap.pos_ned_m, snap.rpy_rad[2], fwd, right, up
            )
            self.airframe.set_velocity(fwd, right, up, yaw, None)
            return
        self.airframe.attitude(
            stick_to_angle_rad(msg.roll) if bits & CtrlBits.ROLL else 0.0,
            stick_to_angle_rad(msg.pitch) if bits & CtrlBits.PITCH else 0.0,
            stick_to_yaw_rate_rad_s(msg.yaw) if bits & CtrlBits.YAW else 0.0,
            msg.thrust / THRUST_MAX if bits & CtrlBits.THRUST else 0.0,
        )

    def _envelope_guard(self) -> None:
        """Stop a flying vehicle that is beyond the envelope and still moving out."""
        if self.state is not NavState.FLYING:
            return
        snap = self.airframe.snapshot()
        reason = self.settings.envelope.breach(self.home_ned_m, snap.pos_ned_m, snap.vel_ned_m_s)
        if reason is None:
            return
        self.envelope_stops += 1
        self.envelope_reason = reason
        self._end_motion()
        self.airframe.hover()
        self._fire(FlightEvent.ARRIVED)

    def _check_gesture(self, now_s: float) -> None:
        since = self._gesture_since_s
        if since is None or self._gesture_done or now_s - since < GESTURE_HOLD_S:
            return
        self._gesture_done = True
        if not self.motors_on:
            self.motors_on = True  # idle until thrust comes up; state stays LANDED
            return
        snap = self.airframe.snapshot()
        if snap.landed or self.state is NavState.LANDED:
            self.motors_on = False
            self.airframe.attitude(0.0, 0.0, 0.0, 0.0)
            self._fire(FlightEvent.MOTORS_OFF)

    # -- time ----------------------------------------------------------------------------
    def tick(self, now_s: float) -> list[Message]:
        """Advance time-dependent behaviour; returns packets to push (streamed telemetry)."""
        self._check_gesture(now_s)
        self._progress(now_s)
        self._envelope_guard()
        self._failsafe(now_s)
        if self._stream is None or now_s < self._stream_next_s:
            return []
        period_s = self._stream.period / 1000.0
        self._stream_next_s = max(self._stream_next_s + period_s, now_s - period_s)
        out = self.poll(self._stream.poll_mask)
        if self._stream.skeye_mask & SkeyeMask.NAV_STATUS:
            out.append(self.nav_status())
        if self._stream.skeye_mask & SkeyeMask.PAD:
            out.append(self.pad.report())
        return out

    def _progress(self, now_s: float) -> None:
        state = self.state
        snap = self.airframe.snapshot()
        self.geo.add(snap.gps, snap.pos_ned_m)
        if state is NavState.TAKING_OFF and not self.airframe.busy:
            self._fire(FlightEvent.CLIMBED)
        elif state is NavState.FLYING:
            if self._velocity_until_s is not None and now_s >= self._velocity_until_s:
                self._velocity_until_s = None
                self.airframe.hover()
                self._fire(FlightEvent.ARRIVED)
            elif self._motion_pending and not self.airframe.busy:
                self._motion_pending = False
                self._waypoint_status |= int(NavigationStatus.REACHED)
                self._fire(FlightEvent.ARRIVED)
        elif state is NavState.LANDING and not self.airframe.busy and snap.landed:
            self._fire(FlightEvent.TOUCHDOWN)
            self.motors_on = False
            self.pad.landing_finished()
        on_ground = snap.landed and not snap.armed
        if on_ground and self.state in (NavState.FLYING, NavState.HOLDING, NavState.FAILSAFE):
            self._fire(FlightEvent.TOUCHDOWN)
            self.motors_on = False
            self._end_motion()
            self.pad.landing_finished()

    def _failsafe(self, now_s: float) -> None:
        state = self.state
        silent_s = now_s - self._last_packet_s
        if state in (NavState.TAKING_OFF, NavState.FLYING, NavState.HOLDING):
            if silent_s >= self.settings.link_timeout_s:
                self._fire(FlightEvent.LINK_LOST)
                self._end_motion()
                self.airframe.hover()
                self._failsafe_since_s = now_s
        elif state is NavState.FAILSAFE and self._failsafe_since_s is not None:
            if now_s - self._failsafe_since_s >= self.settings.land_timeout_s:
                self._fire(FlightEvent.LAND_TIMEOUT)
                self.airframe.land()
                self._failsafe_since_s = None

    def vehicle_lost(self, now_s: float) -> None:
        """The vehicle below stopped answering (simulator gone): failsafe as on link loss.

        In the air that is FAILSAFE (hold, then land after the land timeout: the commands go
        to an airframe that may refuse them, which the loop tolerates); on the ground, nothing.
        """
        if self.state in (NavState.TAKING_OFF, NavState.FLYING, NavState.HOLDING):
            self._fire(FlightEvent.LINK_LOST)
            self._end_motion()
            self._failsafe_since_s = now_s

    def client_gone(self, now_s: float) -> None:
        """The client went away (or a new one arrives): stop the stream. The link-loss timer
        keeps counting from the last packet: a vanished client is a lost link, and a connection
        alone is not a packet."""
        self._stream = None

    # -- telemetry -----------------------------------------------------------------------
    def poll(self, mask: int) -> list[Message]:
        """One frame per requested structure, in mask-bit order."""
        snap = self.airframe.snapshot()
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
        return [build(snap) for bit, build in builders.items() if mask & bit]

    def _ll_status(self, snap: Snapshot) -> LlStatus:
        mv = v_to_mv(snap.battery_v)
        flight_mode = 0x01  # attitude control always on
        if self.state not in (NavState.LANDED,) and self._sticks.ctrl & CtrlBits.HEIGHT_CONTROL:
            flight_mode |= 0x02
        if self._motion_pending or self.state in (NavState.HOLDING, NavState.FAILSAFE):
            flight_mode |= 0x06  # height and position hold
        return LlStatus(
            battery_voltage_1=_sat16(mv),
            battery_voltage_2=_sat16(mv),
            status=0,
            cpu_load=CPU_LOAD_CYCLES_S,
            compass_enabled=1,
            chksum_error=min(255, self.errors[ResultCode.BAD_CHECKSUM.name.lower()]),
            flying=int(not snap.landed),
            motors_on=int(snap.armed or self.motors_on),
            flightMode=flight_mode,
            up_time=_sat16(int(snap.time_s - self._start_sim_s)),
        )

    def _imu_si(self, snap: Snapshot) -> ImuCalcSi:
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
            baro_height_m=snap.baro_altitude_m,
        )

    def _imu_calc(self, snap: Snapshot) -> Message:
        return imu_calcdata_from_si(self._imu_si(snap))

    def _imu_raw(self, snap: Snapshot) -> ImuRawData:
        p, q, r = (_sat16(rad_s_to_angvel_counts(w)) for w in snap.rates_frd_rad_s)
        mx, my, mz = (_sat16(round(b * 100)) for b in snap.mag_field_frd_ut)
        ax, ay, az = (_sat16(m_s2_to_acc_counts(a)) for a in snap.specific_force_frd_m_s2)
        return ImuRawData(
            pressure=round(snap.baro_pressure_pa),
            gyro_x=p,
            gyro_y=q,
            gyro_z=r,
            mag_x=mx,
            mag_y=my,
            mag_z=mz,
            acc_x=ax,
            acc_y=ay,
            acc_z=az,
            temp_gyro=TEMPERATURE_CENTI_DEGC,
            temp_ADC=TEMPERATURE_CENTI_DEGC,
        )

    def _rc_data(self, snap: Snapshot) -> RcData:
        # No RC transmitter in the simulation: the channels show the serial stick input.
        s = self._sticks
        sticks = (s.pitch + 2048, s.roll + 2048, s.yaw + 2048, s.thrust)
        channels = (*sticks, s.ctrl, 0, 0, 0)
        return RcData(channels_in=channels, channels_out=channels, lock=0)

    def _controller_output(self, snap: Snapshot) -> ControllerOutput:
        s = self._sticks
        return ControllerOutput(
            nick=s.pitch,
            roll=s.roll,
            yaw=s.yaw,
            thrust=fraction_to_controller_thrust(snap.thrust_fraction),
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
            horizontal_accuracy_m=2.5,
            vertical_accuracy_m=5.0,
            speed_accuracy_m_s=0.2,
            num_sv=g.satellites,
            status=GPS_FIX_VALID,
        )

    def _gps(self, snap: Snapshot) -> Message:
        return gps_data_from_si(self._gps_si(snap))

    def _gps_advanced(self, snap: Snapshot) -> Message:
        gps = self._gps_si(snap)
        self.geo.add(snap.gps, snap.pos_ned_m)
        here = self.geo.estimate(snap.pos_ned_m)
        lat, lon = here if here is not None else (gps.latitude_deg, gps.longitude_deg)
        vn, ve, _ = snap.vel_ned_m_s  # the INS velocity, as the position
        best = GpsBestSi(lat, lon, ve, vn)
        return gps_data_advanced_from_si(gps, best)

    def _current_way(self, snap: Snapshot) -> CurrentWay:
        status = self._waypoint_status
        distance_m = 0.0
        target = self._waypoint_target
        if target is not None:
            n, e, d = snap.pos_ned_m
            distance_m = math.dist((n, e, d), target)
            if distance_m <= WAYPOINT_NEAR_M:
                status |= int(NavigationStatus.WITHIN_20M)
        wp = self._waypoint
        return CurrentWay(
            dummy1=0,
            properties=0 if wp is None else wp.properties,
            nr_of_wp=0 if wp is None else 1,
            current_wp=0 if wp is None else 1,
            current_wp_memlocation=0,
            status=int(self._motion_pending),
            dummy2=0,
            navigation_status=status,
            distance_to_wp=min(0xFFFF, m_to_dm(distance_m)),
        )

    def nav_status(self) -> Message:
        """NAV_STATUS from the onboard estimate. North and east are from the world origin; down
        is from the ground at home (where the vehicle rested before its last take-off), so
        ``-down`` is the height above ground that TAKE_OFF and GOTO_GPS heights mean: 0 when
        landed there, 1.5 after "take off to 1.5 m"."""
        snap = self.airframe.snapshot()
        north, east, down = snap.pos_ned_m
        return nav_status_from_si(
            NavStatusSi(
                state=self.state,
                pad_mode=self.pad.mode,
                pos_ned_m=(north, east, down - self.home_ned_m[2]),
                yaw_rad=snap.rpy_rad[2],
                vel_ned_m_s=snap.vel_ned_m_s,
                battery_v=snap.battery_v,
                time_s=max(0.0, snap.time_s),
            )
        )


class _Refused(Exception):
    """Internal: a command refused for a reason outside the state table."""

    def __init__(self, code: ResultCode, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason


def event_pd(msg: Message) -> int:
    """The descriptor a command's answer names."""
    from skeye.wire.packet_defs import LAYOUTS

    pd = LAYOUTS[type(msg)].pd
    return NO_COMMAND_PD if pd is None else int(pd)
