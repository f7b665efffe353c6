"""``Airframe`` over MAVLink: the pilot as the companion computer of a PX4-style flight
controller (``mavlink://`` airframe URIs; PX4's Offboard mode, not ArduPilot's GUIDED).

How this works: :class:`MavlinkAirframe` owns one MAVLink link to the flight controller
(``skeye.mavlink.transport``) and one worker thread (``airframe-mavlink``) that alone reads and
writes it. The thread keeps the newest of each telemetry message (HEARTBEAT, ATTITUDE,
LOCAL_POSITION_NED, HIGHRES_IMU, GPS_RAW_INT, SYS_STATUS, EXTENDED_SYS_STATE, VFR_HUD), from
which :meth:`snapshot` builds the boards' ``Snapshot`` (positions in the controller's local NED
frame; times on this computer's monotonic clock, the clock a camera source stamps its frames
with: the controller's boot time plus the smallest offset between the two seen over the last
``OFFSET_WINDOW`` ATTITUDE messages, the one least delayed by the link, as the ``sim://`` camera
maps the simulator's time; LANDING_TARGET goes back in the controller's boot time); it sends
this computer's HEARTBEAT every second, the offboard setpoint every ``setpoint_period_s`` (PX4
drops out of offboard below 2 Hz), and commands one at a time, each resent until its
COMMAND_ACK (at most ``retries`` times). The boards' calls never wait on the link: they set the
setpoint or queue commands and return.

Flying: ``take_off`` arms and sends NAV_TAKEOFF (altitude above mean sea level, from the
controller's own GLOBAL_POSITION_INT); once the controller holds at the height, every motion is
offboard: ``fly_to`` and ``hover`` stream a position setpoint (LOCAL_NED), ``set_velocity``
velocities (BODY_NED, yaw rate), and the first one switches the controller to OFFBOARD
(DO_SET_MODE, PX4's custom mode 6). ``land`` sends NAV_LAND. ``busy`` is True while a take-off
climbs, a ``fly_to`` has not arrived (within ``arrive_m`` and below ``settle_m_s``) or a landing
has not touched down. Stick input (``attitude``) is refused: a flight controller takes sticks
from its own radio. A controller silent for ``lost_after_s`` is lost (:attr:`lost`): the
pilot's failsafe applies. Pad detections go to the controller as LANDING_TARGET
(:meth:`landing_target`), for its precision landing.
"""

from __future__ import annotations

import logging
import math
import selectors
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from pymavlink.dialects.v20 import common as mav

from skeye.errors import ConfigError, LinkClosed, SkeyeError
from skeye.mavlink.codec import BadFrame, MavCodec, MavParser
from skeye.mavlink.modes import Px4Mode
from skeye.mavlink.transport import MavTransport, SerialOpenError, open_transport
from skeye.pilot.airframe import (
    AirframeOptions,
    GpsFix,
    Snapshot,
    VehicleLimits,
    vehicle_limits,
)
from skeye.pilot.pad import PadObservation
from skeye.uris import query_of, split_uri
from skeye.workers import Worker

log = logging.getLogger(__name__)

ONBOARD_COMPUTER = mav.MAV_COMP_ID_ONBOARD_COMPUTER  # 191
POSITION_ONLY = 0b0000_1101_1111_1000  # SET_POSITION_TARGET type_mask: x, y, z (yaw ignored)
VELOCITY_ONLY = 0b0000_0101_1100_0111  # vx, vy, vz and yaw rate
# What start() waits for: the snapshot's attitude, position and battery (SYS_STATUS: PX4 and
# ArduPilot send it on every link by default). HIGHRES_IMU is asked for but not waited on.
READY_MESSAGES = ("HEARTBEAT", "ATTITUDE", "LOCAL_POSITION_NED", "SYS_STATUS")
UINT16_MAX = 65535
OFFSET_WINDOW = 50  # ATTITUDE messages whose clock offsets count: 1 s at the 50 Hz asked for
STREAMS_HZ = {  # asked of the controller with SET_MESSAGE_INTERVAL
    mav.MAVLINK_MSG_ID_ATTITUDE: 50.0,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 50.0,
    mav.MAVLINK_MSG_ID_HIGHRES_IMU: 20.0,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 10.0,
}


@dataclass
class _Pending:
    """A command waiting for its COMMAND_ACK."""

    msg: Any
    command: int
    sent_s: float = -math.inf
    tries: int = 0


class MavlinkAirframe:
    """A flight controller over MAVLink, as the boards' ``Airframe`` (and the pilot's
    ``mavlink://`` backend: :func:`open_mavlink_backend`)."""

    lockstep = False  # the controller keeps its own time
    clock_is_sim = False  # snapshot times are this computer's monotonic clock
    uri = "mavlink://"
    limits = VehicleLimits()
    """The speed limits the boards check commands against: skeye's defaults (3 m/s, climb
    1.5 m/s, yaw 100 deg/s), the backend's the robot file's (``--robot``; the Hummingbird's are
    these); below PX4's own (MPC_XY_VEL_MAX 12 m/s ...), which the controller applies on top
    (docs/protocols/mavlink.md)."""

    def __init__(
        self,
        transport: MavTransport,
        *,
        target_system: int = 1,
        target_component: int = 1,
        setpoint_period_s: float = 0.05,
        arrive_m: float = 0.15,
        settle_m_s: float = 0.15,
        lost_after_s: float = 3.0,
        ack_timeout_s: float = 0.5,
        retries: int = 5,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.transport = transport
        self.codec = MavCodec(target_system, ONBOARD_COMPUTER)  # the vehicle's id, comp 191
        self.target = (target_system, target_component)
        self.setpoint_period_s = setpoint_period_s
        self.arrive_m = arrive_m
        self.settle_m_s = settle_m_s
        self.lost_after_s = lost_after_s
        self.ack_timeout_s = ack_timeout_s
        self.retries = retries
        self.clock = clock
        self._lock = threading.Lock()
        self._latest: dict[str, Any] = {}
        self._heard_s: float | None = None
        self._offsets: deque[float] = deque(maxlen=OFFSET_WINDOW)  # clock() - boot time, s
        self._parser = MavParser()
        self._commands: list[_Pending] = []
        self._raw: list[Any] = []  # messages to send once (PARAM_SET)
        self._setpoint: Any = None  # SET_POSITION_TARGET_LOCAL_NED to stream, or None
        self._offboard_wanted = False
        self._motion: str | None = None  # "takeoff", "goto", "land", "turn" while busy
        self._goal: tuple[float, float, float] | None = None
        self._motion_since_s = 0.0
        self._velocity_until_s: float | None = None
        self.refusals: list[str] = []  # COMMAND_ACKs that were not ACCEPTED, newest last
        self.statustexts: list[str] = []
        self.landing_targets = 0
        self._targets: list[PadObservation] = []
        self._stop = threading.Event()
        self._worker: Worker | None = None

    # -- lifecycle ---------------------------------------------------------------------------
    def start(self, wait_s: float = 30.0) -> MavlinkAirframe:
        """Start the link thread and wait for the controller's attitude, position and status
        (raises ``LinkClosed`` naming the link and what is missing if they do not all come
        within ``wait_s``): a snapshot is whole from the start, its battery voltage included."""
        if self._worker is None:
            self._worker = Worker(self._run, "airframe-mavlink").start()
        deadline = self.clock() + wait_s
        while not self._ready():
            self.check()
            if self.clock() > deadline:
                with self._lock:
                    missing = [k for k in READY_MESSAGES if k not in self._latest]
                raise LinkClosed(f"no flight controller on {self.transport.name} within "
                                 f"{wait_s:g} s (waited for {', '.join(READY_MESSAGES)}; "
                                 f"missing {', '.join(missing)})")
            time.sleep(0.02)
        return self

    def _ready(self) -> bool:
        with self._lock:
            return all(k in self._latest for k in READY_MESSAGES)

    def check(self) -> None:
        if self._worker is not None:
            self._worker.check()

    def close(self, timeout_s: float = 2.0) -> None:
        self._stop.set()
        if self._worker is not None:
            self._worker.join(timeout_s)
        self.transport.close()

    @property
    def control_period_s(self) -> float:
        """How often the set-points stream (the pilot ticks at this in lockstep; here never)."""
        return self.setpoint_period_s

    def describe(self) -> str:
        return f"a MAVLink flight controller on {self.transport.name} (offboard control)"

    def reset(self) -> str:
        """RESET of a real vehicle: nothing to respawn (a crashed one is put back on its feet
        by hand); on the ground it stands LANDED again."""
        return f"{self.describe()}: a real vehicle, nothing to reset"

    def __enter__(self) -> MavlinkAirframe:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the link thread -------------------------------------------------------------------
    def _run(self) -> None:
        selector = selectors.DefaultSelector()
        for f in self.transport.fileobjs():
            selector.register(f, selectors.EVENT_READ)
        next_hb = next_sp = self.clock()
        asked_streams = False
        try:
            while not self._stop.is_set():
                selector.select(0.01)
                for data, _peer in self.transport.poll():
                    for msg in self._parser.feed(data, datagram=self.transport.datagram):
                        if not isinstance(msg, BadFrame):
                            self._receive(msg)
                now = self.clock()
                out: list[Any] = []
                if now >= next_hb:
                    next_hb = now + 1.0
                    out.append(self.codec.mav.heartbeat_encode(
                        mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID, 0, 0,
                        mav.MAV_STATE_ACTIVE, 3))
                    if not asked_streams and self._heard_s is not None:
                        asked_streams = True
                        for msg_id, hz in STREAMS_HZ.items():
                            self._queue(mav.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)
                with self._lock:
                    out += self._raw
                    self._raw = []
                    until = self._velocity_until_s
                    if until is not None and now >= until:  # a timed velocity ran out: hold
                        self._velocity_until_s = None
                        pos = self._latest["LOCAL_POSITION_NED"]
                        self._setpoint = self._position_setpoint(pos.x, pos.y, pos.z)
                        if self._motion == "turn":
                            self._motion = None
                    out += self._due_commands(now)
                    sp = self._setpoint
                    if sp is not None and now >= next_sp:
                        next_sp = now + self.setpoint_period_s
                        out.append(sp)
                    out += self._due_mode(now)
                    targets, self._targets = self._targets, []
                    yaw = self._latest["ATTITUDE"].yaw if "ATTITUDE" in self._latest else 0.0
                    offset = self._offset_s()
                for obs in targets:
                    from skeye.pilot.mavlink_types import landing_target

                    boot = replace(obs, frame_time_s=max(0.0, obs.frame_time_s - offset))
                    out.append(landing_target(self.codec, boot, yaw))
                    self.landing_targets += 1
                for msg in out:
                    self.transport.send(self.codec.encode(msg))
        finally:
            selector.close()

    def _receive(self, msg: Any) -> None:
        if (msg.get_srcSystem(), msg.get_srcComponent()) != self.target:
            return
        kind = msg.get_type()
        with self._lock:
            self._heard_s = self.clock()
            if kind == "ATTITUDE":
                previous = self._latest.get("ATTITUDE")
                if previous is not None and msg.time_boot_ms + 1000 < previous.time_boot_ms:
                    self._offsets.clear()  # the controller rebooted: its clock starts again
                self._offsets.append(self._heard_s - msg.time_boot_ms / 1e3)
            self._latest[kind] = msg
            if kind == "COMMAND_ACK":
                for p in self._commands[:1]:
                    if p.command == msg.command:
                        self._commands.pop(0)
                        if msg.result != mav.MAV_RESULT_ACCEPTED:
                            self._refused(f"command {msg.command} refused ({msg.result})")
            elif kind == "STATUSTEXT":
                self.statustexts = [*self.statustexts[-49:], str(msg.text)]

    def _refused(self, why: str) -> None:
        """A command was refused: the motion it was for is over (the boards see not busy)."""
        log.warning("flight controller: %s", why)
        self.refusals = [*self.refusals[-49:], why]
        if self._motion in ("takeoff", "land"):
            self._motion = None

    def _due_commands(self, now: float) -> list[Any]:
        if not self._commands:
            return []
        p = self._commands[0]
        if now - p.sent_s < self.ack_timeout_s:
            return []
        if p.tries >= self.retries:
            self._commands.pop(0)
            self._refused(f"command {p.command} unanswered after {p.tries} tries")
            return []
        p.tries += 1
        p.sent_s = now
        return [p.msg]

    def _due_mode(self, now: float) -> list[Any]:
        """Ask for OFFBOARD while setpoints stream and the controller is in another mode."""
        hb = self._latest.get("HEARTBEAT")
        if not self._offboard_wanted or hb is None or self._setpoint is None:
            return []
        if hb.custom_mode == Px4Mode.OFFBOARD.custom_mode:
            return []
        if any(p.command == mav.MAV_CMD_DO_SET_MODE for p in self._commands):
            return []
        main, sub = Px4Mode.OFFBOARD.value
        self._queue_locked(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                           int(main), sub)
        return []

    def _queue(self, command: int, *params: float) -> None:
        with self._lock:
            self._queue_locked(command, *params)

    def _queue_locked(self, command: int, *params: float) -> None:
        p = [*params, *([0.0] * (7 - len(params)))]
        msg = self.codec.mav.command_long_encode(*self.target, command, 0, *p)
        self._commands.append(_Pending(msg, command))

    # -- readings --------------------------------------------------------------------------
    @property
    def lost(self) -> str | None:
        """Why the flight controller counts as gone (silent too long), or None."""
        heard = self._heard_s
        if heard is None or self.clock() - heard < self.lost_after_s:
            return None
        return (f"flight controller silent for {self.clock() - heard:.1f} s on "
                f"{self.transport.name}")

    def _offset_s(self) -> float:
        """This computer's clock minus the controller's boot time (call with the lock held)."""
        return min(self._offsets) if self._offsets else 0.0

    def snapshot(self) -> Snapshot:
        with self._lock:
            m = dict(self._latest)
            offset = self._offset_s()
        att, pos = m.get("ATTITUDE"), m.get("LOCAL_POSITION_NED")
        if att is None or pos is None:
            raise SkeyeError(f"no attitude and position from the flight controller on "
                             f"{self.transport.name} yet")
        imu, gps, status = m.get("HIGHRES_IMU"), m.get("GPS_RAW_INT"), m.get("SYS_STATUS")
        ext, hud, hb = m.get("EXTENDED_SYS_STATE"), m.get("VFR_HUD"), m.get("HEARTBEAT")
        fix = None
        if gps is not None:
            ok = gps.fix_type >= mav.GPS_FIX_TYPE_3D_FIX
            vel = (0.0, 0.0, 0.0)
            if ok and gps.vel != 65535 and gps.cog != 65535:
                v = gps.vel / 100.0
                cog = math.radians(gps.cog / 100.0)
                vel = (v * math.cos(cog), v * math.sin(cog), 0.0)
            fix = GpsFix(ok, int(gps.satellites_visible), gps.lat / 1e7, gps.lon / 1e7,
                         gps.alt / 1e3, vel)
        landed = ext.landed_state == mav.MAV_LANDED_STATE_ON_GROUND if ext else True
        return Snapshot(
            time_s=att.time_boot_ms / 1e3 + offset,
            pos_ned_m=(pos.x, pos.y, pos.z),
            rpy_rad=(att.roll, att.pitch, att.yaw),
            vel_ned_m_s=(pos.vx, pos.vy, pos.vz),
            rates_frd_rad_s=(att.rollspeed, att.pitchspeed, att.yawspeed),
            specific_force_frd_m_s2=((imu.xacc, imu.yacc, imu.zacc) if imu
                                     else (0.0, 0.0, -9.80665)),
            mag_field_frd_ut=((imu.xmag * 100, imu.ymag * 100, imu.zmag * 100) if imu
                              else (0.0, 0.0, 0.0)),
            mag_heading_rad=att.yaw,
            baro_pressure_pa=imu.abs_pressure * 100 if imu else 101325.0,
            baro_altitude_m=imu.pressure_alt if imu else -pos.z,
            baro_climb_m_s=-pos.vz,
            gps=fix,
            # UINT16_MAX: the controller measures no voltage (0 V: unknown, as before any status)
            battery_v=(status.voltage_battery / 1e3
                       if status and status.voltage_battery != UINT16_MAX else 0.0),
            armed=bool(hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED) if hb else False,
            landed=landed,
            thrust_fraction=hud.throttle / 100.0 if hud else 0.0,
        )

    @property
    def busy(self) -> bool:
        with self._lock:
            motion = self._motion
            m = dict(self._latest)
            since = self._motion_since_s
            goal = self._goal
        if motion is None:
            return False
        snap = self.snapshot()
        hb, ext = m.get("HEARTBEAT"), m.get("EXTENDED_SYS_STATE")
        settled = math.hypot(*snap.vel_ned_m_s) < self.settle_m_s
        if motion == "takeoff":
            climbing = hb is not None and hb.custom_mode == Px4Mode.TAKEOFF.custom_mode
            in_air = ext is not None and ext.landed_state == mav.MAV_LANDED_STATE_IN_AIR
            done = in_air and not climbing and self.clock() - since > 0.5
        elif motion == "land":
            done = snap.landed and self.clock() - since > 0.5
        elif motion == "turn":
            done = False  # the link thread ends it when its time has run out
        elif goal is not None:
            done = math.dist(snap.pos_ned_m, goal) < self.arrive_m and settled
        else:
            done = True
        if done:
            with self._lock:
                if self._motion == motion:
                    self._motion = None
        return not done

    # -- commands --------------------------------------------------------------------------
    def _start(self, motion: str | None, goal: tuple[float, float, float] | None = None) -> None:
        with self._lock:
            self._motion = motion
            self._goal = goal
            self._motion_since_s = self.clock()
            self._velocity_until_s = None

    def _position_setpoint(self, north: float, east: float, down: float) -> Any:
        return self.codec.mav.set_position_target_local_ned_encode(
            0, *self.target, mav.MAV_FRAME_LOCAL_NED, POSITION_ONLY, north, east, down,
            0, 0, 0, 0, 0, 0, 0, 0)

    def take_off(self, altitude_m: float) -> None:
        snap = self.snapshot()
        with self._lock:
            gpos = self._latest.get("GLOBAL_POSITION_INT")
        amsl = math.nan
        if gpos is not None:
            amsl = gpos.alt / 1e3 + (altitude_m - (-snap.pos_ned_m[2]))
        self._start("takeoff")
        with self._lock:
            self._setpoint = None
            self._offboard_wanted = False
            self._queue_locked(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            if math.isnan(amsl):  # no global position: the controller's MIS_TAKEOFF_ALT
                height = altitude_m + snap.pos_ned_m[2]
                self._raw.append(self.codec.mav.param_set_encode(
                    *self.target, b"MIS_TAKEOFF_ALT", height, mav.MAV_PARAM_TYPE_REAL32))
            self._queue_locked(mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, amsl)

    def fly_to(self, north_m: float, east_m: float, altitude_m: float, speed_m_s: float) -> None:
        goal = (north_m, east_m, -altitude_m)
        self._start("goto", goal)
        with self._lock:
            self._queue_locked(mav.MAV_CMD_DO_CHANGE_SPEED, 1, speed_m_s, -1, 0)
            self._setpoint = self._position_setpoint(*goal)
            self._offboard_wanted = True

    def fly_to_gps(self, latitude_deg: float, longitude_deg: float, altitude_m: float,
                   speed_m_s: float) -> None:
        snap = self.snapshot()
        with self._lock:
            gpos = self._latest.get("GLOBAL_POSITION_INT")
        if gpos is None:
            raise SkeyeError("no global position from the flight controller: GPS targets "
                             "cannot be placed")
        from skeye.geo import GeoOrigin

        here = GeoOrigin(gpos.lat / 1e7, gpos.lon / 1e7)
        dn, de, _ = here.to_ned(latitude_deg, longitude_deg, 0.0)
        self.fly_to(snap.pos_ned_m[0] + dn, snap.pos_ned_m[1] + de, altitude_m, speed_m_s)

    def turn_by(self, yaw_rad: float) -> None:
        """A yaw rate of 0.5 rad/s for as long as the turn takes, then a hold."""
        rate = math.copysign(0.5, yaw_rad)
        self.set_velocity(0.0, 0.0, 0.0, rate, abs(yaw_rad) / 0.5)
        with self._lock:
            self._motion = "turn"

    def set_velocity(self, forward_m_s: float, right_m_s: float, up_m_s: float,
                     yaw_rate_rad_s: float, duration_s: float | None, *,
                     gps_mode: bool = False) -> None:
        sp = self.codec.mav.set_position_target_local_ned_encode(
            0, *self.target, mav.MAV_FRAME_BODY_NED, VELOCITY_ONLY, 0, 0, 0,
            forward_m_s, right_m_s, -up_m_s, 0, 0, 0, 0, yaw_rate_rad_s)
        self._start(None)
        with self._lock:
            self._setpoint = sp
            self._offboard_wanted = True
            self._velocity_until_s = None if duration_s is None else self.clock() + duration_s

    def hover(self) -> None:
        n, e, d = self.snapshot().pos_ned_m
        self._start(None)
        with self._lock:
            if self._latest.get("EXTENDED_SYS_STATE") is not None and \
                    self._latest["EXTENDED_SYS_STATE"].landed_state != \
                    mav.MAV_LANDED_STATE_IN_AIR:
                return  # nothing to hold on the ground
            self._setpoint = self._position_setpoint(n, e, d)
            self._offboard_wanted = True

    def land(self) -> None:
        self._start("land")
        with self._lock:
            self._setpoint = None
            self._offboard_wanted = False
            self._queue_locked(mav.MAV_CMD_NAV_LAND, 0, 0, 0, math.nan)

    def attitude(self, roll_rad: float, pitch_rad: float, yaw_rate_rad_s: float,
                 thrust_fraction: float, height_mode: bool = False) -> None:
        raise SkeyeError("stick input is not flown through a MAVLink flight controller: it "
                         "takes sticks from its own radio")

    def advance(self, seconds: float) -> None:
        """The controller keeps its own time: nothing to advance."""
        self.check()

    def landing_target(self, obs: PadObservation) -> None:
        """Forward a pad detection to the controller as LANDING_TARGET (any thread)."""
        if obs.found:
            with self._lock:
                self._targets.append(obs)


LINK_OPTIONS: dict[str, set[str]] = {"udp": set(), "udpout": {"bind"}, "tcp": set(),
                                     "serial": {"baud"}}
"""The options each ``mavlink://`` link kind takes (those of its ``skeye.mavlink.transport``
link)."""


def open_mavlink_airframe(uri: str, **options: Any) -> MavlinkAirframe:
    """A started :class:`MavlinkAirframe` for ``mavlink://KIND/ADDRESS``:

    - ``mavlink://udp/HOST:PORT``: listen on HOST:PORT for the controller (it sends there, as
      PX4 sends to 14540 and ``skeye pilot --mavlink udpout://HOST:PORT`` does);
    - ``mavlink://udpout/HOST:PORT``: send to a controller listening there
      (``skeye pilot --mavlink udp://HOST:PORT``), from 127.0.0.1 unless ``?bind=ADDR`` names
      the address to send from (a controller on another machine needs it);
    - ``mavlink://tcp/HOST:PORT``: connect to a controller's TCP port;
    - ``mavlink://serial/dev/ttyACM0?baud=921600``: a serial line (a flight controller's
      TELEM port).

    ``options`` go to :class:`MavlinkAirframe` (``wait_s`` to :meth:`MavlinkAirframe.start`).

    Raises:
        ConfigError: a URI that is not one of these, or with an option its link does not take
            (:data:`LINK_OPTIONS`) or anything after HOST:PORT.
        LinkClosed: no flight controller answered within ``wait_s``, or a serial device that
            cannot be opened (not there, or held by another program).
    """
    parts = split_uri(uri, "airframe", "mavlink://udp/HOST:PORT (or udpout, tcp, serial)",
                      ConfigError)
    if parts.scheme != "mavlink" or not parts.netloc:
        raise ConfigError(f"{uri}: a MAVLink airframe is mavlink://udp/HOST:PORT, "
                          "mavlink://udpout/HOST:PORT, mavlink://tcp/HOST:PORT or "
                          "mavlink://serial/DEVICE?baud=N")
    kind = parts.netloc.lower()
    rest = parts.path.lstrip("/")
    query = f"?{parts.query}" if parts.query else ""
    links = {"udp": f"udp://{rest}", "udpout": f"udpout://{rest}{query}",
             "tcp": f"tcpout://{rest}", "serial": f"serial:///{rest}{query}"}
    if kind not in links:
        raise ConfigError(f"{uri}: unknown MAVLink link kind {kind!r} (udp, udpout, tcp, "
                          "serial)")
    # Each option is the link's or refused: one dropped in silence (udpout's bind, a baud
    # typed as speed) showed only as no controller answering, after the whole wait.
    takes = LINK_OPTIONS[kind]
    unknown = sorted(set(query_of(uri, parts, "airframe", ConfigError)) - takes)
    if unknown:
        raise ConfigError(f"{uri}: option(s) {unknown} are not for a {kind} link (it takes "
                          f"{', '.join(sorted(takes)) or 'none'})")
    if kind != "serial" and "/" in rest:
        raise ConfigError(f"{uri}: {kind} is mavlink://{kind}/HOST:PORT, with nothing after "
                          f"the port ({rest[rest.index('/'):]!r})")
    wait_s = float(options.pop("wait_s", 30.0))
    try:
        transport = open_transport(links[kind])
    except SerialOpenError as exc:  # the vehicle's line: unreachable, as asctec-ll://serial's
        raise LinkClosed(f"{uri}: {exc}") from None
    airframe = MavlinkAirframe(transport, **options)
    try:
        return airframe.start(wait_s)
    except BaseException:
        airframe.close()
        raise


def open_mavlink_backend(uri: str, options: AirframeOptions) -> MavlinkAirframe:
    """The ``mavlink://`` airframe backend (``skeye pilot --airframe mavlink://...``): waits
    up to ``options.timeout_s`` for the controller. Its speed limits are the robot file's
    (``--robot``, ``--robot-dir``), as on the other airframes.

    Raises:
        ConfigError: the robot class has no readable file (before the link opens), or a URI
            :func:`open_mavlink_airframe` refuses.
        LinkClosed: no flight controller answered.
    """
    try:
        limits = vehicle_limits(options.robot, options.robot_dirs)
    except ConfigError as exc:
        raise ConfigError(f"airframe {uri}: the speed limits come from the robot file "
                          f"(--robot, --robot-dir): {exc}") from None
    airframe = open_mavlink_airframe(uri, wait_s=options.timeout_s)
    airframe.uri = uri
    airframe.limits = limits
    return airframe
