"""One control connection of the simulator: its threads, its states and its commands.

How this works: the control server (:mod:`skeye.sim.server`) hands each accepted socket to a
:class:`ClientSession` with two threads: a reader that decodes lines with the sans-IO codec
(:mod:`skeye.wire.sim_lines`, then the typed table of :mod:`skeye.wire.sim`) and handles them,
and a writer that alone writes to the socket, draining a bounded queue. The engine thread hands
the robot's readings to the session's sink (a :class:`skeye.sim.stream.StreamEncoder`), which
queues their lines without ever blocking: when a client does not read, its queue fills and further
stream lines are dropped and counted, so a slow client never slows the physics or other
clients. Answers (RES, ERR, GEO, CONF, NFO; the engine's ERR lines of a robot stopped or
crashed too, split out of its chunk of stream lines in their place) go through the same
queue, so their order relative to the stream is kept; they have room of their own
(``OUTBOX_BYTES // 8``), which the stream never takes: a backlog of stream lines never costs
a client an answer it waits for (a STEP's RES, an ERR of its robot's crash), while one that
floods commands and reads nothing loses the answers beyond that room.
Every bad line gets an ``ERR`` with a reason and the connection stays usable; only an
over-long line closes it, and so does an HTTP request line or header. A
session that ends gives its writer ``CLOSE_LINGER_S`` to send what is queued, then shuts the
socket: a client that reads nothing cannot keep a thread and a socket after its slot is freed.

The connection's states are a transition table (:data:`TRANSITIONS`, :class:`ConnectionStates`,
sans-IO): a new connection awaits its first line (``AWAITING``), then has no robot
(``OPEN``) until an INIT succeeds (``BOUND``: one robot per connection), and ends ``CLOSED``.
Which commands each state refuses, and how long each may stay quiet, are tables too.
"""

from __future__ import annotations

import enum
import logging
import math
import os
import queue
import re
import select
import selectors
import socket
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, Protocol

from skeye.errors import ConfigError, LocalProtocolError, RemoteProtocolError, SkeyeError
from skeye.sim.cameras import set_camera_fov
from skeye.sim.clock_barrier import ClockBarrier, fail_step
from skeye.sim.engine import Simulation
from skeye.sim.readings import Event, RobotCrashed, RobotStopped
from skeye.sim.robot import Robot
from skeye.sim.runner import SimulationRunner
from skeye.sim.stream import StreamEncoder
from skeye.wire.sim import (
    DriveLimits,
    decode,
    drive_in_si,
    encode,
    parse_value,
    unknown_command,
    usarsim_notes,
)
from skeye.wire.sim_lines import LineDecoder, LineError, Message
from skeye.wire.sim_messages import (
    Conf,
    Drive,
    Err,
    Geo,
    GetConf,
    GetGeo,
    GetStartPoses,
    Init,
    Ping,
    Res,
    Reset,
    RobotConf,
    Set,
    StartPoses,
    Step,
)
from skeye.wire.wind import make_settings, parse_params
from skeye.workers import Worker

log = logging.getLogger(__name__)

OUTBOX_BYTES = 8 * 1024 * 1024  # per client: the stream lines a client that stops reading holds
# (its answers have an eighth of it more: a client that stops reading costs at most 9 MiB)
STEP_TIMEOUT_S = 3600.0  # a lockstep STEP waits this long to be taken up (then as long to end)
STEP_WATCH_AFTER_S = 0.05  # a STEP still running after this: its reader watches for the client
# poll() events of a socket whose peer is gone: it closed (or shut its sending side), or reset.
# POLLRDHUP (the peer's FIN) is Linux's; elsewhere a reset or hang-up is still seen.
_PEER_GONE = getattr(select, "POLLRDHUP", 0) | select.POLLHUP | select.POLLERR
CLOSE_LINGER_S = 5.0  # an ended session's writer has this long to send what is queued
# An HTTP request line or header: a web page POSTing to this port (a cross-protocol request, whose
# text/plain body would otherwise be read as protocol lines). The connection is closed at once.
_HTTP_LINE = re.compile(
    r"^(?:(?:GET|POST|PUT|DELETE|HEAD|OPTIONS|PATCH|CONNECT|TRACE) \S+ HTTP/\d|"
    r"(?:Host|Origin|Content-Type|User-Agent|Content-Length):)", re.IGNORECASE)
_CLOSE: tuple[bytes, bool] = (b"", False)  # the writer's last item

# (connection id, direction "+" "-" "<" ">", data): see skeye.sim.server's module comment.
LineObserver = Callable[[int, str, bytes], None]


# --- the connection's states (sans-IO) -------------------------------------------------------


class Conn(enum.Enum):
    AWAITING = "awaiting its first line"
    OPEN = "open, no robot"
    BOUND = "driving a robot"
    CLOSED = "closed"


class ConnEvent(enum.Enum):
    LINE = "a line arrived"
    BIND = "INIT spawned the robot"
    UNBIND = "the engine stopped the robot"
    QUIET = "quiet too long"
    CLOSE = "the connection ended"


TRANSITIONS: dict[tuple[Conn, ConnEvent], Conn] = {
    (Conn.AWAITING, ConnEvent.LINE): Conn.OPEN,
    (Conn.OPEN, ConnEvent.LINE): Conn.OPEN,
    (Conn.BOUND, ConnEvent.LINE): Conn.BOUND,
    (Conn.OPEN, ConnEvent.BIND): Conn.BOUND,
    (Conn.AWAITING, ConnEvent.BIND): Conn.BOUND,  # its line ended in a bare CR
    (Conn.BOUND, ConnEvent.UNBIND): Conn.OPEN,  # ERR PHYSICS/CAMERA removed it: INIT again
    (Conn.AWAITING, ConnEvent.QUIET): Conn.CLOSED,
    (Conn.OPEN, ConnEvent.QUIET): Conn.CLOSED,
    (Conn.AWAITING, ConnEvent.CLOSE): Conn.CLOSED,
    (Conn.OPEN, ConnEvent.CLOSE): Conn.CLOSED,
    (Conn.BOUND, ConnEvent.CLOSE): Conn.CLOSED,
    (Conn.CLOSED, ConnEvent.CLOSE): Conn.CLOSED,
}
"""(state, event) -> state. A robot-driving connection is never closed for being quiet (a
hovering robot needs no commands; TCP keepalive finds dead peers): BOUND has no QUIET row."""

NEEDS_ROBOT = frozenset({"DRIVE", "GETCONF", "GETGEO", "RESET"})
"""Commands refused until INIT has bound a robot (SET checks per Type: Camera needs one)."""

ONCE = frozenset({"INIT"})
"""Commands refused once a robot is bound (one robot per connection)."""


def needs_robot(command: str, stopped: str | None = None) -> str:
    """The refusal of a command that needs a robot on a connection without one (``stopped``:
    why the engine removed the connection's last robot, if it did)."""
    if stopped is not None:
        return f"{command} needs a robot: {stopped}; send INIT for a new one"
    return f"{command} needs a robot: send INIT first"


class ConnectionStates:
    """The state of one connection, moved only through :data:`TRANSITIONS`."""

    def __init__(self) -> None:
        self.state = Conn.AWAITING

    def _go(self, event: ConnEvent) -> Conn:
        new = TRANSITIONS.get((self.state, event))
        if new is None:
            raise LocalProtocolError(f"connection {self.state.value}: no transition on "
                                     f"{event.value}")
        self.state = new
        return new

    def line(self) -> None:
        """A complete line arrived."""
        self._go(ConnEvent.LINE)

    def bind(self) -> None:
        """INIT spawned this connection's robot."""
        self._go(ConnEvent.BIND)

    def unbind(self) -> None:
        """The engine stopped and removed this connection's robot."""
        self._go(ConnEvent.UNBIND)

    def close(self) -> None:
        self._go(ConnEvent.CLOSE)

    def refusal(self, command: str, robot_name: str | None,
                stopped: str | None = None) -> str | None:
        """Why ``command`` may not run in this state, or None (``stopped``: why the engine
        removed this connection's last robot, if it did)."""
        if self.state is Conn.BOUND and command in ONCE:
            return (f"this connection already drives robot {robot_name} "
                    "(one robot per connection)")
        if self.state is not Conn.BOUND and command in NEEDS_ROBOT:
            return needs_robot(command, stopped)
        return None

    def quiet(self, quiet_s: float, handshake_timeout_s: float,
              idle_timeout_s: float) -> str | None:
        """After ``quiet_s`` without a line: why the connection must close (it is then CLOSED),
        or None."""
        if self.state is Conn.AWAITING and quiet_s >= handshake_timeout_s:
            reason = f"no command within {handshake_timeout_s:g} s of connecting; closed"
        elif self.state is Conn.OPEN and quiet_s >= idle_timeout_s:
            reason = f"idle for {idle_timeout_s:g} s without a robot; closed"
        else:
            return None
        self._go(ConnEvent.QUIET)
        return reason


class SessionHost(Protocol):
    """What a session needs of its server."""

    runner: SimulationRunner
    observers: list[LineObserver]
    handshake_timeout_s: float
    idle_timeout_s: float
    command_timeout_s: float
    set_handlers: dict[str, Callable[[ClientSession, Set], None]]
    clock_barrier: ClockBarrier

    def notify(self, conn_id: int, direction: str, data: bytes) -> None: ...

    def forget(self, session: ClientSession) -> None: ...


def _line_bytes(event: Message | LineError) -> bytes:
    """A received line as observers see it: its type and blocks (or the bad line's text)."""
    if isinstance(event, LineError):
        return event.line.encode("utf-8", "replace")
    return " ".join([event.type, *(f"{{{b}}}" for b in event.blocks)]).encode("utf-8")


class ClientSession:
    """One connection: its reader and writer threads and, after INIT, its robot."""

    def __init__(self, server: SessionHost, sock: socket.socket, peer: str, conn_id: int,
                 peer_key: str = "") -> None:
        self.server = server
        self.sock = sock
        self.peer = peer
        self.peer_host = peer.rpartition(":")[0]
        self.peer_key = peer_key or self.peer_host  # whose slot it takes (skeye.peers)
        self.last_line_s = time.monotonic()  # when the client last sent a line (or connected)
        self.replaced = False  # a newer connection of the same peer took its slot
        self.conn_id = conn_id
        self.states = ConnectionStates()
        self.robot_name: str | None = None
        self.drives_clock = False  # a member of the server's clock barrier (STEP {Sync true})
        # Set on the engine thread when it stops this connection's robot (RobotStopped); the
        # reader unbinds before its next command (_take_stop), so a new INIT is accepted.
        self._robot_stopped: tuple[str, str] | None = None
        self.stopped_reason: str | None = None
        self.robot_config: Any = None
        self.outbox: queue.Queue[tuple[bytes, bool]] = queue.Queue()  # (bytes, stream lines)
        self.dropped = 0  # lines not sent because the client did not read them in time
        self._queued_bytes = 0
        self._queued_answer_bytes = 0  # of which answers, not stream lines
        self._queued_lock = threading.Lock()
        self._closed = threading.Event()
        # The socket is closed by whichever of the two threads ends last (a client that hangs
        # up ends both): its descriptor must not wait for the garbage collector.
        self._threads_running = 2
        self._threads_lock = threading.Lock()
        self._reader = Worker(self._read_loop, f"sim-read-{peer}", on_error=self._on_error)
        self._writer = Worker(self._write_loop, f"sim-write-{peer}", on_error=self._on_error)

    def start(self) -> None:
        self._reader.start()
        self._writer.start()

    def _on_error(self, exc: BaseException) -> None:
        """A session thread failed (a bug): the client hears why, the session ends."""
        self.send(encode(Err("CONNECT", reason=f"server error, closing: {exc!r}")))
        self._closed.set()
        self.outbox.put_nowait(_CLOSE)
        try:
            self.sock.shutdown(socket.SHUT_RD)
        except OSError:
            pass

    # -- output --------------------------------------------------------------------------
    def send(self, line: bytes, stream: bool = False) -> None:
        """Queue a line, or a chunk of the robot's ``stream`` lines; never blocks (called from
        the engine thread too). Stream lines are dropped beyond ``OUTBOX_BYTES`` queued; the
        other lines (answers) only beyond their own ``OUTBOX_BYTES // 8``, which stream lines
        never take, so that a stream backlog never costs a client an answer."""
        if self._closed.is_set():
            return
        if self.server.observers:
            self.server.notify(self.conn_id, ">", line)
        with self._queued_lock:
            # One chunk may be larger than the bound (a long lockstep STEP); a backlog may not.
            if stream:
                full = self._queued_bytes and self._queued_bytes + len(line) > OUTBOX_BYTES
            else:
                full = (self._queued_answer_bytes
                        and self._queued_answer_bytes + len(line) > OUTBOX_BYTES // 8)
            if full:
                self.dropped += max(1, line.count(b"\n"))
                return
            self._queued_bytes += len(line)
            if not stream:
                self._queued_answer_bytes += len(line)
        self.outbox.put_nowait((line, stream))

    def _write_loop(self) -> None:
        try:
            while True:
                item = self.outbox.get()
                if not item[0]:  # _CLOSE
                    break
                items = [item]
                try:
                    while len(items) < 512:
                        more = self.outbox.get_nowait()
                        if not more[0]:
                            self.sock.sendall(b"".join(chunk for chunk, _ in items))
                            return
                        items.append(more)
                except queue.Empty:
                    pass
                data = b"".join(chunk for chunk, _ in items)
                self.sock.sendall(data)
                with self._queued_lock:
                    self._queued_bytes -= len(data)
                    self._queued_answer_bytes -= sum(len(c) for c, stream in items if not stream)
        except OSError:
            pass
        finally:
            self._closed.set()
            try:
                self.sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            self._thread_done()

    # -- input ---------------------------------------------------------------------------
    def _read_loop(self) -> None:
        decoder = LineDecoder()
        last_s = time.monotonic()
        server = self.server
        try:
            with selectors.DefaultSelector() as sel:
                sel.register(self.sock, selectors.EVENT_READ)
                while not self._closed.is_set():
                    ready = sel.select(0.5)
                    reason = self.states.quiet(time.monotonic() - last_s,
                                               server.handshake_timeout_s, server.idle_timeout_s)
                    if reason is not None:
                        log.info("closing client %s: %s", self.peer, reason)
                        self.send(encode(Err("CONNECT", reason=reason)))
                        return
                    if not ready:
                        continue
                    try:
                        data = self.sock.recv(65536)
                    except OSError:
                        break
                    if not data:
                        break
                    lines = b"\n" in data
                    if lines:
                        self.states.line()
                        last_s = self.last_line_s = time.monotonic()
                    if not self._feed(decoder, data):
                        return
                    if lines:  # the time its commands took (a long STEP) is not its silence
                        last_s = time.monotonic()
        finally:
            try:
                self.states.close()
                self._finish()
            finally:
                self._thread_done()

    def _thread_done(self) -> None:
        """One of the session's two threads ended; the last one closes the socket."""
        with self._threads_lock:
            self._threads_running -= 1
            last = self._threads_running == 0
        if last:
            self.sock.close()

    def _feed(self, decoder: LineDecoder, data: bytes) -> bool:
        """Handle the lines in ``data``; False when the connection must close."""
        for event in decoder.feed(data):
            if self.server.observers:
                self.server.notify(self.conn_id, "<", _line_bytes(event))
            if isinstance(event, LineError) and _HTTP_LINE.match(event.line):
                log.warning("client %s sent HTTP (a web page?); closing: %r", self.peer,
                            event.line[:80])
                self.send(encode(Err(
                    "CONNECT", reason="this is the simulator control port, not HTTP; a web page "
                    "may not talk to it: closed")))
                return False
            if isinstance(event, LineError):
                self.send(encode(Err(event.command, reason=event.reason)))
                if event.fatal:
                    return False
                continue
            self._handle(event)
        return True

    def _finish(self) -> None:
        if self.robot_name is not None:
            name = self.robot_name
            self.robot_name = None
            try:
                self.server.runner.submit(lambda sim: sim.remove(name))
            except SkeyeError:
                pass
        if self.drives_clock:  # the others step on without it (and without its robot: after)
            self._leave_clock()
        self.outbox.put_nowait(_CLOSE)  # the writer sends what is queued, then stops
        self.server.forget(self)
        if not self._writer.join(CLOSE_LINGER_S):
            # A client that reads nothing holds the writer in sendall for good (TCP keepalive
            # sees a live peer): its thread, socket and queue would outlive the freed slot.
            log.info("client %s took nothing of its last %d bytes in %g s; closing without "
                     "them", self.peer, self._queued_bytes, CLOSE_LINGER_S)
            try:
                self.sock.shutdown(socket.SHUT_RDWR)  # sendall fails at once
            except OSError:
                pass

    def end(self) -> None:
        """Close after what is queued has gone out (safe from any thread, never blocks)."""
        self.outbox.put_nowait(_CLOSE)
        try:
            self.sock.shutdown(socket.SHUT_RD)  # the reader sees the end and finishes
        except OSError:
            pass

    def close(self, timeout_s: float = 2.0) -> None:
        self._closed.set()
        try:
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.outbox.put_nowait(_CLOSE)
        for t in (self._reader, self._writer):
            t.join(timeout_s)
        self.sock.close()

    def _handle(self, msg: Message) -> None:
        refused = unknown_command(msg.type)
        if refused is not None:
            self.send(encode(refused))
            return
        handler = _HANDLERS[msg.type]  # one for each of COMMAND_WORDS (tests/sim/test_server.py)
        self._take_stop()
        try:
            refusal = self.states.refusal(msg.type, self.robot_name, self.stopped_reason)
            if refusal is not None:
                raise RemoteProtocolError(refusal)
            handler(self, msg, decode(msg))
        except (RemoteProtocolError, LocalProtocolError, ConfigError) as exc:
            self.send(encode(Err(msg.type, reason=str(exc))))
        except TimeoutError as exc:
            self.send(encode(Err(msg.type, reason=str(exc) or "the simulator did not answer in "
                                 "time")))
        except SkeyeError as exc:
            self.send(encode(Err(msg.type, reason=str(exc))))
        except Exception as exc:  # a bug (or a failure that killed the engine): say so, go on
            log.exception("%s from %s failed", msg.type, self.peer)
            self.send(encode(Err(msg.type, reason=f"failed: {type(exc).__name__}: {exc}")))

    def _take_stop(self) -> None:
        """Unbind the robot the engine stopped (it removed it already); reader thread only."""
        stopped, self._robot_stopped = self._robot_stopped, None
        if stopped is not None and stopped[0] == self.robot_name:
            self.robot_name = None
            self.stopped_reason = f"robot {stopped[0]} was stopped ({stopped[1]})"
            self.states.unbind()

    # -- commands ------------------------------------------------------------------------
    def _call(self, fn: Callable[[Simulation], Any]) -> Any:
        """Run ``fn`` on the engine thread; TimeoutError (and ``fn`` never runs) if the engine
        does not take it up within the server's ``command_timeout_s``."""
        return self.server.runner.call(fn, timeout_s=self.server.command_timeout_s)

    def _robot(self, command: str) -> str:
        if self.robot_name is None:  # _handle has taken any stop the engine reported
            raise RemoteProtocolError(needs_robot(command, self.stopped_reason))
        return self.robot_name

    def cmd_init(self, msg: Message, init: Init) -> None:
        encoder = StreamEncoder()
        # A vector that was not three plain numbers was read as USARSim reads it: say how.
        note = "; ".join(usarsim_notes(msg)) or None
        if note is not None:
            log.info("client %s: INIT %s", self.peer, note)

        def sink(events: list[Event]) -> None:  # engine thread
            # The engine's ERR lines (a robot stopped or crashed) are answers, with their room
            # of their own, in their place among the stream lines: a stream backlog must not
            # cost the client the news (until 2026-11-28 they went in the stream's chunk and
            # were dropped with it).
            start = 0
            for i, event in enumerate(events):
                # A stop is noted before its ERR goes out: a client's next line sees it.
                if isinstance(event, RobotStopped):
                    self._robot_stopped = (event.robot, event.reason)
                if isinstance(event, RobotStopped | RobotCrashed):
                    if i > start:
                        self.send(encoder.encode(events[start:i]), stream=True)
                    self.send(encoder.encode([event]))
                    start = i + 1
            if start < len(events):
                self.send(encoder.encode(events[start:] if start else events), stream=True)

        def spawn(sim: Simulation) -> tuple[str, Any]:
            robot: Robot = sim.spawn(
                init.class_name,
                name=init.name,
                sink=sink,
                location_ned_m=init.location_ned_m if init.start is None else None,
                rotation_rpy_rad=init.rotation_rpy_rad or (0.0, 0.0, 0.0),
                start=init.start,
            )
            placed = robot_note(init, robot.spawn_pos_ned_m)
            if placed is not None:
                log.info("client %s: INIT %s", self.peer, placed)
            said = "; ".join(n for n in (note, placed) if n) or None
            # Bound before the answer goes out: a client that has it drives a robot, also for
            # the server's slot decisions (a connection driving a robot is never replaced).
            self.robot_name, self.robot_config = robot.name, robot.config
            # Answer from the engine thread, before the first STA/SEN of this robot.
            self.send(encode(Res("INIT", name=robot.name, status="OK", note=said)))
            return robot.name, robot.config

        self.robot_name, self.robot_config = self._call(spawn)
        self.stopped_reason = None
        self.states.bind()

    def cmd_reset(self, msg: Message, reset: Reset) -> None:
        """Respawn this connection's robot (crashed or not): where it was spawned, or at the
        start pose or location given. Answered from the engine thread before the robot's first
        reading at its new pose."""
        name = self._robot("RESET")
        note = "; ".join(usarsim_notes(msg)) or None

        def respawn(sim: Simulation) -> None:
            sim.reset_robot(name, start=reset.start, location_ned_m=reset.location_ned_m,
                            rotation_rpy_rad=reset.rotation_rpy_rad or (0.0, 0.0, 0.0))
            self.send(encode(Res("RESET", name=name, status="OK", note=note)))

        self._call(respawn)
        log.info("client %s reset robot %s", self.peer, name)

    def cmd_drive(self, msg: Message, drive: Drive) -> None:
        name = self._robot("DRIVE")
        c = self.robot_config.controller
        limits = DriveLimits(c.max_speed_m_s, c.max_climb_m_s, c.max_yaw_rate_rad_s,
                             c.max_tilt_rad)
        drive = drive_in_si(msg, drive, limits)
        # Each field sets its own axis; the axes left out keep theirs (AerialVehicle.Drive).
        changes: dict[str, Any] = {
            "height_mode": drive.board_mode == "height",
            "gps_mode": drive.board_mode == "gps",
        }
        for attr, value in (
            ("roll_rad", drive.roll_rad),
            ("pitch_rad", drive.pitch_rad),
            ("thrust", drive.thrust_fraction),
            ("forward_m_s", drive.forward_m_s),
            ("right_m_s", drive.right_m_s),
            ("up_m_s", drive.up_m_s),
            ("yaw_rate_rad_s", drive.yaw_rate_rad_s),
        ):
            if value is not None:
                changes[attr] = value

        def apply(sim: Simulation) -> None:
            robot = sim.robots.get(name)
            if robot is None:
                raise RemoteProtocolError(f"robot {name} no longer exists")
            robot.drive(**changes)

        self._call(apply)
        # A value that was not plain, or an angle the same line's velocity overrode: say how
        # it was read (USARSim answers DRIVE with nothing; a RES is ignored by its clients).
        notes = usarsim_notes(msg)
        if notes:
            note = "; ".join(notes)
            log.info("client %s: DRIVE %s", self.peer, note)
            self.send(encode(Res("DRIVE", status="OK", note=note)))

    def cmd_getstartposes(self, msg: Message, command: GetStartPoses) -> None:
        self.send(encode(StartPoses(tuple(self.server.runner.sim.start_poses()))))

    def _lookup(self, query: GetConf | GetGeo, command: str) -> tuple[str, list[Any]]:
        type_name = query.type
        name = self._robot(command)
        if type_name.lower() in ("robot", "aerialvehicle"):
            return "robot", []
        sensor_name = query.name

        def find(sim: Simulation) -> list[Any]:
            robot = sim.robots.get(name)
            if robot is None:  # a STEP stopped it after this command was read
                raise RemoteProtocolError(needs_robot(command, f"robot {name} is gone"))
            return robot.find_sensors(type_name, sensor_name)

        found = self._call(find)
        if not found:
            raise RemoteProtocolError(
                f"robot {name} has no sensor of type {type_name}"
                + (f" named {sensor_name}" if sensor_name else "")
            )
        return "sensor", found

    def cmd_getgeo(self, msg: Message, query: GetGeo) -> None:
        kind, found = self._lookup(query, "GETGEO")
        name = self._robot("GETGEO")
        if kind == "robot":
            a = self.robot_config.airframe
            width_m = 2 * (a.arm_m + a.rotor_radius_m)
            dimensions_m = (width_m, width_m, a.body_size_m[2] + a.gear_height_m)
            fields = (("Dimensions", dimensions_m), ("COG", (0.0, 0.0, 0.0)))
            self.send(encode(Geo("AerialVehicle", name, fields)))
            return
        for s in found:
            self.send(encode(Geo(s.sensor.type_name, s.mount.name, tuple(s.sensor.geo_fields()))))

    def cmd_getconf(self, msg: Message, query: GetConf) -> None:
        kind, found = self._lookup(query, "GETCONF")
        name = self._robot("GETCONF")
        if kind == "robot":
            cfg = self.robot_config
            a, c = cfg.airframe, cfg.controller
            conf = RobotConf(
                name=name,
                class_name=cfg.class_name,
                mass_kg=a.mass_kg,
                max_speed_m_s=c.max_speed_m_s,
                max_climb_m_s=c.max_climb_m_s,
                max_yaw_rate_rad_s=c.max_yaw_rate_rad_s,
                max_tilt_rad=c.max_tilt_rad,
                max_thrust_n=a.max_thrust_n,
                board_rate_hz=cfg.board_rate_hz,
                time_step_s=self.server.runner.sim.dt,
                sensors=",".join(f"{m.type_name}:{m.name}" for m in cfg.sensors),
            )
            self.send(encode(conf))
            return
        for s in found:
            self.send(encode(Conf(s.sensor.type_name, s.mount.name, tuple(s.sensor.conf_fields()))))

    def cmd_set(self, msg: Message, command: Set) -> None:
        handler = self.server.set_handlers.get(command.type.lower())
        if handler is None:
            raise RemoteProtocolError(
                f"SET: unknown Type {command.type!r}; known: "
                + ", ".join(sorted(self.server.set_handlers))
            )
        handler(self, command)
        self.send(encode(Res("SET", type=command.type, status="OK")))

    def cmd_step(self, msg: Message, command: Step) -> None:
        """Run the steps on the engine thread; the answer goes out from there when they end.

        While they run, this reader watches its socket for the client going away (its end
        closed or reset: ``POLLRDHUP``, ``POLLHUP``, ``POLLERR``; lines it sent meanwhile stay
        unread). Then the engine stops this STEP at its next point between steps, so other
        clients are not kept waiting for steps nobody will read; the reader then finds the
        connection's end and the session finishes as for any client gone."""
        count = command.count
        runner = self.server.runner
        barrier = self.server.clock_barrier
        gone = threading.Event()

        def answer(sim: Simulation) -> None:
            self.send(encode(Res("STEP", time_s=sim.time_s)))

        def do(sim: Simulation) -> None:
            sim.step(count, gone.is_set)
            if not gone.is_set():
                answer(sim)
            if barrier.members:  # members whose boundary these steps passed
                barrier.advance(sim)

        if runner.mode != "lockstep":
            raise RemoteProtocolError(
                "STEP works only when the simulator runs with --mode lockstep"
            )
        if command.sync:
            self._step_in_sync(count, answer, gone)
            return
        fut = runner.submit(do, fatal=True)
        try:  # most STEPs are short: no watching
            fut.result(STEP_WATCH_AFTER_S)
            return
        except TimeoutError:
            pass
        self._watch_while(fut, gone, STEP_TIMEOUT_S)

    def _step_in_sync(self, count: int, answer: Callable[[Simulation], None],
                      gone: threading.Event) -> None:
        """``STEP {Sync true}``: this connection's robot steps in the clock barrier
        (:mod:`skeye.sim.clock_barrier`); the answer goes out when the world reaches this
        connection's next boundary, once every member has asked for its own."""
        if not self.drives_clock:  # only a connection flying a robot joins (it stays a member
            self._robot("STEP with Sync")  # if the robot is stopped: a crash, a reset)
        runner = self.server.runner
        barrier = self.server.clock_barrier
        reached: Future[None] = Future()
        self.drives_clock = True
        asked = runner.submit(
            lambda sim: barrier.step(sim, self.conn_id, count, answer, gone.is_set, reached),
            fatal=True)
        asked.add_done_callback(lambda f: _pass_failure(f, reached))
        try:  # most are answered at once (one pilot; or the last of the members to ask)
            reached.result(STEP_WATCH_AFTER_S)
            return
        except TimeoutError:
            pass
        try:
            self._watch_while(reached, gone, STEP_TIMEOUT_S, on_gone=self._leave_clock)
        except TimeoutError:
            if not reached.cancelled():
                raise  # its own steps took too long, as a plain STEP's
            conn_id = self.conn_id
            runner.submit(lambda sim: barrier.withdraw(sim, conn_id, reached))
            raise TimeoutError(
                f"the other clients driving the clock did not all ask within "
                f"{STEP_TIMEOUT_S:g} s; this STEP is withdrawn, not done") from None

    def _leave_clock(self) -> None:
        """Leave the clock barrier (its STEP, if one waits, ends unanswered)."""
        conn_id, barrier = self.conn_id, self.server.clock_barrier
        self.drives_clock = False
        try:  # fatal: leaving may step the others' world
            self.server.runner.submit(lambda sim: barrier.leave(sim, conn_id), fatal=True)
        except SkeyeError:
            pass

    def _watch_while(self, fut: Future[None], gone: threading.Event, timeout_s: float, *,
                     on_gone: Callable[[], None] | None = None) -> None:
        """Wait for ``fut`` (a STEP on the engine thread, at most ``timeout_s`` to be taken up
        and as long again to end, as :meth:`SimulationRunner.call`), setting ``gone`` when the
        client's end of the connection closes. A pipe written from the future's done callback
        wakes the wait when the STEP ends."""
        wake_r, wake_w = os.pipe()
        # The callback may run after this returns (a future is done() before its callbacks
        # have run, and a STEP that timed out ends later): it writes only while the pipe is
        # open, never to a closed descriptor number another socket may have taken since.
        pipe_lock = threading.Lock()
        pipe_open = [True]

        def wake(_: Future[None]) -> None:
            with pipe_lock:
                if pipe_open[0]:
                    os.write(wake_w, b".")

        try:
            fut.add_done_callback(wake)
            poller = select.poll()
            poller.register(wake_r, select.POLLIN)
            poller.register(self.sock, _PEER_GONE)
            deadline = time.monotonic() + timeout_s
            begun = False
            while True:
                left = deadline - time.monotonic()
                if left <= 0.0:
                    if fut.cancel():
                        raise TimeoutError(
                            f"the simulator did not take it up within {timeout_s:g} s (busy: "
                            "another client's long STEP?); not done")
                    if begun:
                        raise TimeoutError(
                            f"the simulator is still at it after {2 * timeout_s:g} s")
                    begun = True  # it had begun: it has as long again to end
                    deadline = time.monotonic() + timeout_s
                    continue
                events = dict(poller.poll(left * 1000.0))
                if wake_r in events:
                    break
                if events.get(self.sock.fileno(), 0) & _PEER_GONE:
                    if not gone.is_set():
                        log.info("client %s went away during its STEP; stopping it", self.peer)
                        gone.set()
                        if on_gone is not None:
                            on_gone()
                    poller.unregister(self.sock)  # reported for good: wait for the engine
            fut.result()  # done: its exception, if any (an engine failure), goes on
        finally:
            with pipe_lock:
                pipe_open[0] = False
                os.close(wake_r)
                os.close(wake_w)

    def cmd_ping(self, msg: Message, ping: Ping) -> None:
        # Its Id is at most sim_messages.MAX_PING_ID_CHARS (decode checks): the answer stays
        # within the line limit.
        if self.server.runner.error is not None:
            raise self.server.runner.error  # no pretending: a dead engine's clock is not time
        self.send(encode(Res("PING", id=ping.id, time_s=self.server.runner.sim.time_s)))


def _pass_failure(asked: Future[None], reached: Future[None]) -> None:
    """A barrier STEP whose task failed or was refused (the engine died, the simulator is
    stopping) ends with that error, unless the barrier has ended it already."""
    exc = asked.exception() if not asked.cancelled() else None
    if exc is not None:
        fail_step(reached, exc)


_HANDLERS: dict[str, Callable[[ClientSession, Message, Any], None]] = {
    "INIT": ClientSession.cmd_init,
    "DRIVE": ClientSession.cmd_drive,
    "RESET": ClientSession.cmd_reset,
    "GETSTARTPOSES": ClientSession.cmd_getstartposes,
    "GETGEO": ClientSession.cmd_getgeo,
    "GETCONF": ClientSession.cmd_getconf,
    "SET": ClientSession.cmd_set,
    "STEP": ClientSession.cmd_step,
    "PING": ClientSession.cmd_ping,
}


def robot_note(init: Init, spawned_ned_m: tuple[float, float, float]) -> str | None:
    """What INIT's answer says when the robot was not put where its Location said: a location
    below the ground (down > 0) stands it on the surface above (see ``Simulation.spawn``)."""
    if init.start is not None or init.location_ned_m is None or init.location_ned_m[2] <= 0.0:
        return None
    n, e, d = spawned_ned_m
    return (f"Location down {init.location_ned_m[2]:g} m is below the ground (NED: down is "
            f"positive); the robot stands on the surface there, at {n:g},{e:g},{d:g}")


def _require(value: str | None, key: str) -> str:
    if value is None:
        raise RemoteProtocolError(f"missing {{{key} ...}}")
    return value


def set_wind(session: ClientSession, command: Set) -> None:
    """``SET {Type Wind} {Mode m} {Params k=v,...}``."""
    settings = make_settings(_require(command.mode, "Mode"), parse_params(command.params or ""))
    session._call(lambda sim: sim.set_wind(settings))


def set_camera(session: ClientSession, command: Set) -> None:
    """``SET {Type Camera} {Name n} {Opcode FOV} {Params rad}``."""
    name = session._robot("SET")
    camera = _require(command.name, "Name")
    opcode = _require(command.opcode, "Opcode")
    if opcode.lower() != "fov":
        raise RemoteProtocolError(f"SET Camera: unknown Opcode {opcode!r}; known: FOV")
    fov = parse_value("Params", _require(command.params, "Params"), "float",
                      min_value=0.01, max_value=math.pi - 0.01)
    session._call(lambda sim: set_camera_fov(sim, name, camera, fov))
