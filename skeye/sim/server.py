"""The control server: docs/protocols/simulator.md over TCP, many clients, one robot per connection.

How this works: an accept thread hands each connection to a :class:`ClientSession` with two
threads: a reader that decodes lines with the sans-IO codec (:mod:`skeye.wire.sim_lines`) and
handles them, and a writer that alone writes to the socket, draining a bounded queue. The engine
thread puts the robot's STA/SEN lines into that queue without ever blocking: when a client does
not read, its queue fills and further stream lines are dropped and counted, so a slow client
never slows the physics or other clients. Answers (RES, ERR, GEO, CONF, NFO) always go through
the same queue, so their order relative to the stream is kept. Every bad line gets an ``ERR``
with a reason and the connection stays usable; only an over-long line closes it, and so does an
HTTP request line or header (a web page's cross-protocol POST, whose body would otherwise be
read as commands).

Slots are bounded: at most ``max_clients`` connections, at most ``max_clients_per_peer`` from
one peer address, and a connection that sends no line within ``handshake_timeout_s`` of
connecting, or (while it drives no robot) none for ``idle_timeout_s``, gets
``ERR {Command CONNECT}`` with the reason and is closed. A connection driving a robot is never
closed for being quiet (a hovering robot needs no commands); TCP keepalive finds its dead peers.

If the engine thread dies (:attr:`SimulationRunner.error`), every client gets
``ERR {Command ENGINE} {Reason ...}`` naming the failure at once and is closed, and so is every
later connection; ``skeye sim`` then exits with status 3.

Observers (:attr:`ControlServer.observers`, e.g. the flight recorder) see every connection
opened (``+``) and closed (``-``), every line received (``<``, re-encoded from the decoded
message) and every chunk queued to a client (``>``, one or more whole lines). They are called on
the thread that produced the data (the engine's for the stream), must not block, and a failing
observer is logged and never breaks the session.
"""

from __future__ import annotations

import itertools
import logging
import math
import queue
import re
import selectors
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

from skeye.errors import ConfigError, LocalProtocolError, RemoteProtocolError, SkeyeError
from skeye.sim.cameras import set_camera_fov
from skeye.sim.engine import Simulation, SimulationRunner
from skeye.sim.limits import check_server_limits
from skeye.sim.robot import Robot
from skeye.sim.wind import make_settings, parse_params
from skeye.wire.sim_format import format_start_poses
from skeye.wire.sim_lines import LineDecoder, LineError, Message, format_error, format_message
from skeye.workers import Worker, WorkerFailed

log = logging.getLogger(__name__)

OUTBOX_BYTES = 8 * 1024 * 1024  # per client: a client that stops reading costs at most this
# An HTTP request line or header: a web page POSTing to this port (a cross-protocol request, whose
# text/plain body would otherwise be read as protocol lines). The connection is closed at once.
_HTTP_LINE = re.compile(
    r"^(?:(?:GET|POST|PUT|DELETE|HEAD|OPTIONS|PATCH|CONNECT|TRACE) \S+ HTTP/\d|"
    r"(?:Host|Origin|Content-Type|User-Agent|Content-Length):)", re.IGNORECASE)
HANDSHAKE_TIMEOUT_S = 10.0  # a new connection must send its first line within this
IDLE_TIMEOUT_S = 120.0  # a connection without a robot must send a line at least this often
MAX_CLIENTS_PER_PEER = 64  # connections from one peer address (half the default 128 slots)
_CLOSE = b""

# (connection id, direction "+" "-" "<" ">", data): see the module comment.
LineObserver = Callable[[int, str, bytes], None]


def _line_bytes(event: Message | LineError) -> bytes:
    """A received line as observers see it: its type and blocks (or the bad line's text)."""
    if isinstance(event, LineError):
        return event.line.encode("utf-8", "replace")
    return " ".join([event.type, *(f"{{{b}}}" for b in event.blocks)]).encode("utf-8")


class ClientSession:
    """One connection: its reader and writer threads and, after INIT, its robot."""

    def __init__(self, server: ControlServer, sock: socket.socket, peer: str) -> None:
        self.server = server
        self.sock = sock
        self.peer = peer
        self.peer_host = peer.rpartition(":")[0]
        self.conn_id = next(server._conn_ids)
        self.robot_name: str | None = None
        self.robot_config: Any = None
        self.outbox: queue.Queue[bytes] = queue.Queue()
        self.dropped = 0  # lines not sent because the client did not read them in time
        self._queued_bytes = 0
        self._queued_lock = threading.Lock()
        self._closed = threading.Event()
        self._reader = Worker(self._read_loop, f"sim-read-{peer}", on_error=self._on_error)
        self._writer = Worker(self._write_loop, f"sim-write-{peer}", on_error=self._on_error)

    def start(self) -> None:
        self._reader.start()
        self._writer.start()

    def _on_error(self, exc: BaseException) -> None:
        """A session thread failed (a bug): the client hears why, the session ends."""
        self.send(format_error("CONNECT", f"server error, closing: {exc!r}"))
        self._closed.set()
        self.outbox.put_nowait(_CLOSE)
        try:
            self.sock.shutdown(socket.SHUT_RD)
        except OSError:
            pass

    # -- output --------------------------------------------------------------------------
    def send(self, line: bytes) -> None:
        """Queue a line; never blocks (called from the engine thread too)."""
        if self._closed.is_set():
            return
        if self.server.observers:
            self.server.notify(self.conn_id, ">", line)
        with self._queued_lock:
            # One chunk may be larger than the bound (a long lockstep STEP); a backlog may not.
            if self._queued_bytes and self._queued_bytes + len(line) > OUTBOX_BYTES:
                self.dropped += max(1, line.count(b"\n"))
                return
            self._queued_bytes += len(line)
        self.outbox.put_nowait(line)

    def _write_loop(self) -> None:
        try:
            while True:
                line = self.outbox.get()
                if line is _CLOSE or not line:
                    break
                chunks = [line]
                try:
                    while len(chunks) < 512:
                        more = self.outbox.get_nowait()
                        if not more:
                            self.sock.sendall(b"".join(chunks))
                            return
                        chunks.append(more)
                except queue.Empty:
                    pass
                data = b"".join(chunks)
                self.sock.sendall(data)
                with self._queued_lock:
                    self._queued_bytes -= len(data)
        except OSError:
            pass
        finally:
            self._closed.set()
            try:
                self.sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    # -- input ---------------------------------------------------------------------------
    def _idle_reason(self, quiet_s: float, got_line: bool) -> str | None:
        """Why this connection must go for having been quiet ``quiet_s``, or None."""
        server = self.server
        if not got_line and quiet_s >= server.handshake_timeout_s:
            return f"no command within {server.handshake_timeout_s:g} s of connecting; closed"
        if got_line and self.robot_name is None and quiet_s >= server.idle_timeout_s:
            return f"idle for {server.idle_timeout_s:g} s without a robot; closed"
        return None

    def _read_loop(self) -> None:
        decoder = LineDecoder()
        got_line = False
        last_s = time.monotonic()
        try:
            with selectors.DefaultSelector() as sel:
                sel.register(self.sock, selectors.EVENT_READ)
                while not self._closed.is_set():
                    ready = sel.select(0.5)
                    reason = self._idle_reason(time.monotonic() - last_s, got_line)
                    if reason is not None:
                        log.info("closing client %s: %s", self.peer, reason)
                        self.send(format_error("CONNECT", reason))
                        return
                    if not ready:
                        continue
                    try:
                        data = self.sock.recv(65536)
                    except OSError:
                        break
                    if not data:
                        break
                    if b"\n" in data:
                        got_line = True
                        last_s = time.monotonic()
                    if not self._feed(decoder, data):
                        return
        finally:
            self._finish()

    def _feed(self, decoder: LineDecoder, data: bytes) -> bool:
        """Handle the lines in ``data``; False when the connection must close."""
        for event in decoder.feed(data):
            if self.server.observers:
                self.server.notify(self.conn_id, "<", _line_bytes(event))
            if isinstance(event, LineError) and _HTTP_LINE.match(event.line):
                log.warning("client %s sent HTTP (a web page?); closing: %r", self.peer,
                            event.line[:80])
                self.send(format_error(
                    "CONNECT", "this is the simulator control port, not HTTP; a web page may "
                    "not talk to it: closed"))
                return False
            if isinstance(event, LineError):
                self.send(format_error(event.command, event.reason))
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
        self.outbox.put_nowait(_CLOSE)  # the writer sends what is queued, then stops
        self.server._forget(self)

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
        handler = _HANDLERS.get(msg.type)
        if handler is None:
            self.send(format_error(msg.type, f"unknown command {msg.type}"))
            return
        try:
            handler(self, msg)
        except (RemoteProtocolError, LocalProtocolError, ConfigError) as exc:
            self.send(format_error(msg.type, str(exc)))
        except TimeoutError:
            self.send(format_error(msg.type, "the simulator did not answer in time"))
        except SkeyeError as exc:
            self.send(format_error(msg.type, str(exc)))
        except Exception as exc:  # a bug (or a failure that killed the engine): say so, go on
            log.exception("%s from %s failed", msg.type, self.peer)
            self.send(format_error(msg.type, f"failed: {type(exc).__name__}: {exc}"))

    # -- commands ------------------------------------------------------------------------
    def _robot(self, command: str) -> str:
        if self.robot_name is None:
            raise RemoteProtocolError(f"{command} needs a robot: send INIT first")
        return self.robot_name

    def cmd_init(self, msg: Message) -> None:
        if self.robot_name is not None:
            raise RemoteProtocolError(
                f"this connection already drives robot {self.robot_name} (one robot per connection)"
            )
        class_name = msg.require("ClassName")
        name = msg.get("Name")
        start = msg.get("Start")
        location = msg.get_vector("Location", 3) if msg.has("Location") else None
        rr, rp, ry = msg.get_vector("Rotation", 3, default=(0.0, 0.0, 0.0))
        rotation = (rr, rp, ry)
        if any(abs(v) > 2 * math.pi for v in rotation):
            raise RemoteProtocolError(
                f"Rotation {rotation} must be in [-2pi, 2pi] rad per axis (radians, not degrees)"
            )
        if start is None and location is None:
            raise RemoteProtocolError("INIT needs {Location x,y,z} or {Start name}")
        if location is not None and any(abs(v) > 1.0e4 for v in location):
            raise RemoteProtocolError(f"Location {location} is outside the world (|x| > 10 km)")

        def spawn(sim: Simulation) -> tuple[str, Any]:
            robot: Robot = sim.spawn(
                class_name,
                name=name,
                outbox=self.send,
                location_ned_m=location if start is None else None,  # type: ignore[arg-type]
                rotation_rpy_rad=rotation,
                start=start,
            )
            # Answer from the engine thread, before the first STA/SEN of this robot.
            self.send(
                format_message("RES", ("Command", "INIT"), ("Name", robot.name), ("Status", "OK"))
            )
            return robot.name, robot.config

        self.robot_name, self.robot_config = self.server.runner.call(spawn)

    def cmd_drive(self, msg: Message) -> None:
        name = self._robot("DRIVE")
        attitude_keys = ("RollAngle", "PitchAngle", "Thrust")
        velocity_keys = ("AltitudeVelocity", "LinearVelocity", "LateralVelocity")
        has_att = any(msg.has(k) for k in attitude_keys)
        has_vel = any(msg.has(k) for k in velocity_keys)
        if has_att and has_vel:
            raise RemoteProtocolError(
                "DRIVE mixes the attitude form (RollAngle, PitchAngle, "
                "Thrust) with the velocity form"
            )
        known = {
            k.lower()
            for k in (*attitude_keys, *velocity_keys, "RotationalVelocity", "Normalized", "Name")
        }
        unknown = [k for k, _ in msg.fields if k.lower() not in known]
        if unknown:
            raise RemoteProtocolError(f"DRIVE: unknown segment(s) {unknown}")
        if not (has_att or has_vel or msg.has("RotationalVelocity")):
            raise RemoteProtocolError("DRIVE needs at least one velocity or attitude segment")
        c = self.robot_config.controller
        robot_limits = {
            "speed": c.max_speed_m_s,
            "climb": c.max_climb_m_s,
            "yaw_rate": c.max_yaw_rate_rad_s,
        }
        changes: dict[str, Any] = {"attitude": has_att}
        if has_att:
            tilt = math.pi / 2 - 1e-3
            if msg.has("RollAngle"):
                changes["roll_rad"] = msg.get_float("RollAngle", min_value=-tilt, max_value=tilt)
            if msg.has("PitchAngle"):
                changes["pitch_rad"] = msg.get_float("PitchAngle", min_value=-tilt, max_value=tilt)
            if msg.has("Thrust"):
                changes["thrust"] = msg.get_float("Thrust", min_value=0.0, max_value=1.0)
        normalized = msg.get_bool("Normalized", default=False)
        scale = 100.0 if normalized else 1.0
        for key, attr, limit in (
            ("LinearVelocity", "forward_m_s", robot_limits["speed"]),
            ("LateralVelocity", "right_m_s", robot_limits["speed"]),
            ("AltitudeVelocity", "up_m_s", robot_limits["climb"]),
            ("RotationalVelocity", "yaw_rate_rad_s", robot_limits["yaw_rate"]),
        ):
            if not msg.has(key):
                continue
            bound = 100.0 if normalized else limit
            value = msg.get_float(key, min_value=-bound, max_value=bound)
            changes[attr] = value / scale * limit if normalized else value

        def apply(sim: Simulation) -> None:
            robot = sim.robots.get(name)
            if robot is None:
                raise RemoteProtocolError(f"robot {name} no longer exists")
            robot.drive(**changes)

        self.server.runner.call(apply)

    def cmd_getstartposes(self, msg: Message) -> None:
        self.send(format_start_poses(self.server.runner.sim.start_poses()))

    def _lookup(self, msg: Message, command: str) -> tuple[str, list[Any]]:
        type_name = msg.require("Type")
        name = self._robot(command)
        if type_name.lower() in ("robot", "aerialvehicle"):
            return "robot", []
        sensor_name = msg.get("Name")

        def find(sim: Simulation) -> list[Any]:
            robot = sim.robots[name]
            return robot.find_sensors(type_name, sensor_name)

        found = self.server.runner.call(find)
        if not found:
            raise RemoteProtocolError(
                f"robot {name} has no sensor of type {type_name}"
                + (f" named {sensor_name}" if sensor_name else "")
            )
        return "sensor", found

    def cmd_getgeo(self, msg: Message) -> None:
        kind, found = self._lookup(msg, "GETGEO")
        name = self._robot("GETGEO")
        if kind == "robot":
            a = self.robot_config.airframe
            self.send(
                format_message(
                    "GEO",
                    ("Type", "AerialVehicle"),
                    ("Name", name),
                    (
                        "Dimensions",
                        (2 * (a.arm_m + a.rotor_radius_m),) * 2
                        + (a.body_size_m[2] + a.gear_height_m,),
                    ),
                    ("COG", (0.0, 0.0, 0.0)),
                )
            )
            return
        for s in found:
            self.send(
                format_message(
                    "GEO",
                    ("Type", s.sensor.type_name),
                    ("Name", s.mount.name),
                    *s.sensor.geo_fields(),
                )
            )

    def cmd_getconf(self, msg: Message) -> None:
        kind, found = self._lookup(msg, "GETCONF")
        name = self._robot("GETCONF")
        if kind == "robot":
            cfg = self.robot_config
            a, c = cfg.airframe, cfg.controller
            self.send(
                format_message(
                    "CONF",
                    ("Type", "AerialVehicle"),
                    ("Name", name),
                    ("Class", cfg.class_name),
                    ("Mass", a.mass_kg),
                    ("MaxSpeed", c.max_speed_m_s),
                    ("MaxClimb", c.max_climb_m_s),
                    ("MaxYawRate", c.max_yaw_rate_rad_s),
                    ("MaxTilt", c.max_tilt_rad),
                    ("MaxThrust", a.max_thrust_n),
                    ("BoardRate", cfg.board_rate_hz),
                    ("TimeStep", self.server.runner.sim.dt),
                ("Sensors", ",".join(f"{m.type_name}:{m.name}" for m in cfg.sensors)),
                )
            )
            return
        for s in found:
            self.send(
                format_message(
                    "CONF",
                    ("Type", s.sensor.type_name),
                    ("Name", s.mount.name),
                    *s.sensor.conf_fields(),
                )
            )

    def cmd_set(self, msg: Message) -> None:
        type_name = msg.require("Type")
        handler = self.server.set_handlers.get(type_name.lower())
        if handler is None:
            raise RemoteProtocolError(
                f"SET: unknown Type {type_name!r}; known: "
                + ", ".join(sorted(self.server.set_handlers))
            )
        handler(self, msg)
        self.send(format_message("RES", ("Command", "SET"), ("Type", type_name), ("Status", "OK")))

    def cmd_step(self, msg: Message) -> None:
        count = msg.get_int("Count", default=1, min_value=1, max_value=10_000_000)
        runner = self.server.runner

        def do(sim: Simulation) -> None:
            sim.step(count)
            self.send(format_message("RES", ("Command", "STEP"), ("Time", sim.time_s)))

        if runner.mode != "lockstep":
            raise RemoteProtocolError(
                "STEP works only when the simulator runs with --mode lockstep"
            )
        runner.call(do, timeout_s=3600.0, fatal=True)

    def cmd_ping(self, msg: Message) -> None:
        ident = msg.get("Id", "")
        if self.server.runner.error is not None:
            raise self.server.runner.error  # no pretending: a dead engine's clock is not time
        self.send(
            format_message(
                "RES", ("Command", "PING"), ("Id", ident), ("Time", self.server.runner.sim.time_s)
            )
        )


_HANDLERS: dict[str, Callable[[ClientSession, Message], None]] = {
    "INIT": ClientSession.cmd_init,
    "DRIVE": ClientSession.cmd_drive,
    "GETSTARTPOSES": ClientSession.cmd_getstartposes,
    "GETGEO": ClientSession.cmd_getgeo,
    "GETCONF": ClientSession.cmd_getconf,
    "SET": ClientSession.cmd_set,
    "STEP": ClientSession.cmd_step,
    "PING": ClientSession.cmd_ping,
}


def _set_wind(session: ClientSession, msg: Message) -> None:
    settings = make_settings(msg.require("Mode"), parse_params(msg.get("Params", "") or ""))
    session.server.runner.call(lambda sim: sim.set_wind(settings))


def _set_camera(session: ClientSession, msg: Message) -> None:
    name = session._robot("SET")
    camera = msg.require("Name")
    opcode = msg.require("Opcode")
    if opcode.lower() != "fov":
        raise RemoteProtocolError(f"SET Camera: unknown Opcode {opcode!r}; known: FOV")
    fov = msg.get_float("Params", min_value=0.01, max_value=math.pi - 0.01)
    session.server.runner.call(lambda sim: set_camera_fov(sim, name, camera, fov))


def _keepalive(sock: socket.socket) -> None:
    """TCP keepalive: a peer that vanished without a FIN is found within about two minutes."""
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
    for name, value in (("TCP_KEEPIDLE", 60), ("TCP_KEEPINTVL", 10), ("TCP_KEEPCNT", 6)):
        option = getattr(socket, name, None)
        if option is not None:
            sock.setsockopt(socket.IPPROTO_TCP, option, value)


class ControlServer:
    """TCP server for the control protocol; a context manager that closes every thread."""

    def __init__(
        self,
        runner: SimulationRunner,
        host: str = "127.0.0.1",
        port: int = 3000,
        max_clients: int = 128,
        *,
        max_clients_per_peer: int = MAX_CLIENTS_PER_PEER,
        handshake_timeout_s: float = HANDSHAKE_TIMEOUT_S,
        idle_timeout_s: float = IDLE_TIMEOUT_S,
    ) -> None:
        check_server_limits("control server", max_clients=max_clients,
                            max_clients_per_peer=max_clients_per_peer,
                            handshake_timeout_s=handshake_timeout_s, idle_timeout_s=idle_timeout_s)
        self.runner = runner
        self.max_clients = max_clients
        self.max_clients_per_peer = max_clients_per_peer
        self.handshake_timeout_s = handshake_timeout_s
        self.idle_timeout_s = idle_timeout_s
        self.set_handlers: dict[str, Callable[[ClientSession, Message], None]] = {
            "wind": _set_wind,
            "camera": _set_camera,
        }
        self.observers: list[LineObserver] = []
        self._conn_ids = itertools.count(1)
        self._sessions: set[ClientSession] = set()
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self._listener = socket.create_server((host, port), reuse_port=False)
        self._listener.settimeout(0.2)
        self.host = host
        self.port = self._listener.getsockname()[1]
        self._accept_thread = Worker(self._accept_loop, "sim-accept").start()
        runner.failure_listeners.append(self._engine_failed)
        if runner.error is not None:
            self._engine_failed(runner.error)

    def _engine_error_line(self, error: WorkerFailed) -> bytes:
        return format_error("ENGINE", f"{error}; the simulator is stopping")

    def _engine_failed(self, error: WorkerFailed) -> None:
        """On the dying engine thread: tell every client why, then close them all."""
        log.error("%s; telling %d clients", error, self.client_count)
        line = self._engine_error_line(error)
        with self._lock:
            sessions = list(self._sessions)
        for session in sessions:
            session.send(line)
            session.end()

    def __enter__(self) -> ControlServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def nfo_line(self) -> bytes:
        sim = self.runner.sim
        return format_message(
            "NFO",
            ("Gametype", "skeye"),
            ("Level", sim.world.name),
            ("TimeLimit", 0),
            ("TimeStep", sim.dt),
            ("Mode", self.runner.mode),
        )

    def _accept_loop(self) -> None:
        while not self._closing.is_set():
            try:
                sock, addr = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                break
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            _keepalive(sock)
            session = ClientSession(self, sock, f"{addr[0]}:{addr[1]}")
            refusal: bytes | None = None
            with self._lock:
                same_peer = sum(1 for s in self._sessions if s.peer_host == addr[0])
                if self.runner.error is not None:
                    refusal = self._engine_error_line(self.runner.error)
                elif len(self._sessions) >= self.max_clients:
                    refusal = format_error("CONNECT", "too many clients")
                elif same_peer >= self.max_clients_per_peer:
                    refusal = format_error(
                        "CONNECT", f"too many clients from {addr[0]} "
                        f"({self.max_clients_per_peer} per address)")
                else:
                    self._sessions.add(session)
            if refusal is not None:
                log.warning("refusing client %s: %s", session.peer, refusal.decode().strip())
                try:
                    sock.settimeout(1.0)
                    sock.sendall(refusal)
                except OSError:
                    pass
                sock.close()
                continue
            if self.observers:
                self.notify(session.conn_id, "+", session.peer.encode())
            session.send(self.nfo_line())
            session.start()
            log.info("client %s connected", session.peer)

    def _forget(self, session: ClientSession) -> None:
        with self._lock:
            self._sessions.discard(session)
        if self.observers:
            self.notify(session.conn_id, "-", session.peer.encode())
        log.info("client %s disconnected", session.peer)

    def notify(self, conn_id: int, direction: str, data: bytes) -> None:
        """Hand data to every observer; one that raises is logged, never propagated."""
        for observer in list(self.observers):
            try:
                observer(conn_id, direction, data)
            except Exception:
                log.exception("observer %r failed", observer)

    @property
    def client_count(self) -> int:
        with self._lock:
            return len(self._sessions)

    def close(self, timeout_s: float = 5.0) -> None:
        if self._closing.is_set():
            return
        if self._engine_failed in self.runner.failure_listeners:
            self.runner.failure_listeners.remove(self._engine_failed)
        self._closing.set()
        self._listener.close()
        self._accept_thread.join(timeout_s)
        with self._lock:
            sessions = list(self._sessions)
        for s in sessions:
            s.close(timeout_s)
