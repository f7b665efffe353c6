"""The three onboard boards, emulated: proxy, low-level board and onboard computer, sans I/O.

How this works: ``OnboardBoards.handle(event, now_s)`` takes one decoded command (or decode
error) from ``CommandStreamParser`` and returns the packets to send back; ``tick(now_s)``
advances everything that depends on time (flight-state progress from the airframe, the
stick gesture, the link-loss failsafe, streamed telemetry) and returns packets to push. The
time is an argument (wall-clock seconds, monotonic), so tests drive it; the boards own no
socket, thread or clock. The caller serialises calls (one lock in the server). What the vehicle
does runs on the vehicle's clock (the airframe snapshot's time: sim time on the simulator): a
VELOCITY's duration ends there, not on the wall clock, which runs apart in lockstep.

Answers: every skeye command gets a RESULT (0 ok, or the code of what is wrong); AscTec
commands get their ack, or a RESULT naming the command's PD when refused; a poll gets one frame
per requested structure. Decode errors that name a command get that command's RESULT; unknown
``>*>`` command letters get RESULT(0x00, bad value); frames too broken to name anything are only
counted. Refusals come from the flight-state table (``skeye.pilot.states``): code 4 "refused in
this state", code 5 "busy".

Crashes (the airframe's snapshot says ``crashed``: the simulator's crash detector, or the
robot removed): CRASHED from any state; every command but RESET (and PAD_MODE, STREAM, polls)
is refused with the cause; RESET asks the airframe to bring the vehicle back (LANDED). The
vehicle's health (OK, CRASHED, LOST with the reason) goes to ground control in HEALTH packets:
pushed when it changes, and streamed with NAV_STATUS once a second.

Link loss: while airborne, no packet for ``link_timeout_s`` (on a simulator, as long in sim
time as on the wall clock: :meth:`OnboardBoards._link_silent_s`) -> FAILSAFE (hover), then after
``land_timeout_s`` more -> LANDING. A packet arriving in FAILSAFE stops the land countdown; the
vehicle keeps holding until ground control commands it, and if the link is lost again first
(no packet for ``link_timeout_s`` once more) the countdown starts again.

Sticks: CTRL_INPUT with its axis bits set, the motors running, takes over from whatever flies
the vehicle (take-off, a move, a pad mode, a landing, a failsafe) and the state says MANUAL
(``skeye.pilot.states``; docs/pilot.md). An axis whose bit is clear is flown from the R/C on
the real board; there is none here, so it holds: centre stick (level, no yaw rate) and, for
the thrust, the height held. The motors start with thrust 0 and full negative yaw held
``GESTURE_HOLD_S`` and stop (on the ground only) with thrust 0 and full positive yaw, as the
AscTec AutoPilot SDK's ``motor_on_off`` example gives them.

Flight envelope (``skeye.pilot.envelope``, like PX4's geofence): every command with a target
is checked against a ceiling above home, a floor at home's height (its ground: landing is
LAND's, never a move's) and a radius around it and refused with RESULT code 3 and a reason
when outside; stick input is limited at the envelope's edge, not refused (a
full-thrust stick in height mode means the maximum climb rate, and holds height at the
ceiling), and so are the pad modes' and a policy's (``fly_velocity``); an open-ended VELOCITY
is not refused nor limited; a vehicle beyond a limit that still moves outward is stopped
(HOLDING).

Telemetry: ``poll`` and the stream hand a snapshot of the airframe and the boards' status
(``BoardStatus``) to ``skeye.pilot.telemetry``, which builds the structures; this module only
decides what happens.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from skeye.errors import LocalProtocolError, SkeyeError
from skeye.geo import GeoOrigin
from skeye.pilot.airframe import Airframe, Snapshot
from skeye.pilot.envelope import FlightEnvelope
from skeye.pilot.pad import PadController
from skeye.pilot.states import FlightEvent, FlightStateMachine, IllegalTransition
from skeye.pilot.telemetry import BoardStatus, GeoAnchor, Telemetry
from skeye.wire.packet_defs import LAYOUTS, NavState
from skeye.wire.packet_units import (
    STICK_MAX,
    THRUST_MAX,
    goto_gps_to_si,
    move_by_to_si,
    si_value,
    stick_to_angle_rad,
    stick_to_yaw_rate_rad_s,
    take_off_to_si,
    velocity_to_si,
    waypoint_to_si,
)
from skeye.wire.packets import (
    PD,
    Ack,
    Clock,
    ComeHome,
    CommandError,
    CommandEvent,
    CtrlBits,
    CtrlInput,
    EndFlight,
    ErrorKind,
    FrameError,
    GotoGps,
    Health,
    HealthStatus,
    Hold,
    Land,
    Launch,
    Message,
    MoveBy,
    MoveFrame,
    NavigationStatus,
    PadMode,
    Poll,
    Reset,
    Result,
    ResultCode,
    SkeyeMask,
    Stream,
    TakeOff,
    VehicleInfo,
    Velocity,
    Waypoint,
    WaypointGoto,
    WaypointProps,
    arrived_intact,
)

log = logging.getLogger(__name__)

NO_COMMAND_PD = 0x00  # RESULT.command_pd when the answer names no command
GESTURE_HOLD_S = 1.0  # thrust 0 + full yaw held this long starts (yaw < 0) or stops the motors
GESTURE_YAW_MIN = 2000  # "full yaw": |yaw stick| at least this (of 2047)
GESTURE_THRUST_MAX = 50  # "thrust 0": thrust stick at most this (of 4095)
AXIS_BITS = CtrlBits.PITCH | CtrlBits.ROLL | CtrlBits.YAW | CtrlBits.THRUST
# Sim time after a stick command during which "on the ground and disarmed" is not read as a
# touchdown: the snapshot may predate the simulator's answer to the stick DRIVE that armed
# it (a board tick can run between sending the DRIVE and the next STA). Without it, sticks
# that lift the vehicle off were followed by a TOUCHDOWN, motors "off" and every later stick
# ignored while the vehicle flew on the first one.
STICK_ARM_SETTLE_S = 0.5
HEALTH_PERIOD_S = 1.0  # HEALTH streamed with NAV_STATUS at most this often
# The lowest TAKE_OFF (m above the take-off point; lower is refused, code 3): twice the motion
# control's 5 cm arrival tolerance (MotionConfig.tolerance_m; the LL pilot's arrival too), so
# a take-off ends clear of the gear by the tolerance again, the onboard estimate's hover jitter
# (docs/control.md). A target within the tolerance was "reached" before the vehicle left the
# ground. Ground control's take-off field and the MAVLink endpoint have the same minimum.
MIN_TAKE_OFF_M = 0.1


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
    # The robot file's max_yaw_rate_rad_s (MaxYawRate): a VELOCITY turning faster is refused.
    max_yaw_rate_rad_s: float = 1.745
    envelope: FlightEnvelope = field(default_factory=FlightEnvelope)  # ceiling, radius


_AIRBORNE = (NavState.TAKING_OFF, NavState.FLYING, NavState.HOLDING, NavState.MANUAL)
"""States in which a lost link (or vehicle) starts the failsafe: in MANUAL the sticks come
over that link, so losing it is PX4's and ArduPilot's radio failsafe."""


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
        self.motors_on = snap.armed
        self._last_packet_s = now_s
        # The vehicle's time (sim time on a simulator) when a tick first saw _last_packet_s:
        # the link's silence on the vehicle's clock (_link_silent_s).
        self._packet_seen_s = now_s
        self._packet_vehicle_s = snap.time_s
        self._failsafe_since_s: float | None = None
        self._vehicle_lost = False  # the vehicle below stopped answering (until it is back)
        # Vehicle time (the snapshot's: sim time on the simulator) a timed VELOCITY ends: the
        # duration is the vehicle's motion, which in lockstep runs at its own pace.
        self._velocity_until_s: float | None = None
        self._motion_pending = False  # an autonomous motion whose end is airframe.busy
        self._sticks = CtrlInput(0, 0, 0, 0, 0)
        self._sticks_sim_s = -math.inf  # sim time of the last stick command flown
        self._gesture_since_s: float | None = None
        self._gesture_start = False  # the gesture held: start (yaw < 0) or stop (yaw > 0)
        self._gesture_done = False
        self._motor_time_s = 0.0  # sim time the motors have turned (LL_STATUS up_time)
        self._motors_seen_s: float | None = None  # sim time they were last seen turning
        self.takeovers = 0  # times the sticks took over from another state
        self.taken_over_from: NavState | None = None  # the state they took over from, last
        self._waypoint: Waypoint | None = None
        self._waypoint_target: tuple[float, float, float] | None = None  # NED
        self._waypoint_status = 0  # NavigationStatus bits the boards latch: 0x01, 0x02, 0x08
        self._waypoint_flying = False  # from >*>wg until 0x02 or the flight is replaced (0x08)
        self._waypoint_radius_m = 0.0  # the waypoint's pos_acc
        self._waypoint_stay_s = 0.0  # its time to stay
        self._waypoint_arrived = False  # the motion to it has ended there
        self._waypoint_inside_s: float | None = None  # vehicle time it came within pos_acc
        self._stream: Stream | None = None
        self._stream_next_s = 0.0
        self.motion_changes = 0  # bumped by every command or event that replaces the motion
        self.pad_commands = 0  # PAD_MODE commands taken (a new pad mode, or the same again)
        self.envelope_stops = 0  # times the envelope stopped a vehicle moving out
        self.envelope_reason = ""  # why, the last time
        self.clock_until_s = 0.0  # sim time granted by CLOCK (used with --ground-clock)
        self.telemetry = Telemetry(snap)
        self.health = Health(HealthStatus.OK)
        self._health_news = False  # changed since the last tick: push it
        self._health_next_s = now_s

    # -- state ---------------------------------------------------------------------------
    @property
    def state(self) -> NavState:
        return self.flight.state

    def _fire(self, event: FlightEvent) -> NavState:
        return self.flight.fire(event)

    # -- packets in ----------------------------------------------------------------------
    def handle(self, event: CommandEvent, now_s: float) -> list[Message]:
        """Answer one parsed command or decode error.

        Only an event whose bytes arrived intact is a packet from ground control for the link
        timeout (:func:`arrived_intact`): a stream of corrupt frames neither keeps the link up
        nor stops the failsafe's land countdown.
        """
        if arrived_intact(event):
            self._last_packet_s = now_s
            if self.state is NavState.FAILSAFE and not self._vehicle_lost:
                # Ground control is back: stop the countdown. Not for a vehicle lost below:
                # the ground being there does not bring it back.
                self._failsafe_since_s = None
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
            reason = str(exc)
            if self.state is NavState.CRASHED:
                reason += f" ({self.health.reason}); send RESET to bring it back"
            return [Result(pd, exc.code, reason[: Result.MAX_REASON_BYTES // 4])]
        except _Refused as exc:
            self.errors["refused"] += 1
            return [Result(pd, exc.code, exc.reason[: Result.MAX_REASON_BYTES // 4])]
        except LocalProtocolError as exc:  # beyond the vehicle's limits
            self.errors["refused"] += 1
            return [Result(pd, ResultCode.BAD_VALUE, str(exc)[: Result.MAX_REASON_BYTES // 4])]
        except SkeyeError as exc:  # the vehicle cannot do it now (no GPS fix, stale sensor)
            self.errors["refused"] += 1
            return [Result(pd, ResultCode.REFUSED, str(exc)[: Result.MAX_REASON_BYTES // 4])]
        except (ArithmeticError, ValueError) as exc:  # a value it cannot fly on (NaN estimate)
            self.errors["failed"] += 1
            why = f"failed: {type(exc).__name__}: {exc}"[: Result.MAX_REASON_BYTES // 4]
            log.warning("command 0x%02x %s", pd, why)
            return [Result(pd, ResultCode.REFUSED, why)]
        return [reply]

    def _dispatch(self, msg: Message, now_s: float) -> Message:
        pd = event_pd(msg)
        ok = Result(pd, ResultCode.OK, "")
        if self._vehicle_lost and isinstance(msg, _NEEDS_THE_VEHICLE):
            raise _Refused(ResultCode.REFUSED, f"the vehicle is lost: {self.health.reason}")
        if isinstance(msg, CtrlInput):
            self._ctrl_input(msg, now_s)
            return Ack(PD.CTRL_INPUT)
        if isinstance(msg, Waypoint):
            self._waypoint = msg  # stored, whatever becomes of an automatic goto
            if msg.properties & WaypointProps.AUTOMATIC_GOTO:
                # WPPROP_AUTOMATICGOTO: "if set, vehicle will not wait for a goto command, but
                # goto this waypoint directly" (AscTec LL/HL communication header): the upload
                # is a >*>wg too, refused (RESULT naming 0x24) as that one would be
                if self._vehicle_lost:
                    raise _Refused(ResultCode.REFUSED,
                                   f"the vehicle is lost: {self.health.reason}")
                self._goto_waypoint()
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
            self._take_off(take_off_to_si(msg))
        elif isinstance(msg, Land):
            self._land()
        elif isinstance(msg, Hold):
            self.flight.check(FlightEvent.HOLD)
            self.airframe.hover()
            self._fire(FlightEvent.HOLD)
            self._end_motion()
            self.pad.stop()  # "stop and hover here": a pad hold or landing ends too
        elif isinstance(msg, Velocity):
            self._velocity(msg)
        elif isinstance(msg, MoveBy):
            self._move_by(msg)
        elif isinstance(msg, GotoGps):
            self._goto_gps(msg)
        elif isinstance(msg, PadMode):
            self._pad_mode(msg)
        elif isinstance(msg, Reset):
            self._reset()
        elif isinstance(msg, Stream):
            self._stream = msg if msg.period > 0 else None
            self._stream_next_s = now_s
        elif isinstance(msg, Clock):
            self.clock_until_s = si_value(msg, "until")
        else:
            raise _Refused(ResultCode.BAD_VALUE, f"{type(msg).__name__} is not a command")
        return ok

    # -- commands ------------------------------------------------------------------------
    def _end_motion(self) -> None:
        """What flew the vehicle is replaced (a command, the sticks, an event). A waypoint
        flight replaced before its 0x02 is aborted: CURRENT_WAY says 0x08, as the AscTec
        board does when the safety pilot's sticks take over (SDK ``sdkio.h``,
        ``WP_NAVSTAT_PILOT_ABORT``: "aborted by safety pilot (any stick was moved)"), here
        whatever replaced it, so a station waiting for 0x02 learns it will not come."""
        self.motion_changes += 1
        self._motion_pending = False
        self._velocity_until_s = None
        self._waypoint_target = None
        if self._waypoint_flying:
            self._waypoint_flying = False
            self._waypoint_status |= int(NavigationStatus.ABORTED)

    def check_move(self, target_ned_m: tuple[float, float, float] | None = None,
                   speed_m_s: float | None = None,
                   home_ned_m: tuple[float, float, float] | None = None) -> str | None:
        """Why a move at ``speed_m_s`` to ``target_ned_m`` is refused, or None: a speed over
        the vehicle's limit (refused, never silently capped), then a target outside the flight
        envelope around ``home_ned_m`` (default: this flight's home). ``None`` skips a check.
        The boards' own commands and the MAVLink endpoint ask this one rule."""
        limit = self.settings.max_speed_m_s
        if speed_m_s is not None and speed_m_s > limit + 1e-9:
            return f"speed {speed_m_s:g} m/s is over this vehicle's limit of {limit:g} m/s"
        if target_ned_m is not None:
            home = self.home_ned_m if home_ned_m is None else home_ned_m
            return self.settings.envelope.check_target(home, target_ned_m)
        return None

    def check_velocity(self, forward_m_s: float, right_m_s: float, up_m_s: float,
                       yaw_rate_rad_s: float) -> str | None:
        """Why a VELOCITY is refused, or None: forward or right over the vehicle's speed limit
        (on each, as the simulated vehicle and a policy's actions limit them), up or down over
        its climb limit, a yaw rate over its own; refused, never silently capped, whatever the
        backend (the simulator's robot refuses one too, in its own terms; a real vehicle's
        would fly what it can). Said as the packet means each value, the yaw rate in deg/s
        (as ``skeye link`` and ground control take it) and rad/s (the packet's SI)."""
        limit = self.settings.max_speed_m_s
        for name, value in (("forward", forward_m_s), ("right", right_m_s)):
            if abs(value) > limit + 1e-9:
                return f"{name} {value:g} m/s is over this vehicle's limit of {limit:g} m/s"
        climb = self.settings.max_climb_m_s
        if abs(up_m_s) > climb + 1e-9:
            return (f"up {up_m_s:g} m/s is over this vehicle's climb and descent limit of "
                    f"{climb:g} m/s")
        turn = self.settings.max_yaw_rate_rad_s
        if abs(yaw_rate_rad_s) > turn + 1e-9:
            return (f"yaw rate {math.degrees(yaw_rate_rad_s):.5g} deg/s "
                    f"({yaw_rate_rad_s:g} rad/s) is over this vehicle's limit of "
                    f"{math.degrees(turn):.5g} deg/s ({turn:g} rad/s)")
        return None

    def _check_envelope(self, home_ned_m: tuple[float, float, float],
                        target_ned_m: tuple[float, float, float]) -> None:
        reason = self.check_move(target_ned_m, home_ned_m=home_ned_m)
        if reason is not None:
            raise _Refused(ResultCode.BAD_VALUE, reason)

    def _gps_target_ned(self, snap: Snapshot, lat_deg: float, lon_deg: float,
                        altitude_m: float) -> tuple[float, float, float] | None:
        """A GPS target in NED through the latest fix (None without a fix: the airframe
        refuses the move itself then)."""
        g = snap.gps
        if g is None or not g.fix:
            return None
        dn, de, _ = GeoOrigin(g.latitude_deg, g.longitude_deg).to_ned(lat_deg, lon_deg, 0.0)
        return (snap.pos_ned_m[0] + dn, snap.pos_ned_m[1] + de, -altitude_m)

    def _take_off(self, height_m: float) -> None:
        """TAKE_OFF, >*>wl: climb ``height_m`` above here, which becomes home. Below
        ``MIN_TAKE_OFF_M`` it is refused (code 3) naming the minimum, not raised to it as PX4
        raises a take-off to ``MIS_TAKEOFF_ALT``: a command is flown as asked or refused, as
        speeds over the limit are."""
        self.flight.check(FlightEvent.TAKE_OFF)
        if height_m < MIN_TAKE_OFF_M - 0.0005:  # the field's resolution is 1 mm
            raise _Refused(
                ResultCode.BAD_VALUE,
                f"take-off height {height_m:g} m is below this vehicle's minimum of "
                f"{MIN_TAKE_OFF_M:g} m (a lower target is reached before it leaves the ground)")
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

    def _speed(self, speed_m_s: float) -> float:
        """A command's speed (0: the default); over the vehicle's limit it is refused, never
        silently capped."""
        speed = speed_m_s if speed_m_s > 0 else self.settings.default_speed_m_s
        reason = self.check_move(speed_m_s=speed)
        if reason is not None:
            raise _Refused(ResultCode.BAD_VALUE, reason)
        return speed

    def _pad_mode(self, msg: PadMode) -> None:
        """PAD_MODE: a correction speed over the vehicle's limit is refused, as for MOVE_BY."""
        if msg.max_speed:
            self._speed(si_value(msg, "max_speed"))
        self.pad.set_mode(msg)
        self.pad_commands += 1

    def _reset(self) -> None:
        """RESET: the airframe brings the vehicle back at home; it stands LANDED there."""
        self.flight.check(FlightEvent.RESET)
        what = self.airframe.reset()
        self._back(FlightEvent.RESET, what)

    def respawned(self, what: str) -> None:
        """A new vehicle under the pilot (re-attached to a restarted simulator): LANDED."""
        self._back(FlightEvent.RESPAWNED, what)

    def _back(self, event: FlightEvent, what: str) -> None:
        self._fire(event)
        self._end_motion()
        self.motors_on = False
        self._failsafe_since_s = None
        self._vehicle_lost = False
        self.pad.landing_finished()
        snap = self.airframe.snapshot()
        self.home_ned_m = snap.pos_ned_m
        self.telemetry = Telemetry(snap)
        self._set_health(HealthStatus.OK, what)

    def _set_health(self, status: HealthStatus, reason: str) -> None:
        reason = reason[: Health.MAX_REASON_BYTES // 4]
        if (status, reason) != (self.health.status, self.health.reason):
            self.health = Health(status, reason)
            self._health_news = True

    def _velocity(self, msg: Velocity) -> None:
        self.flight.check(FlightEvent.MOVE)
        si = velocity_to_si(msg)
        fwd, right, down = si.vel_frd_m_s
        reason = self.check_velocity(fwd, right, -down, si.yaw_rate_rad_s)
        if reason is not None:
            raise _Refused(ResultCode.BAD_VALUE, f"velocity: {reason}")
        duration_s = si.duration_s if msg.duration else None
        snap = self.airframe.snapshot()
        if duration_s is not None:  # where it ends; open-ended ones are stopped at the edge
            vn, ve = _frd_to_ned((fwd, right, 0.0), snap.rpy_rad[2])
            n, e, d = snap.pos_ned_m
            end = (n + vn * duration_s, e + ve * duration_s, d + down * duration_s)
            self._check_envelope(self.home_ned_m, end)
        self.airframe.set_velocity(fwd, right, -down, si.yaw_rate_rad_s, duration_s)
        self._fire(FlightEvent.MOVE)
        self._end_motion()
        self._velocity_until_s = None if duration_s is None else snap.time_s + duration_s

    def _move_by(self, msg: MoveBy) -> None:
        self.flight.check(FlightEvent.MOVE)
        snap = self.airframe.snapshot()
        si = move_by_to_si(msg)
        delta, dyaw_rad = si.delta_m, si.dyaw_rad
        if msg.frame is MoveFrame.BODY_FRD:
            dn, de = _frd_to_ned(delta, snap.rpy_rad[2])
        else:
            dn, de = delta[0], delta[1]
        if delta == (0.0, 0.0, 0.0):
            if dyaw_rad == 0.0:
                raise _Refused(ResultCode.BAD_VALUE, "MOVE_BY of zero distance and zero yaw")
            self._start_motion(lambda: self.airframe.turn_by(dyaw_rad))
            return
        n, e, d = snap.pos_ned_m
        speed = self._speed(si.speed_m_s)
        self._check_envelope(self.home_ned_m, (n + dn, e + de, d + delta[2]))
        self._start_motion(lambda: self.airframe.fly_to(n + dn, e + de, -(d + delta[2]), speed))

    def _goto_gps(self, msg: GotoGps) -> None:
        self.flight.check(FlightEvent.MOVE)
        si = goto_gps_to_si(msg)
        altitude_m = -self.home_ned_m[2] + si.height_m
        lat, lon, speed = si.latitude_deg, si.longitude_deg, self._speed(si.speed_m_s)
        target = self._gps_target_ned(self.airframe.snapshot(), lat, lon, altitude_m)
        self._check_envelope(self.home_ned_m, target or (*self.home_ned_m[:2], -altitude_m))
        self._start_motion(lambda: self.airframe.fly_to_gps(lat, lon, altitude_m, speed))

    def _goto_waypoint(self) -> None:
        wp = self._waypoint
        if wp is None:
            raise _Refused(ResultCode.REFUSED, "no waypoint uploaded (send >*>ws first)")
        self.flight.check(FlightEvent.MOVE)
        snap = self.airframe.snapshot()
        si = waypoint_to_si(wp)  # x east, y north: metres from home, or degrees when ABSOLUTE
        speed = self.settings.max_speed_m_s * max(wp.max_speed, 1) / 100.0
        altitude_m = (
            -self.home_ned_m[2] + si.height_m
            if wp.properties & WaypointProps.HEIGHT_ENABLED
            else snap.altitude_m
        )
        if wp.properties & WaypointProps.ABSOLUTE:
            lat, lon = si.y, si.x
            target = self._gps_target_ned(snap, lat, lon, altitude_m)
            self._check_envelope(self.home_ned_m, target or (*self.home_ned_m[:2], -altitude_m))
            self._start_motion(lambda: self.airframe.fly_to_gps(lat, lon, altitude_m, speed))
        else:
            n = self.home_ned_m[0] + si.y
            e = self.home_ned_m[1] + si.x
            target = (n, e, -altitude_m)
            self._check_envelope(self.home_ned_m, target)
            self._start_motion(lambda: self.airframe.fly_to(n, e, altitude_m, speed))
        # (after _start_motion: replacing the previous flight is not this one's end)
        self._waypoint_target = target  # None: an absolute one without a fix to place it
        self._waypoint_status = 0
        self._waypoint_flying = True
        self._waypoint_radius_m = si.position_accuracy_m
        self._waypoint_stay_s = si.hold_time_s
        self._waypoint_arrived = False
        self._waypoint_inside_s = None

    def _waypoint_progress(self, snap: Snapshot) -> None:
        """The AscTec waypoint engine's navigation status (AscTec AutoPilot SDK, ``sdkio.h``
        ``WP_NAVSTAT_*``; docs/protocols/packets.md, CURRENT_WAY): REACHED (0x01) once the
        estimate has come within the waypoint's ``pos_acc`` (or the motion to it has arrived,
        within the motion's own tolerance: a ``pos_acc`` below that is met there), latched;
        REACHED_AND_WAITED (0x02) once the vehicle has been within it for ``time`` (the time
        to stay) on the vehicle's clock, which ends the waypoint flight (the SDK's
        ``gps_waypoints.c`` sends the next waypoint then). Leaving the radius before the time
        is over starts the count again when it comes back. The vehicle holds at the
        waypoint meanwhile and after."""
        if not self._waypoint_flying:
            return
        target = self._waypoint_target
        inside = self._waypoint_arrived or (
            target is not None and math.dist(snap.pos_ned_m, target) <= self._waypoint_radius_m)
        if not inside:
            self._waypoint_inside_s = None
            return
        self._waypoint_status |= int(NavigationStatus.REACHED)
        if self._waypoint_inside_s is None:
            self._waypoint_inside_s = snap.time_s
        if snap.time_s - self._waypoint_inside_s >= self._waypoint_stay_s - 1e-9:
            self._waypoint_status |= int(NavigationStatus.REACHED_AND_WAITED)
            self._waypoint_flying = False

    def _come_home(self) -> None:
        self.flight.check(FlightEvent.MOVE)
        snap = self.airframe.snapshot()
        n, e, _ = self.home_ned_m
        speed = self.settings.default_speed_m_s
        self._start_motion(lambda: self.airframe.fly_to(n, e, snap.altitude_m, speed))

    def _ctrl_input(self, msg: CtrlInput, now_s: float) -> None:
        self._sticks = msg
        gesture = msg.thrust <= GESTURE_THRUST_MAX and abs(msg.yaw) >= GESTURE_YAW_MIN
        start = msg.yaw < 0
        if not gesture or start != self._gesture_start:
            self._gesture_since_s = None
            self._gesture_done = False
        if gesture and self._gesture_since_s is None:
            self._gesture_since_s = now_s
            self._gesture_start = start
        self._check_gesture(now_s)
        if not self.motors_on or gesture:
            return  # the low-level board ignores the sticks until the motors run
        bits = CtrlBits(msg.ctrl)
        if not bits & AXIS_BITS:
            return  # no axis taken from the serial input
        if self.state is NavState.LANDED and (
            not bits & CtrlBits.THRUST or msg.thrust <= GESTURE_THRUST_MAX
        ):
            return  # motors idling on the ground: nothing asks them up
        self.flight.check(FlightEvent.STICKS)
        before = self.state
        self._end_motion()
        if before is not NavState.MANUAL:  # the sticks take over (docs/pilot.md)
            self.takeovers += 1
            self.taken_over_from = before
            self.pad.stop()
        if self._fly_sticks(msg, bits):
            self._sticks_sim_s = self.airframe.snapshot().time_s
        self._fire(FlightEvent.STICKS)

    def _fly_sticks(self, msg: CtrlInput, bits: CtrlBits) -> bool:
        """The LL board's modes by the ctrl bits (sdk.h ``WO_CTRL_INPUT``): attitude mode (sticks
        are angles, thrust is collective), height mode (0x10: angles, the thrust stick a climb
        rate around its centre, height held there) and GPS mode (0x20: sticks are velocities,
        full stick = the vehicle's maximum speed; centred they hold). An axis whose bit is clear
        holds (no R/C here to fly it): centre stick, and the height held for the thrust. At
        the flight envelope's edge the outward part of a stick is removed, never refused: a
        climb at the ceiling, a velocity or a tilt towards the radius limit.

        Returns whether the command asks the vehicle to move (it arms a disarmed one)."""
        yaw = stick_to_yaw_rate_rad_s(msg.yaw) if bits & CtrlBits.YAW else 0.0
        # The stick's centre (2047.5) lies between two counts: both are "centred", a climb of
        # exactly zero, so the board holds the height (else 2048 climbed at 0.4 mm/s for ever).
        off_centre = msg.thrust - THRUST_MAX / 2
        climb = (
            max(-1.0, min(1.0, off_centre / (THRUST_MAX / 2))) * self.settings.max_climb_m_s
            if bits & CtrlBits.THRUST and abs(off_centre) > 0.5
            else 0.0
        )
        if bits & CtrlBits.GPS_POSITION_CONTROL:
            full = self.settings.max_speed_m_s
            fwd = -msg.pitch / STICK_MAX * full if bits & CtrlBits.PITCH else 0.0
            right = msg.roll / STICK_MAX * full if bits & CtrlBits.ROLL else 0.0
            snap = self.airframe.snapshot()
            fwd, right, up = self.settings.envelope.limit_body_velocity(
                self.home_ned_m, snap.pos_ned_m, snap.rpy_rad[2], fwd, right, climb
            )
            self.airframe.set_velocity(fwd, right, up, yaw, None, gps_mode=True)
            return up > 0.0 or fwd != 0.0 or right != 0.0 or yaw != 0.0
        roll = stick_to_angle_rad(msg.roll) if bits & CtrlBits.ROLL else 0.0
        pitch = stick_to_angle_rad(msg.pitch) if bits & CtrlBits.PITCH else 0.0
        if bits & CtrlBits.HEIGHT_CONTROL or not bits & CtrlBits.THRUST:
            # The tilt's direction is where the vehicle accelerates (forward = nose down).
            snap = self.airframe.snapshot()
            fwd, right, up = self.settings.envelope.limit_body_velocity(
                self.home_ned_m, snap.pos_ned_m, snap.rpy_rad[2], -pitch, roll, climb
            )
            full_climb = self.settings.max_climb_m_s
            thrust = 0.5 + (up / full_climb / 2.0 if full_climb > 0 else 0.0)
            self.airframe.attitude(right, -fwd, yaw, thrust, height_mode=True)
            return thrust > 0.0
        thrust = msg.thrust / THRUST_MAX
        self.airframe.attitude(roll, pitch, yaw, thrust)
        return thrust > 0.0

    def fly_velocity(self, forward_m_s: float, right_m_s: float, up_m_s: float,
                     yaw_rate_rad_s: float = 0.0) -> None:
        """An open-ended velocity set-point of the onboard computer's own (the pad hold and
        landing, a ``--policy``), heading frame, up positive: at the flight envelope's edge its
        outward part is removed, as the sticks' is (the envelope guard acts only on FLYING and
        MANUAL, and these fly while HOLDING: a pad search climbed to its 8 m over a 3 m
        ceiling)."""
        snap = self.airframe.snapshot()
        envelope, fwd, right, up = self.settings.envelope, forward_m_s, right_m_s, up_m_s
        if envelope.at_limit(self.home_ned_m, snap.pos_ned_m):  # (inside, the numbers go on
            # untouched: the heading-frame round trip would change their last bits)
            fwd, right, up = envelope.limit_body_velocity(
                self.home_ned_m, snap.pos_ned_m, snap.rpy_rad[2], fwd, right, up)
        self.airframe.set_velocity(fwd, right, up, yaw_rate_rad_s, None)

    def _envelope_guard(self) -> None:
        """Stop a flying vehicle that is beyond the envelope and still moving out (flown by a
        motion or by the sticks, as PX4's geofence acts in manual modes too; the next stick
        command takes over again, and the sticks are limited at the edge)."""
        if self.state is not NavState.FLYING and self.state is not NavState.MANUAL:
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
        """A gesture held for its time: start the motors (full negative yaw) if they are off,
        stop them (full positive yaw) if they run on the ground; else nothing (the AscTec
        gestures are one for each, so a stop meant for motors that already stopped by
        themselves leaves them stopped)."""
        since = self._gesture_since_s
        if since is None or self._gesture_done or now_s - since < GESTURE_HOLD_S:
            return
        if self.state is NavState.CRASHED:
            return  # a wreck's motors stay off until RESET
        self._gesture_done = True
        if self._gesture_start:
            if not self.motors_on:
                self.motors_on = True  # idle until thrust comes up; state stays LANDED
            return
        snap = self.airframe.snapshot()
        if self.motors_on and (snap.landed or self.state is NavState.LANDED):
            self.motors_on = False
            self.airframe.attitude(0.0, 0.0, 0.0, 0.0)
            self._fire(FlightEvent.MOTORS_OFF)

    # -- time ----------------------------------------------------------------------------
    def tick(self, now_s: float) -> list[Message]:
        """Advance time-dependent behaviour; returns packets to push (streamed telemetry, and
        HEALTH when it changed)."""
        self._check_gesture(now_s)
        self._progress()
        self._envelope_guard()
        self._failsafe(now_s)
        out: list[Message] = []
        if self._health_news:
            self._health_news = False
            out.append(self.health)
        if self._stream is None or now_s < self._stream_next_s:
            return out
        period_s = si_value(self._stream, "period")
        self._stream_next_s = max(self._stream_next_s + period_s, now_s - period_s)
        out += self.poll(self._stream.poll_mask)
        if self._stream.skeye_mask & SkeyeMask.NAV_STATUS:
            nav = self.nav_status()
            if nav is not None:
                out.append(nav)
            if now_s >= self._health_next_s:  # the health now, for a station that came late
                self._health_next_s = now_s + HEALTH_PERIOD_S
                if not out or out[0] is not self.health:
                    out.append(self.health)
                info = self.telemetry.built("VEHICLE", self.vehicle_info)
                if info is not None:
                    out.append(info)
        if self._stream.skeye_mask & SkeyeMask.TRUTH:
            snap, status = self.airframe.snapshot(), self.status()
            truth = (self.telemetry.built("TRUTH", lambda: self.telemetry.truth(snap, status))
                     if snap.truth_ned_m is not None else None)
            if truth is not None:
                out.append(truth)
        if self._stream.skeye_mask & SkeyeMask.PAD:
            out.append(self.pad.report())
        return out

    def vehicle_info(self) -> VehicleInfo:
        """VEHICLE: whether the airframe is simulated (it then knows its truth) and what it is."""
        text = self.airframe.describe()
        data = text.encode("utf-8", errors="replace")[: VehicleInfo.MAX_DESCRIPTION_BYTES]
        return VehicleInfo(
            simulated=int(self.airframe.snapshot().truth_ned_m is not None),
            description=data.decode("utf-8", errors="ignore"),
        )

    def _count_motor_time(self, snap: Snapshot) -> None:
        """Add the sim time since the last look while the motors turn (LL_STATUS up_time)."""
        running = self.motors_on or snap.armed
        seen = self._motors_seen_s
        if running and seen is not None and snap.time_s > seen:
            self._motor_time_s += snap.time_s - seen
        if running:
            self._motors_seen_s = snap.time_s if seen is None else max(seen, snap.time_s)
        else:
            self._motors_seen_s = None

    def _progress(self) -> None:
        state = self.state
        snap = self.airframe.snapshot()
        if snap.crashed and state is not NavState.CRASHED:
            self._crash(snap.crashed)
            return
        self.geo.add(snap.gps, snap.pos_ned_m)
        self._count_motor_time(snap)
        self.telemetry.observe(snap, self.motors_on or snap.armed)
        if state is NavState.TAKING_OFF and not self.airframe.busy:
            self._fire(FlightEvent.CLIMBED)
        elif state is NavState.FLYING:
            if self._velocity_until_s is not None and snap.time_s >= self._velocity_until_s:
                self._velocity_until_s = None
                self.airframe.hover()
                self._fire(FlightEvent.ARRIVED)
            elif self._motion_pending and not self.airframe.busy:
                self._motion_pending = False
                self._waypoint_arrived = self._waypoint_flying
                self._fire(FlightEvent.ARRIVED)
        elif state is NavState.LANDING and not self.airframe.busy and snap.landed:
            self._fire(FlightEvent.TOUCHDOWN)
            self.motors_on = False
            self.pad.landing_finished()
        self._waypoint_progress(snap)
        on_ground = (snap.landed and not snap.armed
                     and snap.time_s > self._sticks_sim_s + STICK_ARM_SETTLE_S)
        if on_ground and self.state in (NavState.FLYING, NavState.HOLDING, NavState.FAILSAFE,
                                        NavState.MANUAL):
            self._fire(FlightEvent.TOUCHDOWN)
            self.motors_on = False
            self._end_motion()
            self.pad.landing_finished()

    def _crash(self, cause: str) -> None:
        """The vehicle crashed: CRASHED, whatever it was doing; the cause goes to the ground."""
        self._fire(FlightEvent.CRASH)
        self._end_motion()
        self.motors_on = False
        self._failsafe_since_s = None
        self.pad.landing_finished()
        self._set_health(HealthStatus.CRASHED, cause)

    def _link_silent_s(self, now_s: float) -> float:
        """How long ground control has been silent: on the wall clock (the link is a radio,
        or a TCP connection, on wall time), and for a simulated vehicle at most as long on its
        own clock, sim time. A simulator that is merely slow (a loaded machine, a ground
        station that grants lockstep time and waits for it to be flown) does not make ground
        control silent: a vehicle whose whole flight took a fifth of a second of sim time went
        FAILSAFE (and never HOLDING) when the process stalled 2 s of wall time. A ground
        station that is gone stays silent on both clocks, so the failsafe still comes, after
        ``link_timeout_s`` of each. A vehicle lost below has no clock (its sim time stands
        still): the wall clock alone."""
        silent_s = now_s - self._last_packet_s
        if not getattr(self.airframe, "clock_is_sim", False) or self._vehicle_lost:
            return silent_s
        vehicle_s = self.airframe.snapshot().time_s
        if self._last_packet_s != self._packet_seen_s or vehicle_s < self._packet_vehicle_s:
            # (a clock that went back is a new simulator's, the vehicle respawned there)
            self._packet_seen_s, self._packet_vehicle_s = self._last_packet_s, vehicle_s
        return min(silent_s, vehicle_s - self._packet_vehicle_s)

    def _failsafe(self, now_s: float) -> None:
        state = self.state
        silent_s = self._link_silent_s(now_s)
        if state in _AIRBORNE:
            if silent_s >= self.settings.link_timeout_s:
                self._fire(FlightEvent.LINK_LOST)
                self._end_motion()
                self.airframe.hover()
                self._failsafe_since_s = now_s
        elif state is NavState.FAILSAFE:
            if self._failsafe_since_s is None and silent_s >= self.settings.link_timeout_s:
                # Ground control came back (its packet stopped the countdown) and was lost
                # again before commanding anything: the countdown starts again, or a vehicle
                # that heard one packet in FAILSAFE hovered for good.
                self._failsafe_since_s = now_s
            since = self._failsafe_since_s
            if since is not None and now_s - since >= self.settings.land_timeout_s:
                self._fire(FlightEvent.LAND_TIMEOUT)
                self._failsafe_since_s = None
                try:
                    self.airframe.land()
                except SkeyeError as exc:
                    if not self._vehicle_lost:
                        raise
                    log.warning("failsafe: the land timeout's landing did not reach the lost "
                                "vehicle: %s", exc)

    def vehicle_lost(self, now_s: float, reason: str = "") -> None:
        """The vehicle below stopped answering (simulator gone): failsafe as on link loss.

        In the air that is FAILSAFE (hold, then land after the land timeout: the commands go
        to an airframe that may refuse them, which the loop tolerates), from a landing too: the
        pilot can no longer see the touchdown that would end it (a landing lost to its LL board
        stayed LANDING for good); on the ground, nothing. The health is LOST, with ``reason``.
        Ground control's packets do not stop this countdown as they stop a lost link's: the
        ground being heard does not bring the vehicle back (they did, and with a station
        connected the pilot never tried to land a vehicle it had lost).
        """
        self._set_health(HealthStatus.LOST, reason or "the vehicle stopped answering")
        self._vehicle_lost = True
        if self.state in _AIRBORNE or self.state is NavState.LANDING:
            self._fire(FlightEvent.VEHICLE_LOST)
            self._end_motion()
            self._failsafe_since_s = now_s

    def client_gone(self, now_s: float) -> None:
        """The client went away (or a new one arrives): stop the stream. The link-loss timer
        keeps counting from the last packet: a vanished client is a lost link, and a connection
        alone is not a packet."""
        self._stream = None

    # -- telemetry -----------------------------------------------------------------------
    @property
    def geo(self) -> GeoAnchor:
        """The fused position estimate GPS_DATA_ADVANCED reports."""
        return self.telemetry.geo

    def status(self) -> BoardStatus:
        """What the structures report of the boards' own state, now."""
        return BoardStatus(
            state=self.state,
            pad_mode=self.pad.mode,
            sticks=self._sticks,
            motors_on=self.motors_on,
            motion_pending=self._motion_pending,
            checksum_errors=self.errors[ResultCode.BAD_CHECKSUM.name.lower()],
            home_ned_m=self.home_ned_m,
            waypoint=self._waypoint,
            waypoint_target=self._waypoint_target,
            waypoint_status=self._waypoint_status,
            motor_time_s=self._motor_time_s,
        )

    def poll(self, mask: int) -> list[Message]:
        """One frame per requested structure, in mask-bit order."""
        snap = self.airframe.snapshot()
        self._count_motor_time(snap)
        return self.telemetry.poll(mask, snap, self.status())

    def nav_status(self) -> Message | None:
        """NAV_STATUS from the onboard estimate (``Telemetry.nav_status``); None when the
        snapshot's values do not fit it (counted in ``telemetry.unfit``)."""
        snap, status = self.airframe.snapshot(), self.status()
        return self.telemetry.built("NAV_STATUS", lambda: self.telemetry.nav_status(snap, status))


_NEEDS_THE_VEHICLE = (WaypointGoto, Launch, EndFlight, ComeHome, TakeOff, Land, Hold, Velocity,
                      MoveBy, GotoGps, PadMode)
"""Commands refused while the vehicle below is lost (``vehicle_lost`` until it is back): they
would go to a simulator that is gone or frozen, and a frozen one takes them without a word.
Polls, the stream, a stored waypoint, the clock and RESET are answered; so is CTRL_INPUT (it
is acknowledged, as the LL board does, and a station sends it twice a second as keep-alive)."""


class _Refused(Exception):
    """Internal: a command refused for a reason outside the state table."""

    def __init__(self, code: ResultCode, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason


def event_pd(msg: Message) -> int:
    """The descriptor a command's answer names."""
    pd = LAYOUTS[type(msg)].pd
    return NO_COMMAND_PD if pd is None else int(pd)
