"""``skeye replay``: serve a flight recording to clients over the control protocol.

How this works: :class:`ReplayServer` listens like the simulator (127.0.0.1 unless told
otherwise). Each client gets its own playback from the start of the recording, on its own
thread: ``NFO {Gametype skeye} ... {Mode realtime} {Replay true}`` on accept, then the recorded
stream of one robot (the lines the engine sent its connection, or each of its connections in
turn where it was spawned again under its name: ``STA``, ``SEN``, and the ``ERR``
of a crash, ``{Command CRASH}``, or of a robot the engine stopped, ``{Command PHYSICS}`` or
``{Command CAMERA}``; not the answers to its client's commands), each line released when
``(sim_s - first_sim_s) / speed`` wall seconds have passed since the first of them was read.
The first part of a rotated
recording is played with the parts that continue it, as one flight (connection ids and robot
names run on across parts as the recorder wrote them); a later part named alone plays alone.
The files are read lazily, so a long recording costs no memory per client, and in slices
of ``_SLICE_RECORDS`` records, the client's lines answered between them (the NFO is sent on
connecting: another robot's records do not hold it). The client's own
lines go through the same sans-IO decoder as the simulator's: ``PING`` is answered with the
playback's current sim time; commands that would change the world (``INIT``, ``DRIVE``,
``SET``, ``STEP``) get ``ERR ... {Reason replay is read-only}``; the queries
(``GETSTARTPOSES``, ``GETGEO``, ``GETCONF``) get ``ERR`` too, as the recording holds no world
to ask. At the end of the recording the connection stays open (PING still answered) and
nothing more is sent. A file of the recording that can no longer be read (moved or deleted
since the replay started) is said to the client, ``ERR {Command REPLAY}``, and logged, and
its connection closes. A client that does not read blocks only its own thread; ``close()``
shuts every socket.
"""

from __future__ import annotations

import argparse
import logging
import select
import socket
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from skeye import cliargs
from skeye.errors import ConfigError, LocalProtocolError, RemoteProtocolError
from skeye.peers import accept_failed, listen
from skeye.processes import check_ports_free, on_stop_signals, wait_for_signal
from skeye.recording.records import SENT, Record, RecordingReader, robot_connections
from skeye.uris import url_host
from skeye.wire.sim import decode, encode, unknown_command
from skeye.wire.sim_lines import LineDecoder, LineError, Message, format_error, format_message
from skeye.wire.sim_messages import ROBOT_ERRORS, Ping

log = logging.getLogger(__name__)

READ_ONLY = frozenset(("INIT", "DRIVE", "SET", "STEP"))
_STREAM_PREFIXES = ("STA ", "SEN ", *(f"ERR {{Command {c}}} {{Name " for c in ROBOT_ERRORS))
"""The engine's lines (skeye.sim.stream), as opposed to the answers to the client's commands:
the engine's ERR names its robot, an answer to a client's unknown command ``CRASH`` does not."""
_MAX_BATCH_LINES = 512
_SLICE_RECORDS = 10_000
"""Records a playback reads before it looks at its client again: another robot's records do
not hold the client's NFO or answers while the playback reads past them (a robot spawned late
in a long recording)."""
MIN_SPEED, MAX_SPEED = 0.01, 1000.0
"""The playback rates a replay takes (``--speed``; 1 = as recorded)."""


class ReplayServer:
    """Plays one robot of a recording to every client that connects; a context manager.

    Args:
        path: the recording (a rotated one's first part: the whole flight).
        host, port: where to listen (port 0 picks a free one; read :attr:`port`).
        speed: playback rate (2.0 = twice as fast as recorded).
        robot: which recorded robot to play (default: the first one recorded).
    """

    def __init__(
        self,
        path: str | Path,
        host: str = "127.0.0.1",
        port: int = 3000,
        *,
        speed: float = 1.0,
        robot: str | None = None,
        max_clients: int = 64,
    ) -> None:
        if not (MIN_SPEED <= speed <= MAX_SPEED):
            raise LocalProtocolError(f"replay speed must be in [{MIN_SPEED:g}, {MAX_SPEED:g}], "
                                     f"got {speed}")
        self.reader = RecordingReader(path, follow_parts=True)
        self.speed = speed
        first_line_s: dict[int, float] = {}  # each connection's first stream line, sim time

        def noting_first_lines(records: Iterator[Record]) -> Iterator[Record]:
            for rec in records:
                if (rec.conn not in first_line_s and rec.direction == SENT
                        and rec.line.startswith(_STREAM_PREFIXES)):
                    first_line_s[rec.conn] = rec.sim_s
                yield rec

        self.robots = robot_connections(noting_first_lines(self.reader.records()))
        self.skipped_lines = self.reader.bad_lines
        """Records of the file that did not parse: counted, never played (said at the start)."""
        self.cut_short = self.reader.truncated
        """The file ends inside a line (a recording cut off by a crash): that line is not
        played."""
        if not self.robots:
            raise ConfigError(f"{path}: the recording holds no robot (no INIT answer, no robot "
                              "status line)")
        self.names = list(dict.fromkeys(self.robots.values()))
        """The recorded robots' names, each once, in the order they were first spawned."""
        chosen = self.names[0] if robot is None else robot  # "" is no robot's name
        # Every connection that flew a robot of this name: a robot spawned again under it on a
        # new connection (a pilot restarted, or re-attaching after the simulator removed its
        # robot) goes on with the same robot. Names are unique at any one time, so their
        # streams do not overlap.
        self.conns = frozenset(c for c, n in self.robots.items() if n == chosen)
        if not self.conns:
            raise ConfigError(f"no robot {chosen!r} in the recording; it holds "
                              f"{', '.join(self.names)}")
        self.robot = chosen
        self.first_sim_s = min((first_line_s[c] for c in self.conns if c in first_line_s),
                               default=0.0)
        """The sim time of the chosen robot's first stream line: each playback's clock starts
        there, on connecting (0 when the robot has none)."""
        try:  # each client's first line: a header it cannot be made of is refused now
            self._nfo = self._format_nfo()
        except LocalProtocolError as exc:
            raise RemoteProtocolError(f"{path}: recording header: its world cannot be sent in "
                                      f"the NFO line ({exc})") from None
        self.max_clients = max_clients
        self._threads: set[threading.Thread] = set()
        self._socks: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self._listener = listen(host, port)
        self._listener.settimeout(0.2)
        self.host = host
        self.port: int = self._listener.getsockname()[1]
        self._accept = threading.Thread(target=self._accept_loop, name="replay-accept", daemon=True)
        self._accept.start()

    def __enter__(self) -> ReplayServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def client_count(self) -> int:
        with self._lock:
            return len(self._socks)

    def nfo_line(self) -> bytes:
        """The line each client is sent first."""
        return self._nfo

    def _format_nfo(self) -> bytes:
        h = self.reader.header
        return format_message(
            "NFO",
            ("Gametype", "skeye"),
            ("Level", str(h.get("world", "unknown"))),
            ("TimeLimit", 0),
            ("TimeStep", float(h.get("timestep_s", 0.001))),
            ("Mode", "realtime"),
            ("Replay", True),
        )

    def stream(self) -> Iterator[tuple[float, bytes] | None]:
        """(sim time, line) of the chosen robot's stream, in recorded order; None after every
        ``_SLICE_RECORDS`` records read without one (the reader looks at its client then).

        Raises:
            ConfigError: a file of the recording can no longer be read (moved or deleted
                since the replay started: each client's playback reads it anew).
        """
        try:
            read = 0
            for rec in self.reader.records():
                if (rec.conn in self.conns and rec.direction == SENT
                        and rec.line.startswith(_STREAM_PREFIXES)):
                    read = 0
                    yield rec.sim_s, rec.line.encode() + b"\r\n"
                else:
                    read += 1
                    if read >= _SLICE_RECORDS:
                        read = 0
                        yield None
        except OSError as exc:  # the file's, not the client socket's (that is the caller's)
            raise ConfigError(f"the recording {exc.filename or self.reader.path} cannot be "
                              f"read: {exc.strerror or exc}") from None

    def _accept_loop(self) -> None:
        said_s = 0.0
        while not self._closing.is_set():
            try:
                sock, addr = self._listener.accept()
            except TimeoutError:
                continue
            except OSError as exc:  # out of descriptors: waited out; the listener closed: done
                when = accept_failed(exc, said_s, "replay")
                if when is None:
                    break
                said_s = when
                continue
            with self._lock:
                full = len(self._socks) >= self.max_clients
                if not full:
                    self._socks.add(sock)
                    t = threading.Thread(
                        target=self._serve, args=(sock,), name=f"replay {addr[1]}", daemon=True
                    )
                    self._threads.add(t)
            if full:
                # One non-blocking send, its failure ignored, as the simulator refuses: a
                # blocking sendall to a client that had reset its connection raised, and the
                # accept thread died of it (no client was taken again).
                log.warning("refusing client %s:%s: too many clients (%d)", addr[0], addr[1],
                            self.max_clients)
                try:
                    sock.setblocking(False)
                    sock.send(format_error("CONNECT", "too many clients"))
                except OSError:
                    pass
                sock.close()
                continue
            t.start()

    def _serve(self, sock: socket.socket) -> None:
        try:
            _Playback(self, sock).run()
        except ConfigError as exc:  # the recording, not the client: said to both
            log.error("replay: %s; client %s closed", exc, _peer(sock))
            try:
                sock.setblocking(False)
                sock.send(format_error("REPLAY", f"{exc}; closing"))
            except OSError:
                pass
        except OSError:  # the client went
            pass
        except Exception:
            log.exception("replay client failed")
        finally:
            with self._lock:
                self._socks.discard(sock)
                self._threads.discard(threading.current_thread())
            sock.close()

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop accepting, shut every client socket and join the threads; idempotent."""
        if self._closing.is_set():
            return
        self._closing.set()
        self._listener.close()
        self._accept.join(timeout_s)
        with self._lock:
            socks, threads = list(self._socks), list(self._threads)
        for s in socks:
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        deadline = time.monotonic() + timeout_s
        for t in threads:
            t.join(max(0.0, deadline - time.monotonic()))


_END = object()  # a playback's stream has no more lines


def _peer(sock: socket.socket) -> str:
    try:
        host, port = sock.getpeername()[:2]
    except OSError:
        return "(gone)"
    return f"{host}:{port}"


class _Playback:
    """One client's playback: a paced stream out, commands in, on one thread."""

    def __init__(self, server: ReplayServer, sock: socket.socket) -> None:
        self.server = server
        self.sock = sock
        self.decoder = LineDecoder()
        self.lines = server.stream()
        self.next_line: tuple[float, bytes] | None = None  # None: the end, or still reading
        self.reading = True  # the next line is not read yet (the file is read in slices)
        self.first_sim_s = server.first_sim_s
        self.sim_now_s = self.first_sim_s
        # The playback's clock starts with the robot's first line, once read: a robot far into
        # a long recording is paced from there (started on connecting, the lines of the read's
        # duration were all due at once when it ended, and went out in one burst).
        self.start = time.monotonic()
        self.clock_started = False

    def _due_sim_s(self) -> float:
        return self.first_sim_s + (time.monotonic() - self.start) * self.server.speed

    def _read_on(self) -> None:
        """One slice of the file further: the next line, or still reading, or the end."""
        item = next(self.lines, _END)
        self.reading = item is None
        self.next_line = item if isinstance(item, tuple) else None
        if self.next_line is not None and not self.clock_started:
            self.clock_started = True
            self.start = time.monotonic()

    def run(self) -> None:
        self.sock.sendall(self.server.nfo_line())
        while not self.server._closing.is_set():
            self._send_due()
            timeout = 0.5
            if self.reading:
                timeout = 0.0  # a look at the client, then the next slice
            elif self.next_line is not None:
                wait = (self.next_line[0] - self._due_sim_s()) / self.server.speed
                timeout = min(timeout, max(0.0, wait))
            readable, _, _ = select.select([self.sock], [], [], timeout)
            if readable:
                data = self.sock.recv(65536)
                if not data:
                    return
                if not self._handle(data):
                    return

    def _send_due(self) -> None:
        if self.reading:
            self._read_on()
        now = self._due_sim_s()  # after the read: it may have started the clock
        batch: list[bytes] = []
        while self.next_line is not None and self.next_line[0] <= now:
            self.sim_now_s = self.next_line[0]
            batch.append(self.next_line[1])
            self._read_on()
            if len(batch) >= _MAX_BATCH_LINES:
                self.sock.sendall(b"".join(batch))
                batch = []
        if batch:
            self.sock.sendall(b"".join(batch))

    def _handle(self, data: bytes) -> bool:
        """Answer what the client sent; False when the connection must close."""
        out: list[bytes] = []
        keep = True
        for event in self.decoder.feed(data):
            if isinstance(event, LineError):
                out.append(format_error(event.command, event.reason))
                keep = keep and not event.fatal
                continue
            out.append(self._answer(event))
        if out:
            self.sock.sendall(b"".join(out))
        return keep

    def _answer(self, msg: Message) -> bytes:
        if msg.type == "PING":
            try:  # refused as the simulator refuses it (a key, an Id too long or not printable)
                ping: Ping = decode(msg)
            except RemoteProtocolError as exc:
                return format_error("PING", str(exc))
            # the line last played while the next is not known (read on, or the end): the
            # clock past it could run beyond the next line's time, and go back once it is read
            sim_s = self.sim_now_s if self.next_line is None else self._due_sim_s()
            return format_message("RES", ("Command", "PING"), ("Id", ping.id), ("Time", sim_s))
        refused = unknown_command(msg.type)  # no command at all: the simulator's own answer
        if refused is not None:
            return encode(refused)
        if msg.type in READ_ONLY:
            return format_error(msg.type, "replay is read-only: the recording cannot be changed")
        return format_error(msg.type, f"{msg.type} is not available in a replay")


def cmd_replay(args: argparse.Namespace) -> int:
    """Serve a recording until stopped."""
    # before the recording is read: a taken port (the simulator's 3000) is named with --port
    check_ports_free([("the replay", args.host, args.port, "--port")])
    with ReplayServer(
        args.file, host=args.host, port=args.port, speed=args.speed, robot=args.robot
    ) as server:
        stop = threading.Event()
        on_stop_signals(lambda *_: stop.set())  # before its address is printed, as the sim's
        where = "all interfaces" if args.host in ("0.0.0.0", "::") else args.host
        parts = server.reader.parts
        if server.reader.broken is not None:
            print(f"skeye replay: warning: {server.reader.broken}: playing "
                  f"{', '.join(p.name for p in parts)} only", file=sys.stderr, flush=True)
        if server.skipped_lines:
            print(f"skeye replay: warning: {args.file}: {server.skipped_lines} "
                  f"line{'s' if server.skipped_lines > 1 else ''} that did not parse, skipped",
                  file=sys.stderr, flush=True)
        if server.cut_short:
            print(f"skeye replay: warning: {args.file}: its last line is cut short (the "
                  "recording ended in a crash?), not played", file=sys.stderr, flush=True)
        of = f" ({len(parts)} parts: {', '.join(p.name for p in parts)})" if len(parts) > 1 \
            else ""
        print(
            f"skeye replay: {args.file}{of}, robot {server.robot} (of "
            f"{', '.join(server.names)}), speed x{args.speed:g}; "
            f"control protocol on {url_host(args.host)}:{server.port} ({where})",
            flush=True,
        )
        if args.host == "127.0.0.1":
            print(
                "skeye replay: bound to 127.0.0.1 only; use --host 0.0.0.0 to accept other "
                "machines",
                flush=True,
            )
        wait_for_signal(stop)
        print("skeye replay: stopping", flush=True)
    return 0


def _speed(text: str) -> float:
    """``--speed``: a playback rate the replay takes, refused naming the option (the range was
    said only once the recording was read, without the option's name)."""
    value = cliargs.positive_float(text)
    if not MIN_SPEED <= value <= MAX_SPEED:
        raise argparse.ArgumentTypeError(f"must be {MIN_SPEED:g}..{MAX_SPEED:g} (1 = as "
                                         f"recorded), got {text!r}")
    return value


def register(sub: Any) -> None:
    """Add ``skeye replay`` to the command line."""
    p = sub.add_parser("replay", help="play a flight recording to clients (control protocol)")
    p.add_argument("file", type=cliargs.file_path, help="a recording made with skeye sim --record")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=cliargs.port, default=3000, help="port (0 = any free)")
    p.add_argument("--speed", type=_speed, default=1.0,
                   help=f"playback rate, {MIN_SPEED:g}..{MAX_SPEED:g} (1.0 = as recorded)")
    p.add_argument("--robot", default=None, help="recorded robot to play (default: the first)")
    p.set_defaults(func=cmd_replay)
