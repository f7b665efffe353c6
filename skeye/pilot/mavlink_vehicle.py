"""The pilot's vehicle as a MAVLink autopilot: commands, missions, parameters, telemetry; sans-IO.

How this works: :class:`MavlinkVehicle` sits beside the AscTec packet link as a second client of
the same :class:`~skeye.pilot.boards.OnboardBoards`. ``handle(link, peer, msg, now_s)`` takes
one decoded message and returns :class:`Out` items (a message and where it goes);
``tick(now_s)`` runs what depends on time (the streams, the mission and return programs, the
offboard-loss and auto-disarm timers, mission transfer retries). The caller holds the boards'
lock around both, and gives the wall clock as the boards get it (``now_s``: the timers' clock,
the host's monotonic one under ``MavlinkServer``). The vehicle time every message carries
(``time_boot_ms``, ``time_usec``, TIMESYNC's answer) is the airframe snapshot's ``time_s``
instead: sim time on the simulator. SYSTEM_TIME's Unix time comes from ``wall_clock``
(``time.time`` unless a test gives another).

GPS_GLOBAL_ORIGIN: the geodetic position of the local NED origin, as GLOBAL_POSITION_INT
anchors the estimate to GPS. That anchor is the mean over every fix, so the origin moves a
little with each fix (PX4's EKF origin is set once); it is sent when first known and again
whenever it has moved by PX4's own re-send thresholds (1e-7 deg, 1 mm), checked every
``ORIGIN_CHECK_S``, so a client that keeps the last one converts local to global within a few
centimetres. Without a GPS fix (indoors) the origin is the one a ground station gave with
SET_GPS_GLOBAL_ORIGIN, if any; it is taken only then (where GPS anchors the frame it is refused,
as ArduPilot's EKF refuses it while it uses GPS: skeye's local frame is the world's, it cannot be
moved under the GPS as PX4's EKF moves its own), with PX4's checks on the values (latitude,
longitude in range; the altitude on Earth: not below the lowest land, ``ORIGIN_MAX_ALT_M`` at
most); a refusal is a STATUSTEXT and the GPS_GLOBAL_ORIGIN in force. Once fixes come, they place
the frame and the origin moves to theirs (sent as any move is).

One vehicle, two links: every motion a MAVLink command asks for is made of the boards' own
commands (TAKE_OFF, LAND, HOLD, MOVE_BY in the world frame, VELOCITY, CTRL_INPUT, PAD_MODE)
handed to ``boards.handle``, so the flight-state table, the flight envelope, the speed limits
and the link-loss failsafe apply exactly as over the AscTec link, and a refusal's RESULT code
and reason become COMMAND_ACK's result and a STATUSTEXT. Every message from a ground station
counts for the link-loss timer as a packet does (an empty poll); no message of another
vehicle does (a system whose autopilot component, 1, sends a HEARTBEAT naming an autopilot, no
ground station's type: heard where a router or a shared radio net forwards a fleet's streams to
every vehicle; PX4 counts only MAV_TYPE_GCS heartbeats towards its data link, ArduPilot only
its ground station's), nor is another vehicle a ground station. The last command wins,
whichever link it came on; a program the endpoint runs (mission, return, precision landing,
offboard) notes the boards' ``motion_changes`` after each of its own commands and stops, with a
STATUSTEXT, when any other command changed the motion.

Modes: the reported PX4 mode is ``MODE_TABLE[(state, program)]`` (``skeye.mavlink.modes``).
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from collections.abc import Callable, Hashable
from dataclasses import dataclass, replace
from typing import Any, TypeVar

from pymavlink.dialects.v20 import common as mav

from skeye.errors import LocalProtocolError
from skeye.geo import LOWEST_LAND_AMSL_M, MAX_POSITION_M, GeoOrigin
from skeye.mavlink.codec import BadFrame, MavCodec, MavMessage, statustext
from skeye.mavlink.mission import DEFAULT_SPEED, MissionItem, MissionProtocol
from skeye.mavlink.modes import MODE_TABLE, REQUESTS, Program, Px4Mode, Request
from skeye.mavlink.params import ParamSpec, ParamTable
from skeye.mavlink.streams import MessageScheduler
from skeye.mavlink.transport import PEER_TIMEOUT_S
from skeye.pilot import mavlink_telemetry as telem
from skeye.pilot.boards import MIN_TAKE_OFF_M, OnboardBoards
from skeye.pilot.mavlink_types import (
    FORCE_MAGIC,
    RESULT_OF_CODE,
    Command,
    Out,
    Refused,
    Settings,
    Step,
    command_name,
    landing_target,
)
from skeye.pilot.pad import PadObservation
from skeye.wire.packet_defs import NavState, PadAction, ResultCode
from skeye.wire.packet_units import wire_value
from skeye.wire.packets import (
    CtrlBits,
    CtrlInput,
    Hold,
    Land,
    Message,
    MoveBy,
    MoveFrame,
    PadMode,
    Poll,
    Result,
    TakeOff,
    Velocity,
)

log = logging.getLogger(__name__)
K = TypeVar("K")
V = TypeVar("V")

GCS_TIMEOUT_S = PEER_TIMEOUT_S  # a ground station silent this long is forgotten (10 s; a
# listening UDP link stops sending to it after the same time)
NOTICE_EVERY_S = 2.0  # the same refusal or bad-input notice at most this often per peer
DUPLICATE_WINDOW_S = 1.0  # a command repeated within this is acked again, not re-run
COMMANDS_KEPT = 256  # the most (peer, command id) answers kept for the repeat rule
NOTICES_KEPT = 1024  # the most (peer, notice) times kept for the notices' rate limit
ARRIVED_RADIUS_M = 0.5
ORIGIN_CHECK_S = 1.0  # how often a moved GPS_GLOBAL_ORIGIN is looked for
ORIGIN_MIN_DEG = 1e-7  # PX4's GPS_GLOBAL_ORIGIN re-send thresholds (about 1.1 cm; 1 mm)
ORIGIN_MIN_ALT_M = 1e-3
ORIGIN_MAX_ALT_M = 100_000.0  # PX4's highest origin taken ("the edge of space"); its lowest,
# -12 km (the Mariana Trench), is under water: skeye's is the lowest land, LOWEST_LAND_AMSL_M
MANUAL_CTRL = (CtrlBits.PITCH | CtrlBits.ROLL | CtrlBits.YAW | CtrlBits.THRUST
               | CtrlBits.GPS_POSITION_CONTROL)


def _flight_controller(src: tuple[int, int], heartbeat: MavMessage) -> bool:
    """Whether a HEARTBEAT from ``src`` (system, component) is a vehicle's flight controller's:
    from the autopilot component (MAV_COMP_ID_AUTOPILOT1, as PX4 and ArduPilot send), naming an
    autopilot and no ground station's type. A ground station sends MAV_TYPE_GCS with
    MAV_AUTOPILOT_INVALID from its own component (QGroundControl 255/190); a script that sends
    a bare heartbeat (type and autopilot 0) from pymavlink's default component 0 is no vehicle
    either."""
    return (src[1] == mav.MAV_COMP_ID_AUTOPILOT1
            and int(heartbeat.autopilot) != mav.MAV_AUTOPILOT_INVALID
            and int(heartbeat.type) != mav.MAV_TYPE_GCS)


LOCAL_SETPOINT_FRAMES = (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_LOCAL_OFFSET_NED,
                         mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED,
                         mav.MAV_FRAME_BODY_FRD)
"""SET_POSITION_TARGET_LOCAL_NED's frames flown (PX4's, and BODY_FRD as BODY_NED)."""
GLOBAL_SETPOINT_FRAMES = (mav.MAV_FRAME_GLOBAL_INT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                          mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT)
"""SET_POSITION_TARGET_GLOBAL_INT's frames flown (PX4 takes the float ones' ids too)."""


INT32_MAX = 2**31 - 1  # an integer field's "not given" (MAV_CMD: NaN for a float field's)


def _frame_name(frame: int) -> str:
    entry = mav.enums["MAV_FRAME"].get(frame)
    return entry.name.removeprefix("MAV_FRAME_") if entry is not None else "unknown"


def _over(value: float, limit: float) -> bool:
    """``value``, from a MAVLink float field, over ``limit`` by more than single precision's
    rounding (2**-24 of it, a few times over for a speed turned into the heading's frame): a
    client sending the limit itself (2.2 m/s arrives as 2.2000000477) is at it, not over it."""
    return abs(value) > limit * (1.0 + 1e-6)


@dataclass
class _Link:
    scheduler: MessageScheduler


class MavlinkVehicle:
    """The MAVLink side of one vehicle (see the module docstring)."""

    def __init__(self, boards: OnboardBoards, *, settings: Settings | None = None,
                 max_speed_m_s: float | None = None, system_id: int = 1,
                 now_s: float = 0.0, wall_clock: Callable[[], float] = time.time) -> None:
        self.boards = boards
        self.wall_clock = wall_clock
        self.settings = settings or Settings()
        self.codec = MavCodec(system_id, 1)
        self.max_speed_limit_m_s = max_speed_m_s or boards.settings.max_speed_m_s
        self.program = Program.NONE
        self.step = Step()
        self.mission = MissionProtocol(self.codec, self._check_item)
        self.mission_current = 0
        self.mission_state = mav.MISSION_STATE_NO_MISSION
        self.cruise_m_s: float | None = None  # DO_CHANGE_SPEED
        self.params = ParamTable(self._param_specs(), self.codec)
        self.links: list[_Link] = []
        self.gcs: dict[tuple[int, int], float] = {}
        # Other vehicles heard on the links (system id -> when last): their messages are no
        # ground station's.
        self.vehicles: dict[int, float] = {}
        self.bad_frames = 0
        self.ignored = 0  # messages understood but not acted on
        self.refusals = 0
        self.acks: dict[int, int] = {}  # MAV_RESULT -> count
        self._notices: dict[tuple[Hashable, str], float] = {}
        # (peer, command id) -> the last such command (Command.key), when it was answered, its
        # result, and the vehicle's situation after it (_situation): a repeat is a
        # retransmission only of the last command of its id, and while that situation holds
        self._recent: dict[tuple[Hashable, int], tuple[tuple[object, ...], float, int,
                                                        tuple[Px4Mode, bool, NavState | None]]] = {}
        self._armed_at_s: float | None = None
        self._setpoint: tuple[MavMessage, float] | None = None
        self._attitude_target_s: float | None = None  # the last SET_ATTITUDE_TARGET (not flown)
        self._applied_target: tuple[float, float, float] | None = None
        self._targets: deque[PadObservation] = deque(maxlen=64)
        self.landing_targets = 0
        self.landing_targets_in = 0
        self._status: tuple[Px4Mode, bool, NavState] | None = None  # the last one told
        self._now_s = now_s
        self._command_peer: Hashable = None  # who sent the command being run (its notices)
        self._origin_told: GeoOrigin | None = None  # the last GPS_GLOBAL_ORIGIN sent unasked
        self._origin_given: GeoOrigin | None = None  # SET_GPS_GLOBAL_ORIGIN's (no GPS fix)
        self._origin_check_s = -math.inf

    # -- links ---------------------------------------------------------------------------
    def add_link(self, now_s: float) -> int:
        """A new link (its own message intervals); returns its number."""
        self.links.append(_Link(MessageScheduler(now_s)))
        return len(self.links) - 1

    # -- parameters ----------------------------------------------------------------------
    def _board_setting(self, name: str) -> Callable[[float], None]:
        def set_value(value: float) -> None:
            changes: dict[str, Any] = {name: value}
            self.boards.settings = replace(self.boards.settings, **changes)
        return set_value

    def _envelope_setting(self, name: str) -> Callable[[float], None]:
        def set_value(value: float) -> None:
            env = replace(self.boards.settings.envelope, **{name: value})
            self.boards.settings = replace(self.boards.settings, envelope=env)
        return set_value

    def _endpoint_setting(self, name: str) -> Callable[[float], None]:
        def set_value(value: float) -> None:
            setattr(self.settings, name, value)
        return set_value

    def _set_cruise(self, value: float) -> None:
        """MPC_XY_CRUISE: no faster than MPC_XY_VEL_MAX, which every move is checked against
        (one above it made every move that names no speed refused)."""
        limit = self.boards.settings.max_speed_m_s
        if _over(value, limit):
            raise LocalProtocolError(f"must be at most MPC_XY_VEL_MAX, {limit:g} m/s, not "
                                     f"{value:g}")
        self._board_setting("default_speed_m_s")(min(value, limit))

    def _set_max_speed(self, value: float) -> None:
        """MPC_XY_VEL_MAX: the cruise speed (MPC_XY_CRUISE) and DO_CHANGE_SPEED's come down to
        a limit set below them, as PX4 constrains MPC_XY_CRUISE ("Cruise speed has been
        constrained by max speed"); the caller tells the ground stations the new values."""
        settings = self.boards.settings
        self.boards.settings = replace(
            settings, max_speed_m_s=value,
            default_speed_m_s=min(settings.default_speed_m_s, value))
        if self.cruise_m_s is not None:
            self.cruise_m_s = min(self.cruise_m_s, value)

    def _param_specs(self) -> list[ParamSpec]:
        b = lambda: self.boards.settings  # noqa: E731
        s = self.settings
        top = self.max_speed_limit_m_s
        return [
            ParamSpec("MIS_TAKEOFF_ALT", 0.5, 80.0, "m", "take-off height above home",
                      lambda: s.takeoff_alt_m, self._endpoint_setting("takeoff_alt_m")),
            ParamSpec("RTL_RETURN_ALT", 0.0, 150.0, "m", "return height above home",
                      lambda: s.rtl_alt_m, self._endpoint_setting("rtl_alt_m")),
            ParamSpec("MPC_XY_CRUISE", 0.1, top, "m/s",
                      "speed of moves that name none (MPC_XY_VEL_MAX at most)",
                      lambda: b().default_speed_m_s, self._set_cruise),
            ParamSpec("MPC_XY_VEL_MAX", 0.1, top, "m/s",
                      "fastest horizontal speed a command may ask for (the robot file's limit "
                      "at most)", lambda: b().max_speed_m_s, self._set_max_speed),
            ParamSpec("GF_MAX_VER_DIST", 1.0, 10_000.0, "m", "flight envelope ceiling above home",
                      lambda: b().envelope.ceiling_m, self._envelope_setting("ceiling_m")),
            ParamSpec("GF_MAX_HOR_DIST", 1.0, 100_000.0, "m",
                      "flight envelope radius around home", lambda: b().envelope.max_radius_m,
                      self._envelope_setting("max_radius_m")),
            ParamSpec("COM_DL_LOSS_T", 0.5, 300.0, "s",
                      "ground link silent this long: failsafe (hover)",
                      lambda: b().link_timeout_s, self._board_setting("link_timeout_s")),
            ParamSpec("SKY_LAND_TIMEOUT", 1.0, 3600.0, "s",
                      "in failsafe this long: land", lambda: b().land_timeout_s,
                      self._board_setting("land_timeout_s")),
            ParamSpec("COM_OF_LOSS_T", 0.1, 60.0, "s", "offboard setpoints lost: hold",
                      lambda: s.offboard_loss_s, self._endpoint_setting("offboard_loss_s")),
            ParamSpec("COM_DISARM_PRFLT", 0.0, 600.0, "s",
                      "armed on the ground without taking off: disarm (0: never)",
                      lambda: s.disarm_preflight_s, self._endpoint_setting("disarm_preflight_s")),
        ]

    # -- the vehicle ---------------------------------------------------------------------
    @property
    def armed(self) -> bool:
        return bool(self.boards.motors_on or self.boards.airframe.snapshot().armed)

    @property
    def mode(self) -> Px4Mode:
        return MODE_TABLE[(self.boards.state, self.program)]

    def origin(self) -> GeoOrigin | None:
        """The geodetic position of the estimate's NED origin: the GPS fixes' anchor, or before
        the first fix the origin a ground station gave (SET_GPS_GLOBAL_ORIGIN); else None."""
        return self._gps_origin() or self._origin_given

    def _gps_origin(self) -> GeoOrigin | None:
        latlon = self.boards.geo.estimate((0.0, 0.0, 0.0))
        alt = self.boards.geo.origin_amsl_m
        if latlon is None or alt is None:
            return None
        return GeoOrigin(latlon[0], latlon[1], alt)

    def view(self) -> telem.VehicleView:
        snap = self.boards.airframe.snapshot()
        total = len(self.mission.items)
        return telem.VehicleView(
            snap=snap, state=self.boards.state, mode=self.mode, armed=self.armed,
            home_ned_m=self.boards.home_ned_m, origin=self.origin(),
            healthy=not getattr(self.boards.airframe, "lost", None),
            bad_frames=self.bad_frames,
            mission_seq=min(self.mission_current, max(0, total - 1)), mission_total=total,
            mission_state=self.mission_state if total else mav.MISSION_STATE_NO_MISSION,
            mission_active=self.program is Program.MISSION, unix_time_s=self.wall_clock())

    # -- messages in ---------------------------------------------------------------------
    def handle(self, link: int, peer: Hashable, msg: MavMessage | BadFrame,
               now_s: float) -> list[Out]:
        """Answer one message (or bad frame) from ``peer`` on ``link``."""
        self._now_s = now_s
        reply = lambda items: [Out(m, link, peer) for m in items]  # noqa: E731
        if isinstance(msg, BadFrame):
            self.bad_frames += 1
            what = (f"unknown message id {msg.msg_id}" if msg.msg_id is not None
                    else f"bad MAVLink frame ({msg.reason[:60]})")
            return reply(self._notice(peer, "bad", mav.MAV_SEVERITY_WARNING,
                                      f"{what}: ignored"))
        if isinstance(peer, tuple) and peer[:1] == ("refused",):
            return reply(self._notice(peer, "full", mav.MAV_SEVERITY_WARNING,
                                      "too many ground stations on this link: ignored"))
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if src[0] == self.codec.system_id and src[1] == self.codec.component_id:
            return []  # our own messages echoed back
        out: list[Out] = []
        kind = msg.get_type()
        if src[0] in self.vehicles or (kind == "HEARTBEAT" and _flight_controller(src, msg)):
            self.vehicles[src[0]] = now_s  # another vehicle of a fleet, heard now
            self.ignored += 1  # its stream, forwarded to us: neither ground link nor station
            return out
        if src not in self.gcs and kind == "HEARTBEAT":
            out += self._new_station(src, link, peer, now_s)
        if kind == "HEARTBEAT" or src in self.gcs:
            self.gcs[src] = now_s
        self.boards.handle(Poll(0), now_s)  # a message from the ground: the link is alive
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            if not self._for_us(msg):
                return out
            return out + reply(self._command(peer, Command.of(msg), src))
        if kind == "SET_MODE":
            # The mode message (QGroundControl's Vehicle::setFlightMode before it sent
            # DO_SET_MODE, a script's mav.set_mode_send): DO_SET_MODE with its base mode and
            # PX4's custom mode, answered with DO_SET_MODE's COMMAND_ACK, as PX4 runs it
            # (handle_message_set_mode).
            if int(msg.target_system) not in (0, self.codec.system_id):
                return out
            custom = int(msg.custom_mode)
            params = (float(msg.base_mode), float((custom >> 16) & 0xFF),
                      float((custom >> 24) & 0xFF), 0.0, 0.0, 0.0, 0.0)
            return out + reply(self._command(
                peer, Command(mav.MAV_CMD_DO_SET_MODE, params, None), src))
        if kind.startswith("PARAM_"):
            if kind == "PARAM_VALUE":
                return out
            if not self._for_us(msg):  # (the list too: PX4 answers its own system's only)
                return out
            changed = self.params.changed
            before = [spec.get() for spec in self.params.specs]
            answer = self.params.handle(msg)
            if self.params.changed != changed:  # a new value: every ground station hears it,
                # and of every other parameter it changed (MPC_XY_VEL_MAX lowers MPC_XY_CRUISE)
                name = str(msg.param_id).split("\x00", 1)[0]
                others = [i for i, (spec, was) in enumerate(zip(self.params.specs, before,
                                                                 strict=True))
                          if spec.get() != was and spec.name != name]
                answer += [self.params.value_msg(i) for i in others]
                answer += statustext(self.codec, mav.MAV_SEVERITY_NOTICE, "; ".join(
                    f"{self.params.specs[i].name} constrained to "
                    f"{self.params.specs[i].get():g} by {name}" for i in others)) if others else []
                return out + [Out(m) for m in answer]
            return out + reply(answer)
        if kind.startswith("MISSION_"):
            if not self._for_us(msg):
                return out
            if kind == "MISSION_SET_CURRENT":
                return out + reply(self._set_current(int(msg.seq)))
            version = self.mission.version
            answer = self.mission.handle(msg, now_s, (link, peer))
            if kind == "MISSION_COUNT" or kind.startswith("MISSION_ITEM"):
                answer += self._mission_notice(answer)
            out += reply(answer)
            if self.mission.version != version:
                out += self._mission_changed("cleared" if kind == "MISSION_CLEAR_ALL"
                                             else "replaced")
            return out
        if kind in ("SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT"):
            if self._for_us(msg):
                self._setpoint = (msg, now_s)
                if self.program is Program.OFFBOARD:
                    out += reply(self._apply_setpoint(msg, peer))
            return out
        if kind == "SET_ATTITUDE_TARGET":
            if self._for_us(msg):
                self._attitude_target_s = now_s  # not flown; the Offboard request says so
            return out
        if kind == "MANUAL_CONTROL":
            if int(msg.target) in (0, self.codec.system_id) and self.program is Program.MANUAL:
                out += reply(self._manual(msg, peer))
            return out
        if kind == "SET_GPS_GLOBAL_ORIGIN":
            if int(msg.target_system) in (0, self.codec.system_id):
                out += self._set_origin(link, peer, msg)
            return out
        if kind == "LANDING_TARGET":
            self.landing_targets_in += 1  # a companion's detections (this vehicle's own
            return out  # precision landing flies on its own pad vision)
        if kind == "TIMESYNC":
            # A request: tc1 our time in ns, on the clock of the telemetry's time_boot_ms and
            # time_usec (sim time on the simulator), as PX4 answers with its boot time.
            vehicle_s = self.boards.airframe.snapshot().time_s if msg.tc1 == 0 else math.nan
            if math.isfinite(vehicle_s):
                out.append(Out(self.codec.mav.timesync_encode(round(vehicle_s * 1e9), msg.ts1),
                               link, peer))
            return out
        if kind == "PING" and msg.target_system == 0:
            # The request's own time_usec comes back (as PX4 and MAVSDK answer): the sender
            # takes its clock now minus it as the round trip.
            out.append(Out(self.codec.mav.ping_encode(msg.time_usec, msg.seq, src[0], src[1]),
                           link, peer))
            return out
        self.ignored += 1  # HEARTBEAT, SYSTEM_TIME, ...: nothing to do
        return out

    def _for_us(self, msg: MavMessage) -> bool:
        ts = int(getattr(msg, "target_system", 0))
        tc = int(getattr(msg, "target_component", 0))
        return ts in (0, self.codec.system_id) and tc in (0, self.codec.component_id)

    def _set_origin(self, link: int, peer: Hashable, msg: MavMessage) -> list[Out]:
        """SET_GPS_GLOBAL_ORIGIN: taken without a GPS fix and sent back on every link as
        GPS_GLOBAL_ORIGIN; refused with a STATUSTEXT to the sender, who gets the origin in force
        (none: nothing more), as the message's definition asks the vehicle to answer either way."""
        lat, lon, alt = msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1e3
        why = None
        if not -90.0 <= lat <= 90.0:
            why = f"latitude {lat:g} deg is out of range -90..90"
        elif not -180.0 <= lon <= 180.0:
            why = f"longitude {lon:g} deg is out of range -180..180"
        elif not LOWEST_LAND_AMSL_M <= alt <= ORIGIN_MAX_ALT_M:
            why = (f"altitude {alt:g} m above mean sea level is outside "
                   f"{LOWEST_LAND_AMSL_M:g}..{ORIGIN_MAX_ALT_M:g} m (the lowest land on Earth "
                   "to 100 km)")
        elif self._gps_origin() is not None:
            why = ("the GPS places this vehicle's local frame (the mean of its fixes): an "
                   "origin is taken only without a GPS fix")
        if why is not None:
            self.refusals += 1
            answer = self._notice(peer, f"origin:{why}", mav.MAV_SEVERITY_WARNING,
                                  f"SET_GPS_GLOBAL_ORIGIN refused: {why}")
            now = telem.gps_global_origin(self.codec, self.view())
            return [Out(m, link, peer) for m in [*answer, *([now] if now is not None else [])]]
        self._origin_given = GeoOrigin(lat, lon, alt)
        view = self.view()
        told = telem.gps_global_origin(self.codec, view)  # (an origin is known now)
        self._origin_told = view.origin
        out = self._on_change(told) if told is not None else []
        if told is not None and not any(o.link == link for o in out):  # stopped there (-1):
            out.append(Out(told, link, peer))  # the sender still hears its answer
        return out

    def _new_station(self, src: tuple[int, int], link: int, peer: Hashable,
                     now_s: float) -> list[Out]:
        live = [s for s, t in self.gcs.items() if now_s - t < GCS_TIMEOUT_S]
        if not live:
            return []
        text = (f"ground station {src[0]}/{src[1]} joined; {len(live) + 1} connected: the last "
                "command wins")
        return [Out(m) for m in statustext(self.codec, mav.MAV_SEVERITY_NOTICE, text)]

    def _notice(self, peer: Hashable, key: str, severity: int, text: str) -> list[MavMessage]:
        """A STATUSTEXT, at most once per ``NOTICE_EVERY_S`` for the same peer and key."""
        last = self._notices.get((peer, key))
        if last is not None and self._now_s - last < NOTICE_EVERY_S:
            return []
        _remember(self._notices, (peer, key), self._now_s, lambda t: t, self._now_s,
                  NOTICE_EVERY_S, NOTICES_KEPT)
        return statustext(self.codec, severity, text)

    def _mission_notice(self, answer: list[MavMessage]) -> list[MavMessage]:
        for m in answer:
            if m.get_type() == "MISSION_ACK" and m.type != mav.MAV_MISSION_ACCEPTED:
                reason = self.mission.rejections[-1] if self.mission.rejections else "refused"
                return statustext(self.codec, mav.MAV_SEVERITY_WARNING,
                                  f"mission refused: {reason}")
        return []

    def _mission_changed(self, how: str) -> list[Out]:
        """The stored mission was replaced or cleared: it starts again from its first item,
        and a mission under way stops (the vehicle holds where it is), with a STATUSTEXT to
        every link; its items are gone, so it cannot go on."""
        self.mission_current = 0
        self.mission_state = mav.MISSION_STATE_NOT_STARTED
        if self.program is not Program.MISSION:
            return []
        out = self._stop_program(f"the mission was {how}")
        self.mission_state = mav.MISSION_STATE_NOT_STARTED
        if self.boards.state in (NavState.FLYING, NavState.HOLDING):
            try:  # (a take-off ends in a hover and a landing lands, as their modes say)
                self._board(Hold())
            except Refused:
                pass
        return out

    # -- commands ------------------------------------------------------------------------
    def _command(self, peer: Hashable, cmd: Command, src: tuple[int, int]) -> list[MavMessage]:
        # A ground station retransmits only the command it waits on, and MAVSDK sends no other
        # command of an id while one is waiting: A, B, A makes the second A a new command.
        slot = (peer, cmd.command)
        seen = self._recent.get(slot)
        if (seen is not None and seen[0] == cmd.key()
                and self._now_s - seen[1] < DUPLICATE_WINDOW_S
                and cmd.command not in QUERIES and seen[3] == self._situation()):
            return [self._ack(cmd.command, seen[2], src)]  # a retransmission: same answer
        extra: list[MavMessage] = []
        self._command_peer = peer
        try:
            handler = COMMANDS.get(cmd.command)
            if handler is None:
                raise Refused(mav.MAV_RESULT_UNSUPPORTED,
                              f"command {cmd.command} is not supported by this vehicle")
            extra = handler(self, cmd) or []
            result = mav.MAV_RESULT_ACCEPTED
        except Refused as exc:
            result = exc.result
            self.refusals += 1
            extra = self._notice(peer, f"cmd{cmd.command}:{exc}", mav.MAV_SEVERITY_WARNING,
                                 f"{command_name(cmd.command)}: {exc}")
        except LocalProtocolError as exc:  # a value the boards' packets cannot carry
            result = mav.MAV_RESULT_DENIED
            self.refusals += 1
            extra = self._notice(peer, f"cmd{cmd.command}:{exc}", mav.MAV_SEVERITY_WARNING,
                                 f"{command_name(cmd.command)}: {exc}")
        _remember(self._recent, slot, (cmd.key(), self._now_s, result, self._situation()),
                  lambda seen: seen[1], self._now_s, DUPLICATE_WINDOW_S, COMMANDS_KEPT)
        self.acks[result] = self.acks.get(result, 0) + 1
        return [self._ack(cmd.command, result, src), *extra]

    def _situation(self) -> tuple[Px4Mode, bool, NavState | None]:
        """What a command's answer depends on and changes: the mode, armed, and the flight
        state while no program runs. A command repeated within ``DUPLICATE_WINDOW_S`` is a
        retransmission only while these are as its first answer left them; once they moved on
        (the take-off climbed and holds, a disarm came between two arms) the repeat is a new
        command and is run. A program (a mission, a return, offboard) moves through flight
        states by itself, and its mode names it: its own progress is no change. (Until
        2026-11-28 it was: a mission started on the ground took off at the next tick, and
        MAVSDK's resend of the start, 0.5 s later, restarted it at its take-off item in the
        air, which the climb refused: "mission stopped: move: busy while taking off".)"""
        state = self.boards.state if self.program is Program.NONE else None
        return (self.mode, self.armed, state)

    def _ack(self, command: int, result: int, src: tuple[int, int]) -> MavMessage:
        return self.codec.mav.command_ack_encode(command, result, 0, 0, src[0], src[1])

    def _board(self, msg: Message) -> None:
        """Hand one command to the boards; a refusal raises ``Refused`` with its reason."""
        for reply in self.boards.handle(msg, self._now_s):
            if isinstance(reply, Result) and reply.code != ResultCode.OK:
                raise Refused(RESULT_OF_CODE.get(ResultCode(reply.code),
                                                 mav.MAV_RESULT_DENIED),
                              reply.reason or ResultCode(reply.code).name.lower())

    def _mine(self) -> None:
        """The boards' motion now is this endpoint's (a program checks it is still so)."""
        self.step.mark = self.boards.motion_changes

    def _snap(self) -> Any:
        return self.boards.airframe.snapshot()

    def _airborne(self) -> bool:
        return self.boards.state not in (NavState.LANDED,) and self.boards.state.name != "CRASHED"

    def _fly_to(self, target_ned_m: tuple[float, float, float], speed_m_s: float | None) -> None:
        """MOVE_BY (world frame) from where the vehicle is to a NED target; HOLD if there.

        The speed limit and the flight envelope are checked here first (DENIED, by the
        boards' own rule, ``OnboardBoards.check_move``), so that a refusal gives the user's
        value and not the range of a MOVE_BY field it would overflow (a speed of 100 m/s, a
        target thousands of km away)."""
        if not all(map(math.isfinite, target_ned_m)):  # callers name the field first
            raise Refused(mav.MAV_RESULT_DENIED, "target is not a finite position")
        n, e, d = self._snap().pos_ned_m
        delta = [round((t - c) * 1e3) for t, c in zip(target_ned_m, (n, e, d), strict=True)]
        if delta == [0, 0, 0]:
            self._board(Hold())
            return
        speed = self._at_most_the_limit(speed_m_s if speed_m_s is not None else self.cruise_m_s)
        reason = self.boards.check_move(target_ned_m, speed)
        if reason is not None:
            raise Refused(mav.MAV_RESULT_DENIED, reason)
        self._board(MoveBy(delta[0], delta[1], delta[2], 0, MoveFrame.WORLD_NED,
                           round((speed or 0.0) * 1e3)))

    def _global_to_ned(self, lat_e7: int, lon_e7: int, alt_m: float, frame: int | None,
                       names: tuple[str, str, str] = ("x", "y", "z"),
                       ) -> tuple[float, float, float]:
        """A global target (COMMAND_INT x/y or MISSION_ITEM_INT) in the estimate's NED frame;
        ``names`` are the message's fields for latitude, longitude and altitude, which a
        refusal names (DENIED: out of range or not a number)."""
        for value, lo, hi, what, name in ((lat_e7, -90, 90, "latitude", names[0]),
                                          (lon_e7, -180, 180, "longitude", names[1])):
            if not lo * 10**7 <= value <= hi * 10**7:
                raise Refused(mav.MAV_RESULT_DENIED,
                              f"{what} ({name}) {value / 1e7:g} deg is out of range {lo}..{hi}")
        origin = self.origin()
        if origin is None:
            raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED,
                          "no GPS position yet: global targets cannot be placed")
        n, e, _ = origin.to_ned(lat_e7 / 1e7, lon_e7 / 1e7, origin.altitude_m)
        return n, e, self._down_of(alt_m, frame, origin, names[2])

    def _down_of(self, alt_m: float, frame: int | None, origin: GeoOrigin,
                 name: str = "z") -> float:
        """The NED down coordinate of an altitude: above home in the relative frames, above
        mean sea level in the others; one that is not a finite number is refused (DENIED)
        naming the field ``name``, and so is one below the lowest dry land on Earth (a bound on
        the number; the flight envelope's floor, home's height, is checked after it)."""
        if not math.isfinite(alt_m):
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"altitude ({name}) {alt_m:g} m is not a finite number")
        if frame in (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT):
            down = self.boards.home_ned_m[2] - alt_m
        else:
            down = origin.altitude_m - alt_m
        amsl = origin.altitude_m - down
        if amsl < LOWEST_LAND_AMSL_M:
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"altitude ({name}) {alt_m:g} m puts the target {amsl:g} m above mean "
                          f"sea level, below the lowest land on Earth ({LOWEST_LAND_AMSL_M:g} m)")
        return down

    def _arm(self, cmd: Command) -> None:
        if cmd.p(1) == 1.0:
            lost = getattr(self.boards.airframe, "lost", None)
            if lost:
                raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED, f"not armable: {lost}")
            if self.boards.state is NavState.LANDED and not self.boards.motors_on:
                self.boards.motors_on = True
                self._armed_at_s = self._now_s
            return
        if cmd.p(1) != 0.0:
            raise Refused(mav.MAV_RESULT_DENIED, f"param1 must be 0 or 1, not {cmd.p(1):g}")
        if self.boards.state is NavState.LANDED:
            self.boards.motors_on = False
            self._armed_at_s = None
            return
        if cmd.p(2) == FORCE_MAGIC:
            raise Refused(mav.MAV_RESULT_DENIED,
                          "a skeye vehicle never stops its motors in the air: land")
        raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED, "in the air: land first")

    def _takeoff(self, cmd: Command) -> None:
        if not self.armed:
            raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED, "disarmed: arm first")
        alt = cmd.p(7)
        if math.isnan(alt):
            height = self.settings.takeoff_alt_m
        elif not math.isfinite(alt):  # was "inf m AMSL is not at least 0.1 m above the vehicle"
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"take-off altitude (param7) {alt:g} m is not a finite number: give "
                          "metres above mean sea level, or NaN for MIS_TAKEOFF_ALT")
        elif alt > ORIGIN_MAX_ALT_M:  # bounded before the boards' packet, which it overflowed
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"take-off altitude (param7) {alt:g} m above mean sea level is over "
                          f"{ORIGIN_MAX_ALT_M:g} m (the edge of space)")
        else:
            origin = self.origin()
            if origin is None:
                raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED,
                              "no GPS altitude yet: leave param7 NaN (MIS_TAKEOFF_ALT)")
            height = alt - (origin.altitude_m - self._snap().pos_ned_m[2])
        if not (math.isfinite(height) and height >= MIN_TAKE_OFF_M):
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"take-off altitude {alt:g} m AMSL is not at least "
                          f"{MIN_TAKE_OFF_M:g} m above the vehicle (the lowest take-off)")
        self._board(TakeOff(round(height * 1e3)))
        self._start(Program.NONE)  # after the boards took it: a refusal changes nothing

    def _land(self, cmd: Command) -> None:
        precision = cmd.p(2)
        if precision in (1.0, 2.0) and (self.settings.pad_vision or precision == 2.0):
            self._precland()
            return
        self._board(Land())
        self._start(Program.NONE)

    def _precland(self) -> None:
        if not self.settings.pad_vision:
            raise Refused(mav.MAV_RESULT_DENIED,
                          "precision landing needs the pad vision (skeye pilot --images)")
        if not self._airborne():
            raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED, "landed")
        self._board(Hold())
        self._board(PadMode(PadAction.LAND, 0, 0))
        self._start(Program.PRECLAND)
        self._mine()

    def _rtl(self, cmd: Command | None = None) -> None:
        if not self._airborne():
            raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED, "landed: nothing to return from")
        self._start(Program.RTL)

    def _reposition(self, cmd: Command) -> list[MavMessage]:
        if cmd.frame is None:
            cmd = self._reposition_as_int(cmd)
        if cmd.frame not in (mav.MAV_FRAME_GLOBAL_INT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                             mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT):
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"frame {cmd.frame}: give GLOBAL_INT or GLOBAL_RELATIVE_ALT_INT")
        speed = cmd.p(1)  # NaN (unset, as MAVSDK's goto_location sends) or <= 0: cruise
        if math.isinf(speed):
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"ground speed (p1) {speed:g} m/s is not a finite speed: give m/s, or "
                          "-1 for the cruise speed")
        snap = self._snap()
        n, e, d = snap.pos_ned_m
        # 0/0 or INT32_MAX/INT32_MAX (MAV_CMD's "not given" for an integer field, to "use the
        # component's current ... latitude rather than a specific value"): here
        if (cmd.x, cmd.y) not in ((0, 0), (INT32_MAX, INT32_MAX)):
            n, e, _ = self._global_to_ned(cmd.x, cmd.y, 0.0, cmd.frame)
        origin = self.origin()
        if not math.isnan(cmd.p(7)) and origin is not None:  # NaN: keep the altitude
            d = self._down_of(cmd.p(7), cmd.frame, origin)
        elif not math.isnan(cmd.p(7)):
            raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED,
                          "no GPS position yet: global targets cannot be placed")
        self._fly_to((n, e, d), speed if speed > 0 else None)
        self._start(Program.NONE)  # after the boards took it: a refusal changes nothing
        yaw = cmd.p(4)  # MAVSDK's goto_location always sends one (0 for north, NaN for none)
        if math.isnan(yaw):
            return []
        return self._notice(self._command_peer, "reposition-yaw", mav.MAV_SEVERITY_NOTICE,
                            f"DO_REPOSITION: yaw (p4) {yaw:g} deg is not flown: the heading "
                            "is kept (give NaN for no yaw)")

    @staticmethod
    def _reposition_as_int(cmd: Command) -> Command:
        """A COMMAND_LONG DO_REPOSITION (QGroundControl's altitude change for PX4, its go-to
        where COMMAND_INT is not supported, a script's) as the COMMAND_INT it stands for, as
        PX4 reads it: p5, p6 latitude and longitude in degrees (both NaN: here), p7 altitude
        above mean sea level (a COMMAND_LONG has no frame: GLOBAL)."""
        lat, lon = cmd.p(5), cmd.p(6)
        if math.isnan(lat) and math.isnan(lon):
            x = y = INT32_MAX
        else:
            for value, lo, hi, what, name in ((lat, -90, 90, "latitude", "p5"),
                                              (lon, -180, 180, "longitude", "p6")):
                if not lo <= value <= hi:  # (NaN too)
                    raise Refused(mav.MAV_RESULT_DENIED,
                                  f"{what} ({name}) {value:g} deg is out of range {lo}..{hi}")
            x, y = round(lat * 1e7), round(lon * 1e7)
        return Command(cmd.command, cmd.params, mav.MAV_FRAME_GLOBAL, x, y)

    def _change_speed(self, cmd: Command) -> None:
        speed = cmd.p(2)
        if speed in DEFAULT_SPEED:
            self.cruise_m_s = None
            return
        limit = self.boards.settings.max_speed_m_s
        if not (math.isfinite(speed) and 0 < speed and not _over(speed, limit)):
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"speed {speed:g} m/s: must be above 0 and at most {limit:g} m/s")
        self.cruise_m_s = self._at_most_the_limit(speed)

    def _at_most_the_limit(self, speed_m_s: float | None) -> float | None:
        """A speed from a MAVLink float field, the vehicle's limit where it is the limit as a
        float32 carries it (``_over``: 2.2 m/s arrives as 2.2000000477), else as it came; the
        boards, which take the limit exactly, then fly the limit instead of refusing it."""
        limit = self.boards.settings.max_speed_m_s
        if speed_m_s is not None and limit < speed_m_s and not _over(speed_m_s, limit):
            return limit
        return speed_m_s

    def _set_mode(self, cmd: Command) -> None:
        if not cmd.whole(1, "base mode") & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            raise Refused(mav.MAV_RESULT_DENIED,
                          "only PX4 custom modes (base mode with CUSTOM_MODE_ENABLED)")
        mode = Px4Mode.from_custom(cmd.whole(2, "custom main mode"),
                                   cmd.whole(3, "custom sub mode"))
        if mode is None:  # it was said as one not flown, for the sticks of the AscTec link
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"custom mode {cmd.p(2):g}/{cmd.p(3):g} (main/sub) is no PX4 mode")
        request = REQUESTS.get(mode)
        if request is None:
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"mode {mode.name} is not flown by this vehicle (attitude sticks come "
                          "over its AscTec link)")
        if mode == self.mode and request is not Request.MISSION \
                and self.boards.state is not NavState.FAILSAFE:
            return  # already so (in the failsafe, Hold is the way out: it is sent)
        if request is Request.HOLD:
            if self._airborne():
                self._board(Hold())
            self._start(Program.NONE)
        elif request is Request.MISSION:
            self._start_mission(self.mission_current)
        elif request is Request.RTL:
            self._rtl()
        elif request is Request.LAND:
            self._board(Land())
            self._start(Program.NONE)
        elif request is Request.TAKEOFF:
            self._takeoff(Command(mav.MAV_CMD_NAV_TAKEOFF, (0,) * 6 + (math.nan,), None))
        elif request is Request.OFFBOARD:
            sp = self._setpoint
            if sp is None or self._now_s - sp[1] > self.settings.offboard_loss_s:
                att = self._attitude_target_s
                if att is not None and self._now_s - att <= self.settings.offboard_loss_s:
                    raise Refused(mav.MAV_RESULT_DENIED,
                                  "attitude setpoints (SET_ATTITUDE_TARGET) are not flown by "
                                  "this vehicle: send SET_POSITION_TARGET_LOCAL_NED or "
                                  "_GLOBAL_INT (a position or a velocity)")
                raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED,
                              "offboard needs setpoints first (none within COM_OF_LOSS_T)")
            if not self._airborne():
                raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED,
                              "take off first: offboard flies a vehicle in the air")
            # The latest setpoint is flown first: one that cannot be refuses the mode with its
            # reason (its own result: DENIED for a value, TEMPORARILY_REJECTED for the state),
            # and the mode and program stay as they were; PX4 too refuses a mode whose
            # requirements are not met (TEMPORARILY_REJECTED, "Switching to Offboard is
            # currently not possible").
            self._applied_target = None
            try:
                self._fly_setpoint(sp[0])
            except (Refused, LocalProtocolError) as exc:
                result = exc.result if isinstance(exc, Refused) else mav.MAV_RESULT_DENIED
                raise Refused(result, f"the latest offboard setpoint is refused: {exc}") from None
            self._start(Program.OFFBOARD)  # after the boards took it (marks their motion ours)
        elif request is Request.MANUAL:
            if self._airborne():
                self._board(Hold())
            self._start(Program.MANUAL)
        elif request is Request.PRECLAND:
            self._precland()

    def _mission_start(self, cmd: Command) -> None:
        first = int(cmd.p(1)) if math.isfinite(cmd.p(1)) else 0
        self._start_mission(first)

    def _set_current_cmd(self, cmd: Command) -> None:
        seq = int(cmd.p(1)) if math.isfinite(cmd.p(1)) else -1
        if not 0 <= seq < len(self.mission.items):
            raise Refused(mav.MAV_RESULT_DENIED, f"no mission item {cmd.p(1):g}")
        self._set_current(seq)

    def _set_current(self, seq: int) -> list[MavMessage]:
        if not 0 <= seq < len(self.mission.items):
            return statustext(self.codec, mav.MAV_SEVERITY_WARNING, f"no mission item {seq}")
        self.mission_current = seq
        if self.program is Program.MISSION:  # the mission goes on from that item (its
            # motion is still this endpoint's: the next tick flies the new item)
            self.step = Step(index=seq, mark=self.step.mark)
        return [telem.mission_current(self.codec, self.view())]

    def _message_interval(self, cmd: Command) -> None:
        msg_id, interval_us = cmd.whole(1, "message id"), cmd.p(2)
        interval = None if interval_us == -1 else max(0.0, interval_us) / 1e6
        if not math.isfinite(interval_us) or (interval_us < 0 and interval_us != -1):
            raise Refused(mav.MAV_RESULT_DENIED, f"interval {interval_us:g} us: give -1 (stop), "
                          "0 (the default rate) or an interval > 0")
        try:
            for link in self._links_of_command():
                link.scheduler.set_interval(msg_id, interval, self._now_s)
        except LocalProtocolError as exc:
            raise Refused(mav.MAV_RESULT_DENIED, str(exc)) from None

    def _links_of_command(self) -> list[_Link]:
        return self.links  # one scheduler per link; a command sets it on every link

    def _get_interval(self, cmd: Command) -> list[MavMessage]:
        msg_id = cmd.whole(1, "message id")
        if not self.links or not self.links[0].scheduler.streamable(msg_id):
            raise Refused(mav.MAV_RESULT_DENIED, f"message {msg_id} is not streamed")
        interval = self.links[0].scheduler.interval_s(msg_id)
        return [self.codec.mav.message_interval_encode(
            msg_id, -1 if interval is None else round(interval * 1e6))]

    def _request_message(self, cmd: Command) -> list[MavMessage]:
        msg_id = int(cmd.p(1)) if math.isfinite(cmd.p(1)) else -1
        if msg_id == mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return [telem.autopilot_version(self.codec)]
        builder = telem.BUILDERS.get(msg_id)
        if builder is None:
            raise Refused(mav.MAV_RESULT_DENIED, f"message {cmd.p(1):g} is not available")
        msg = builder(self.codec, self.view())
        if msg is None:
            raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED,
                          f"message {msg_id} needs a GPS position (none yet)")
        return [msg]

    def _capabilities(self, cmd: Command) -> list[MavMessage]:
        return [telem.autopilot_version(self.codec)]

    # -- offboard and sticks -------------------------------------------------------------
    def _apply_setpoint(self, msg: MavMessage, peer: Hashable) -> list[MavMessage]:
        """Fly one offboard setpoint in the Offboard mode (``_fly_setpoint``); a refusal is
        a STATUSTEXT "offboard setpoint refused: ..." to ``peer``."""
        try:
            if self._fly_setpoint(msg):
                self._mine()
        except (Refused, LocalProtocolError) as exc:
            return self._notice(peer, f"offboard:{exc}", mav.MAV_SEVERITY_WARNING,
                                f"offboard setpoint refused: {exc}")
        return []

    def _fly_setpoint(self, msg: MavMessage) -> bool:
        """Fly one offboard setpoint: a position (MOVE_BY to it, once per target) or a
        velocity (VELOCITY lasting COM_OF_LOSS_T, so lost setpoints end in a hover); True if
        a command went to the boards. One that cannot be flown raises ``Refused`` (or
        ``LocalProtocolError``) naming its field, and nothing is flown."""
        frame = int(msg.coordinate_frame)
        local = int(msg.get_msgId()) == mav.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED
        if frame not in (LOCAL_SETPOINT_FRAMES if local else GLOBAL_SETPOINT_FRAMES):
            # (a LOCAL_ENU or FLU setpoint flown as NED went east for north and down for up;
            # a terrain altitude as one above mean sea level)
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"coordinate_frame {frame} ({_frame_name(frame)}) is not flown: give "
                          + ("LOCAL_NED, LOCAL_OFFSET_NED, BODY_NED, BODY_OFFSET_NED or BODY_FRD"
                             if local else "GLOBAL_INT or GLOBAL_RELATIVE_ALT_INT"))
        mask = int(msg.type_mask)
        pos_ignored = mask & 0b111 == 0b111
        vel_ignored = mask & 0b111000 == 0b111000
        snap = self._snap()
        if not pos_ignored:
            target = self._setpoint_position(msg, snap, mask & 0b111)
            if (self._applied_target is not None
                    and max(abs(a - b) for a, b in zip(target, self._applied_target,
                                                       strict=True)) < 0.02
                    and self.boards.motion_changes == self.step.mark):
                return False
            self._fly_to(target, None)
            self._applied_target = target
            return True
        if vel_ignored:
            return False
        # an axis ignored in type_mask (vx 8, vy 16, vz 32) is not commanded: 0, whatever the
        # field holds (a client's NaN or stale value there is no speed to fly)
        vn, ve, vd = ((0.0 if mask & bit else float(v))
                      for bit, v in ((0b1000, msg.vx), (0b10000, msg.vy), (0b100000, msg.vz)))
        if local and frame in (mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED,
                               mav.MAV_FRAME_BODY_FRD):
            fwd, right = vn, ve
        else:
            yaw = snap.rpy_rad[2]
            fwd = math.cos(yaw) * vn + math.sin(yaw) * ve
            right = -math.sin(yaw) * vn + math.cos(yaw) * ve
        yaw_rate = 0.0 if mask & 0b100000000000 else float(msg.yaw_rate)
        self._check_velocity((vn, ve, vd, yaw_rate), fwd, right)
        self._applied_target = None
        self._board(Velocity(round(fwd * 1e3), round(right * 1e3), round(vd * 1e3),
                             wire_value(Velocity, "yaw_rate", yaw_rate),
                             round(self.settings.offboard_loss_s * 1e3)))
        return True

    def _setpoint_position(self, msg: MavMessage, snap: Any, ignored: int = 0
                           ) -> tuple[float, float, float]:
        """The NED target of a position setpoint. ``ignored``: its type_mask's position bits
        (x/latitude 1, y/longitude 2, z/altitude 4); an axis ignored is not commanded: the
        target keeps the vehicle's own coordinate there (an offset of 0), whatever the field
        holds (a client's 0 for an unused z is not the ground)."""
        n, e, d = snap.pos_ned_m
        if msg.get_type() == "SET_POSITION_TARGET_GLOBAL_INT":
            frame = int(msg.coordinate_frame)
            lat, lon, alt = int(msg.lat_int), int(msg.lon_int), float(msg.alt)
            # an ignored field: a valid stand-in (0), replaced by the vehicle's own below
            lat, lon = (0 if ignored & 1 else lat), (0 if ignored & 2 else lon)
            alt = 0.0 if ignored & 4 else alt
            target = self._global_to_ned(lat, lon, alt, frame, ("lat_int", "lon_int", "alt"))
            return (n if ignored & 1 else target[0], e if ignored & 2 else target[1],
                    d if ignored & 4 else target[2])
        x, y, z = ((0.0 if ignored & bit else float(v))
                   for bit, v in ((1, msg.x), (2, msg.y), (4, msg.z)))
        for name, value in (("x", x), ("y", y), ("z", z)):
            if not math.isfinite(value):
                raise Refused(mav.MAV_RESULT_DENIED,
                              f"position setpoint: {name} {value:g} m is not a finite number")
        frame = int(msg.coordinate_frame)
        if frame in (mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED, mav.MAV_FRAME_BODY_FRD):
            yaw = snap.rpy_rad[2]
            target = (n + math.cos(yaw) * x - math.sin(yaw) * y,
                      e + math.sin(yaw) * x + math.cos(yaw) * y, d + z)
        elif frame == mav.MAV_FRAME_LOCAL_OFFSET_NED:
            target = n + x, e + y, d + z
        else:
            target = (n if ignored & 1 else x, e if ignored & 2 else y,
                      d if ignored & 4 else z)
        self._check_local_down(target[2], z)
        return target

    def _check_local_down(self, down_m: float, z_m: float) -> None:
        """Refuse (DENIED, naming the field z) a local target below the ground, as global
        ones are (``_down_of``), before the flight envelope (whose floor is home's ground) names
        the target in its own terms. With
        an origin, below the lowest land on Earth; without one (indoors: the ground's height
        above the sea is not known), deeper than ``MAX_POSITION_M`` below the local origin,
        as far as a local position reaches. (Past these, the target is thousands of km away
        and its MOVE_BY's fields would overflow.)"""
        origin = self.origin()
        if origin is not None:
            amsl = origin.altitude_m - down_m
            if amsl < LOWEST_LAND_AMSL_M:
                raise Refused(mav.MAV_RESULT_DENIED,
                              f"position setpoint: z {z_m:g} m puts the target {amsl:g} m above "
                              f"mean sea level, below the lowest land on Earth "
                              f"({LOWEST_LAND_AMSL_M:g} m)")
        elif down_m > MAX_POSITION_M:
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"position setpoint: z {z_m:g} m puts the target {down_m:g} m below the "
                          f"local origin, beyond the {MAX_POSITION_M / 1e3:g} km a local "
                          "position reaches")

    def _check_velocity(self, given: tuple[float, float, float, float], fwd: float,
                        right: float) -> None:
        """Refuse (DENIED, naming the fields) a velocity setpoint (``given``: vx, vy, vz,
        yaw_rate as sent) that is not a number or is over the vehicle's limits: forward or
        right of its heading (``fwd``, ``right``: vx, vy turned into the heading frame, as
        the VELOCITY flies them) over ``MPC_XY_VEL_MAX`` (the boards' ``max_speed_m_s``, the
        limit a simulated vehicle puts on each of the two, as a policy's actions do), vz over
        the climb limit (``max_climb_m_s``, up or down), yaw_rate over the vehicle's
        (``max_yaw_rate_rad_s``, the robot file's ``MaxYawRate``); refused, not capped, as
        every speed is here, and said in the message's fields before the boards' (or the
        simulator's) own words could reach the user. The yaw rate is a float32 field: the
        limit sent as one (1.745 is 1.7450000048) is at the limit, not over it. What a
        VELOCITY carries bounds the yaw rate too, should a vehicle's limit be over it
        (``wire_value`` says it in rad/s)."""
        vn, ve, vd, yaw_rate = given
        for name, value, unit in (("vx", vn, "m/s"), ("vy", ve, "m/s"), ("vz", vd, "m/s"),
                                  ("yaw_rate", yaw_rate, "rad/s")):
            if not math.isfinite(value):
                raise Refused(mav.MAV_RESULT_DENIED,
                              f"velocity setpoint: {name} {value:g} {unit} is not a finite number")
        limit = self.boards.settings.max_speed_m_s
        if _over(fwd, limit) or _over(right, limit):
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"velocity setpoint: vx {vn:g}, vy {ve:g} m/s is {fwd:.4g} m/s forward "
                          f"and {right:.4g} m/s right of the heading, over this vehicle's limit "
                          f"of {limit:g} m/s on each (MPC_XY_VEL_MAX)")
        climb = self.boards.settings.max_climb_m_s
        if _over(vd, climb):
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"velocity setpoint: vz {vd:g} m/s is over this vehicle's climb and "
                          f"descent limit of {climb:g} m/s")
        turn = self.boards.settings.max_yaw_rate_rad_s
        if _over(yaw_rate, turn):  # the limit itself, as sent, is at it
            raise Refused(mav.MAV_RESULT_DENIED,
                          f"velocity setpoint: yaw_rate {yaw_rate:g} rad/s is over this "
                          f"vehicle's limit of {turn:g} rad/s")
        wire_value(Velocity, "yaw_rate", yaw_rate, what="velocity setpoint: yaw_rate")

    def _manual(self, msg: MavMessage, peer: Hashable) -> list[MavMessage]:
        """MANUAL_CONTROL as the AscTec link's sticks in GPS mode (velocities)."""
        scale = lambda v: max(-2047, min(2047, round(float(v) * 2047 / 1000)))  # noqa: E731
        thrust = max(0, min(4095, round(max(0.0, float(msg.z)) * 4095 / 1000)))
        try:
            self._board(CtrlInput(-scale(msg.x), scale(msg.y), scale(msg.r), thrust,
                                  int(MANUAL_CTRL)))
        except Refused as exc:
            return self._notice(peer, f"manual:{exc}", mav.MAV_SEVERITY_WARNING,
                                f"sticks refused: {exc}")
        self._mine()
        return []

    # -- programs ------------------------------------------------------------------------
    def _start(self, program: Program) -> None:
        if self.program is Program.PRECLAND and program is not Program.PRECLAND:
            self.boards.pad.landing_finished()
        self.program = program
        self.step = Step(index=self.mission_current if program is Program.MISSION else 0)
        self.step.mark = self.boards.motion_changes

    def _stop_program(self, why: str) -> list[Out]:
        was = self.program
        self.program = Program.NONE
        if was is Program.MISSION:
            self.mission_state = mav.MISSION_STATE_PAUSED
        if was is Program.NONE:
            return []
        return [Out(m) for m in statustext(self.codec, mav.MAV_SEVERITY_NOTICE,
                                           f"{was.value} stopped: {why}")]

    def _start_mission(self, first: int) -> None:
        items = self.mission.items
        if not items:
            raise Refused(mav.MAV_RESULT_DENIED, "no mission uploaded")
        if not 0 <= first < len(items):
            raise Refused(mav.MAV_RESULT_DENIED, f"no mission item {first}")
        if not self._airborne() and items[first].command != mav.MAV_CMD_NAV_TAKEOFF:
            raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED,
                          "landed: the mission must start with a take-off item")
        self.mission_current = first
        self.mission_state = mav.MISSION_STATE_ACTIVE
        self._start(Program.MISSION)

    def _check_item(self, item: MissionItem) -> tuple[int, str] | None:
        """The vehicle's checks on a mission item: a position inside the flight envelope."""
        if item.command not in (mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_TAKEOFF,
                                mav.MAV_CMD_NAV_LOITER_TIME, mav.MAV_CMD_NAV_LAND):
            if item.command == mav.MAV_CMD_DO_CHANGE_SPEED:
                reason = self.boards.check_move(speed_m_s=self._at_most_the_limit(item.param2))
                if reason is not None:
                    return mav.MAV_MISSION_INVALID_PARAM2, f"item {item.seq}: {reason}"
            return None
        try:
            if item.x == 0 and item.y == 0:  # "here": where the vehicle will be, at its z;
                # the envelope's ceiling is checked above home
                target = (*self.boards.home_ned_m[:2], self._item_down(item))
            else:
                target = self._global_to_ned(item.x, item.y, item.z, item.frame)
        except Refused as exc:
            code = (mav.MAV_MISSION_INVALID_PARAM7 if str(exc).startswith("altitude")
                    else mav.MAV_MISSION_ERROR)
            return code, f"item {item.seq}: {exc}"
        reason = self.boards.check_move(target)
        if reason is not None:
            code = (mav.MAV_MISSION_INVALID_PARAM7 if "above" in reason or "below" in reason
                    else mav.MAV_MISSION_INVALID_PARAM5_X)
            return code, f"item {item.seq}: {reason}"
        return None

    def _item_down(self, item: MissionItem) -> float:
        """The NED down of a mission item's altitude (z in its frame): above home needs no GPS
        position (only its check against the lowest land does), above mean sea level does."""
        origin = self.origin()
        if origin is not None:
            return self._down_of(item.z, item.frame, origin)
        if item.relative_alt and math.isfinite(item.z):
            return self.boards.home_ned_m[2] - item.z
        raise Refused(mav.MAV_RESULT_TEMPORARILY_REJECTED,
                      "no GPS position yet: global targets cannot be placed")

    def _interrupted(self) -> bool:
        return self.boards.motion_changes != self.step.mark

    def _run_program(self, now_s: float) -> list[Out]:
        """One look at the running program: start its next step when the last one is done."""
        program = self.program
        if program is Program.NONE or program is Program.MANUAL:
            return []
        state = self.boards.state
        if program is Program.OFFBOARD:
            sp = self._setpoint
            if sp is None or now_s - sp[1] > self.settings.offboard_loss_s:
                out = self._stop_program("offboard setpoints lost: holding")
                if self._airborne():
                    try:
                        self._board(Hold())
                    except Refused:
                        pass
                return out
            if self._interrupted():
                return self._stop_program("another command took over")
            return []
        if self._interrupted():
            return self._stop_program("another command took over")
        if state is NavState.FAILSAFE:
            return self._stop_program("link-loss failsafe")
        try:
            if program is Program.PRECLAND:
                if state is NavState.LANDED:
                    self.program = Program.NONE
                return []
            if program is Program.RTL:
                return self._rtl_step(state)
            return self._mission_step(state, now_s)
        except (Refused, LocalProtocolError) as exc:
            return self._stop_program(str(exc))

    def _rtl_step(self, state: NavState) -> list[Out]:
        st = self.step
        if st.phase != "start" and state not in (NavState.HOLDING, NavState.LANDED):
            return []  # the current phase is still under way
        snap = self._snap()
        home = self.boards.home_ned_m
        n, e, d = snap.pos_ned_m
        if st.phase == "start":
            st.phase = "climb"
            climb_to = home[2] - self.settings.rtl_alt_m
            if d > climb_to + 0.05:
                self._fly_to((n, e, climb_to), None)
                self._mine()
                return []
        if st.phase == "climb":
            st.phase = "return"
            if math.hypot(home[0] - n, home[1] - e) > ARRIVED_RADIUS_M:
                self._fly_to((home[0], home[1], d), None)
                self._mine()
                return []
        if st.phase == "return":
            st.phase = "land"
            self._board(Land())
            self._mine()
            return []
        if st.phase == "land" and state is NavState.LANDED:
            self.program = Program.NONE
        return []

    def _mission_step(self, state: NavState, now_s: float) -> list[Out]:
        st = self.step
        items = self.mission.items
        snap = self._snap()
        if st.phase == "wait":
            if st.wait_until_s is not None and snap.time_s < st.wait_until_s:
                return []
            return self._item_done()
        if st.phase == "going":
            item = items[st.index]
            if item.command == mav.MAV_CMD_NAV_LAND:
                if state is NavState.LANDED:
                    return self._item_done()
                return []
            if state not in (NavState.HOLDING,):
                return []
            hold = item.param1 if item.command in (mav.MAV_CMD_NAV_WAYPOINT,
                                                   mav.MAV_CMD_NAV_LOITER_TIME) else 0.0
            if hold > 0 and math.isfinite(hold):
                st.phase, st.wait_until_s = "wait", snap.time_s + hold
                return []
            return self._item_done()
        if st.index >= len(items):
            return self._mission_complete()
        item = items[st.index]
        self.mission_current = st.index
        cmd = item.command
        if cmd == mav.MAV_CMD_DO_CHANGE_SPEED:
            self.cruise_m_s = (None if item.param2 in DEFAULT_SPEED
                               else self._at_most_the_limit(item.param2))
            return self._item_done()
        if cmd == mav.MAV_CMD_NAV_DELAY:
            st.phase, st.wait_until_s = "wait", snap.time_s + item.param1
            return []
        if cmd == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            out = self._reached(st.index)
            self.mission_state = mav.MISSION_STATE_COMPLETE
            self._start(Program.RTL)
            return out
        here = item.x == 0 and item.y == 0
        if cmd == mav.MAV_CMD_NAV_TAKEOFF and not self._airborne():
            if not self.armed:
                return []  # waits for the arming
            if item.relative_alt:
                height = item.z
            else:  # AMSL (0/0, "here", too): above where the vehicle stands
                down = (self._item_down(item) if here else
                        self._global_to_ned(item.x, item.y, item.z, item.frame)[2])
                height = snap.pos_ned_m[2] - down
            self._board(TakeOff(round(max(MIN_TAKE_OFF_M, height) * 1e3)))
            self._mine()
            st.phase = "going"
            return []
        if cmd == mav.MAV_CMD_NAV_LAND:
            if not here:
                target = self._global_to_ned(item.x, item.y, item.z, item.frame)
                n, e, d = snap.pos_ned_m
                if math.hypot(target[0] - n, target[1] - e) > ARRIVED_RADIUS_M:
                    self._fly_to((target[0], target[1], d), None)
                    self._mine()
                    st.phase = "to-land"
                    return []
            self._board(Land())
            self._mine()
            st.phase = "going"
            return []
        if st.phase == "to-land":
            return []
        target = ((snap.pos_ned_m[0], snap.pos_ned_m[1], self._item_down(item)) if here else
                  self._global_to_ned(item.x, item.y, item.z, item.frame))
        self._fly_to(target, None)
        self._mine()
        st.phase = "going"
        return []

    def _reached(self, seq: int) -> list[Out]:
        return [Out(self.codec.mav.mission_item_reached_encode(seq))]

    def _item_done(self) -> list[Out]:
        st = self.step
        out = self._reached(st.index)
        self.step = Step(index=st.index + 1, mark=st.mark)
        self.mission_current = min(st.index + 1, max(0, len(self.mission.items) - 1))
        out += self._on_change(telem.mission_current(self.codec, self.view()))
        return out

    def _mission_complete(self) -> list[Out]:
        self.program = Program.NONE
        self.mission_state = mav.MISSION_STATE_COMPLETE
        return [*self._on_change(telem.mission_current(self.codec, self.view())),
                *[Out(m) for m in statustext(self.codec, mav.MAV_SEVERITY_INFO,
                                             "mission complete")]]

    # -- time ----------------------------------------------------------------------------
    def on_pad(self, obs: PadObservation) -> None:
        """A pad detection from the vision (any thread): sent as LANDING_TARGET at the next
        tick."""
        if obs.found:
            self._targets.append(obs)

    def _landing_targets(self) -> list[Out]:
        out = []
        snap = None
        while self._targets:
            obs = self._targets.popleft()
            snap = snap or self._snap()
            out.append(Out(landing_target(self.codec, obs, snap.rpy_rad[2])))
            self.landing_targets += 1
        return out

    def tick(self, now_s: float) -> list[Out]:
        """Streams due, programs advanced, timers checked."""
        self._now_s = now_s
        out: list[Out] = []
        state = self.boards.state
        if self._armed_at_s is not None:
            if state is not NavState.LANDED or not self.boards.motors_on:
                self._armed_at_s = None
            elif (self.settings.disarm_preflight_s > 0
                  and now_s - self._armed_at_s >= self.settings.disarm_preflight_s):
                self.boards.motors_on = False
                self._armed_at_s = None
                out += [Out(m) for m in statustext(
                    self.codec, mav.MAV_SEVERITY_NOTICE,
                    "disarmed: no take-off within COM_DISARM_PRFLT")]
        if self.program is Program.PRECLAND and self.boards.pad.mode is not PadAction.LAND \
                and state is not NavState.LANDING:
            out += self._stop_program("the pad landing mode was changed")
        out += self._run_program(now_s)
        route = self.mission.upload_route  # an upload's re-requests are its station's alone
        link_of, peer_of = route if isinstance(route, tuple) else (None, None)
        out += [Out(m, link_of, peer_of) for m in self.mission.tick(now_s)]
        out += self._landing_targets()
        view = None
        status = (self.mode, self.armed, self.boards.state)
        changed = status != self._status
        self._status = status
        for i, link in enumerate(self.links):
            due = link.scheduler.due(now_s)
            if changed and mav.MAVLINK_MSG_ID_HEARTBEAT not in due \
                    and link.scheduler.interval_s(mav.MAVLINK_MSG_ID_HEARTBEAT) is not None:
                due.append(mav.MAVLINK_MSG_ID_HEARTBEAT)  # a new mode is told at once
            if not due:
                continue
            view = view or self.view()
            for msg_id in due:
                msg = telem.BUILDERS[msg_id](self.codec, view)
                if msg is not None:
                    out.append(Out(msg, i))
        out += self._origin_news(now_s, view)
        for src, seen in list(self.gcs.items()):
            if now_s - seen > GCS_TIMEOUT_S:
                del self.gcs[src]
        for system, seen in list(self.vehicles.items()):
            if now_s - seen > GCS_TIMEOUT_S:
                del self.vehicles[system]
        return out

    def _origin_news(self, now_s: float, view: telem.VehicleView | None) -> list[Out]:
        """GPS_GLOBAL_ORIGIN on every link when the origin is first known or has moved (as
        PX4's stream sends it), but where SET_MESSAGE_INTERVAL -1 stopped it."""
        if now_s < self._origin_check_s:
            return []
        self._origin_check_s = now_s + ORIGIN_CHECK_S
        view = view or self.view()
        new, old = view.origin, self._origin_told
        if new is None or (old is not None
                           and abs(new.latitude_deg - old.latitude_deg) <= ORIGIN_MIN_DEG
                           and abs(new.longitude_deg - old.longitude_deg) <= ORIGIN_MIN_DEG
                           and abs(new.altitude_m - old.altitude_m) <= ORIGIN_MIN_ALT_M):
            return []
        msg = telem.gps_global_origin(self.codec, view)
        if msg is None:
            return []
        self._origin_told = new
        return self._on_change(msg)

    def _on_change(self, msg: MavMessage) -> list[Out]:
        """A streamed message sent because its content changed: on every link but those where
        SET_MESSAGE_INTERVAL -1 stopped it."""
        msg_id = msg.get_msgId()
        return [Out(msg, i) for i, link in enumerate(self.links)
                if msg_id not in link.scheduler.stopped]


def _remember(memory: dict[K, V], key: K, value: V, stamp_s: Callable[[V], float],
              now_s: float, keep_s: float, most: int) -> None:
    """``memory[key] = value``, as its newest entry, and the entries that can no longer matter
    forgotten, oldest first: those ``keep_s`` old (a repeat or a notice is looked for only
    within it), then any beyond ``most`` (a flood of stations within ``keep_s``). A live
    station's recent entry is never forgotten for stale ones (the memory was once cleared
    whole when full, so a take-off resent just then was run again)."""
    memory.pop(key, None)
    memory[key] = value  # a dict keeps insertion order: oldest first
    while len(memory) > 1:
        first = next(iter(memory))
        if now_s - stamp_s(memory[first]) < keep_s and len(memory) <= most:
            break
        del memory[first]


QUERIES = (mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_GET_MESSAGE_INTERVAL,
           mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES)
"""Commands that change nothing and whose answer is a message: run again when repeated within
``DUPLICATE_WINDOW_S`` (a repeat is a client that did not get the message, or wants it again)."""

COMMANDS: dict[int, Callable[[MavlinkVehicle, Command], list[MavMessage] | None]] = {
    mav.MAV_CMD_COMPONENT_ARM_DISARM: MavlinkVehicle._arm,
    mav.MAV_CMD_NAV_TAKEOFF: MavlinkVehicle._takeoff,
    mav.MAV_CMD_NAV_LAND: MavlinkVehicle._land,
    mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: MavlinkVehicle._rtl,
    mav.MAV_CMD_DO_REPOSITION: MavlinkVehicle._reposition,
    mav.MAV_CMD_DO_CHANGE_SPEED: MavlinkVehicle._change_speed,
    mav.MAV_CMD_DO_SET_MODE: MavlinkVehicle._set_mode,
    mav.MAV_CMD_MISSION_START: MavlinkVehicle._mission_start,
    mav.MAV_CMD_DO_SET_MISSION_CURRENT: MavlinkVehicle._set_current_cmd,
    mav.MAV_CMD_SET_MESSAGE_INTERVAL: MavlinkVehicle._message_interval,
    mav.MAV_CMD_GET_MESSAGE_INTERVAL: MavlinkVehicle._get_interval,
    mav.MAV_CMD_REQUEST_MESSAGE: MavlinkVehicle._request_message,
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: MavlinkVehicle._capabilities,
}
"""The commands this vehicle flies (COMMAND_LONG or COMMAND_INT); any other is UNSUPPORTED."""
