"""The pilot's I/O: one ground-control link (TCP or serial), the boards, and the loop that ticks.

How this works: ``PilotServer`` wraps an ``OnboardBoards`` (sans-IO) with threads:

- an accept thread (TCP) hands each connection a ``TcpLink`` and its own reader thread at
  once: it never waits on a client. Exactly one client is served: a connection arriving while
  another is served gets ``RESULT(0x00, code 5, reason)`` (after a short grace, in its own
  thread, for a holder that has just hung up) and is closed; the first is not touched. A
  connection becomes the served client with its first packet (or bad frame), so idle
  connections never hold the slot; before that, one peer (a local user however many loopback
  addresses it binds, or a remote address: :func:`skeye.peers.peer_key`) holds at most
  ``MAX_PENDING_PER_PEER`` connections (a newer one replaces its oldest). A serial port is the
  single client for the whole run. Running out of file descriptors is logged and waited out,
  never the end of the accept thread.
- one reader thread per link alone calls ``link.recv``, feeds a fresh
  ``CommandStreamParser`` and answers each event at once (``boards.handle``), so a poll's
  round trip never waits for the loop. Garbage is counted by the parser and the boards; the
  reader never stops on bad input.
- one sender thread per served link (``skeye.pilot.outbox.Outbox``) alone writes to it: the
  reader's answers and the loop's telemetry are queued, never sent inline, so a ground client
  that stops reading loses telemetry (dropped, counted) and is closed after the link's send
  timeout; the loop keeps ticking and the vehicle is never declared lost for it.
- a TCP client that sends no valid packet within the link timeout of connecting is closed (a
  silent connection must not hold the one client slot); a client whose last packet is older
  than the link timeout is replaced by the next one that sends a packet. Accepted sockets use TCP
  keepalive, so a peer that vanished without a FIN is noticed. The link-loss failsafe counts
  from the last packet: a connection alone (without packets) does not reset it.
- a TCP connection whose first bytes are an HTTP request line (``POST /...``) is closed before
  anything it sends is parsed: a web page cannot make the browser send packets in a request
  body (a cross-protocol request) to fly the vehicle.
- the loop thread calls ``boards.tick`` every ``tick_s`` (stream, flight-state progress,
  failsafe) and, when the simulator is in lockstep, drives sim time: it advances the sim by
  ``tick_s`` per iteration, paced to ``lockstep_rate`` sim seconds per wall second (0 = as
  fast as the CPU allows). Time given to the boards is the wall clock (``time.monotonic``):
  the link-loss timeouts are about the radio link, which runs on wall time (on a simulator the
  boards also wait for as much sim time: a slow simulator is not a silent station).

When the vehicle below is lost (the simulator died, froze, or removed the robot and a RESET
asked for a new one) and the airframe can re-attach (``SimAirframe`` with an ``attach``
factory: ``needs_attach``), a re-attach thread tries every ``reattach_s`` to connect and spawn
anew, off the loop; the loop swaps the new vehicle in (``bind``), points the vision at it,
tells the boards (LANDED, HEALTH OK) and logs it. Until then the loop keeps ticking: the ground
link, telemetry and failsafe go on, and HEALTH says LOST and why.

With a video server (``video=``, :mod:`skeye.pilot.video_server`), the vision's frames and
detections are served on the vehicle's video port; it starts and stops with this server.

One lock serialises every call into the boards; sends are thread-safe in the links. Stopping
(``close``) is idempotent and joins every thread with a deadline.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from skeye.errors import ConfigError, InvalidArgument, SkeyeError
from skeye.link.transport import Link, LinkClosed, TcpLink, open_link
from skeye.peers import accept_failed, listen, socket_peer_key
from skeye.pilot.airframe import Airframe
from skeye.pilot.boards import NO_COMMAND_PD, BoardSettings, OnboardBoards
from skeye.pilot.outbox import Outbox
from skeye.pilot.video_server import VideoServer
from skeye.wire.packets import (
    CommandStreamParser,
    Message,
    Result,
    ResultCode,
    arrived_intact,
    encode,
)
from skeye.workers import Worker

log = logging.getLogger(__name__)

DEFAULT_PORT = 7000
DEFAULT_TICK_S = 0.01
MAX_PENDING_PER_PEER = 4
"""Connections one peer (a local user, a remote address) may hold before their first packet."""
MAX_PENDING = 32
"""Connections all peers together may hold before their first packet."""
HANDOVER_GRACE_S = 0.5
"""How long a new ground station waits for the current one's connection to finish closing (it
may have hung up a moment ago, its reader not yet noticed) before being turned away as busy."""
SEND_TIMEOUT_S = 5.0
"""A ground client that takes no byte of what the pilot sends for this long is closed."""
SEND_BUFFER_BYTES = 64 * 1024
"""Kernel send buffer of a ground client's socket: telemetry a client has not read waits in the
pilot's outbox (where it can be dropped), not in megabytes of kernel buffer going stale."""
HTTP_METHODS = (b"GET ", b"POST ", b"PUT ", b"HEAD ", b"OPTIONS ", b"DELETE ", b"PATCH ",
                b"CONNECT ", b"TRACE ")
REATTACH_S = 1.0
"""How often the pilot tries to re-attach to a lost simulator."""
STOP_S = 1.0
"""What ``close()`` waits for the threads, in all: one control tick and a simulator's answer
take milliseconds; a frozen simulator's answer never comes, and Ctrl-C must stop the pilot."""
KEEPALIVE_IDLE_S = 10
KEEPALIVE_INTERVAL_S = 5
KEEPALIVE_COUNT = 3


@dataclass(eq=False)
class ClientSession:
    """One ground client: its link, its outbox (once served), and when it last sent a packet."""

    link: Link
    outbox: Outbox | None
    connected_s: float
    tcp: bool
    key: str = ""  # whose connection it is (skeye.peers): a local user or a remote address
    claimed: bool = False  # the served client (its first packet took the slot)
    last_packet_s: float | None = None
    packets: int = 0  # valid packets (not garbage) received


def _tune(sock: socket.socket) -> None:
    """A bounded send buffer, and TCP keepalive: a peer gone without a FIN is noticed in
    about 25 s."""
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER_BYTES)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
    for name, value in (
        ("TCP_KEEPIDLE", KEEPALIVE_IDLE_S),
        ("TCP_KEEPINTVL", KEEPALIVE_INTERVAL_S),
        ("TCP_KEEPCNT", KEEPALIVE_COUNT),
    ):
        if hasattr(socket, name):
            sock.setsockopt(socket.IPPROTO_TCP, getattr(socket, name), value)


class PilotServer:
    """Serve one ground-control client at a time over TCP, or a serial line.

    Args:
        airframe: the vehicle (``SimAirframe`` on the simulator).
        host, port: where to listen for TCP (port 0: any free port; see ``self.port``).
        serial_uri: ``serial:///dev/ttyX?baud=57600`` instead of TCP.
        settings: link-loss timeouts and other tunables of the boards.
        tick_s: loop period (stream resolution, failsafe resolution, lockstep step).
        lockstep: drive the simulator's clock (it is in lockstep mode).
        lockstep_rate: sim seconds per wall second when driving the clock; 0 = unpaced.
        ground_clock: in lockstep, advance sim time only up to what the ground station granted
            with CLOCK packets (a scripted ground client then acts at exact sim times).
        clock: wall clock in seconds (injectable for tests).
    """

    def __init__(
        self,
        airframe: Airframe,
        *,
        host: str = "127.0.0.1",
        port: int | None = DEFAULT_PORT,
        serial_uri: str | None = None,
        settings: BoardSettings | None = None,
        tick_s: float = DEFAULT_TICK_S,
        lockstep: bool = False,
        lockstep_rate: float = 1.0,
        ground_clock: bool = False,
        clock: Callable[[], float] = time.monotonic,
        vision: Callable[[OnboardBoards, threading.Lock], Any] | None = None,
        video: VideoServer | None = None,
        reattach_s: float = REATTACH_S,
    ) -> None:
        if (port is None) == (serial_uri is None):
            raise ConfigError("PilotServer needs exactly one of port= or serial_uri=")
        if not tick_s > 0 or lockstep_rate < 0:
            raise InvalidArgument(
                f"tick_s must be > 0 and lockstep_rate >= 0 ({tick_s}, {lockstep_rate})"
            )
        self.airframe = airframe
        self.clock = clock
        self.tick_s = tick_s
        self.lockstep = lockstep
        self.lockstep_rate = lockstep_rate
        self.ground_clock = ground_clock and lockstep
        self.boards = OnboardBoards(airframe, settings, now_s=clock())
        self.turned_away = 0
        self.loop_error: BaseException | None = None
        self.vehicle_lost: str | None = None  # why the simulator/vehicle stopped answering
        self.reattach_s = reattach_s
        self.reattached = 0  # times a new vehicle was swapped in
        self.loop_faults = 0  # ticks whose boards or vision step raised (reported, not fatal)
        self._faults_said: set[str] = set()
        self._attached: tuple[Any, Any] | None = None  # from the re-attach thread to the loop
        self._lock = threading.Lock()
        # The landing-pad vision (skeye.pilot.vision.PadVision), stepped after every tick.
        self.vision = vision(self.boards, self._lock) if vision is not None else None
        # The vehicle's video port: what the vision saw and detected, for ground control.
        self.video = video
        if video is not None and self.vision is not None:
            self.vision.attach_video(video.publish)
        self._client: Link | None = None
        self._session: ClientSession | None = None
        self.closed_idle = 0  # TCP clients closed for sending nothing after connecting
        self.replaced_silent = 0  # silent clients replaced by a new one
        self.replaced_pending = 0  # connections closed for a newer one of the same peer
        self._candidates: list[ClientSession] = []  # connected, not served yet
        self.refused_http = 0  # connections closed for sending an HTTP request
        self._client_lock = threading.Lock()
        self._client_changed = threading.Condition(self._client_lock)
        self._stop = threading.Event()
        self._threads: list[Worker] = []
        self._threads_lock = threading.Lock()
        self._listener: socket.socket | None = None
        self.host = host
        self.port: int | None = None
        self.serial_uri = serial_uri
        if port is not None:
            self._listener = listen(host, port, backlog=socket.SOMAXCONN)
            self._listener.settimeout(0.2)
            self.port = self._listener.getsockname()[1]

    @property
    def lock(self) -> threading.Lock:
        """The lock every call into the boards takes (the MAVLink endpoint takes it too)."""
        return self._lock

    @property
    def address(self) -> str:
        """Where the pilot listens: ``tcp://host:port`` or the serial URI."""
        return self.serial_uri or f"tcp://{self.host}:{self.port}"

    # -- lifecycle -----------------------------------------------------------------------
    def start(self) -> PilotServer:
        """Start the loop and the accept thread (or open the serial port); returns self.

        Raises:
            LinkClosed: the serial port cannot be opened (nothing is started then).
        """
        serial = None if self.serial_uri is None else open_link(self.serial_uri)
        if self.video is not None:
            self.video.start()
        self._spawn(self._loop, "pilot-loop")
        if hasattr(self.airframe, "attach_new"):
            self._spawn(self._reattach_loop, "pilot-reattach")
        if serial is not None:
            self._serve(serial)
        else:
            self._spawn(self._accept_loop, "pilot-accept")
        return self

    def _spawn(self, target: Callable[..., None], name: str, *args: object) -> None:
        with self._threads_lock:
            # A reader ends with its connection: forget the ended ones (each held its session,
            # link and outbox), so connections that come and go cost nothing that lasts.
            self._threads[:] = [t for t in self._threads if t.alive]
            self._threads.append(Worker(target, name, args=args).start())

    @property
    def threads(self) -> int:
        """Worker threads held (loop, accept, re-attach and one reader per connection)."""
        with self._threads_lock:
            return len(self._threads)

    def serve_forever(self) -> None:
        """Run until ``close()`` (or Ctrl-C in the caller); re-raises a loop failure."""
        self.start()
        while not self._stop.wait(0.5):
            pass
        if self.loop_error is not None:
            raise self.loop_error

    def close(self, timeout_s: float = STOP_S) -> None:
        """Stop every thread and close the links (idempotent). Every wait shares one deadline,
        ``timeout_s`` in all; a thread still busy then (the loop waiting on a frozen
        simulator's answer) is a daemon, and ends when the airframe is closed."""
        deadline = time.monotonic() + timeout_s

        def left() -> float:
            return max(0.0, deadline - time.monotonic())

        self._stop.set()
        if self._listener is not None:
            self._listener.close()
        with self._client_lock:
            client = self._client
            session = self._session
            pending = list(self._candidates)
        if client is not None:
            client.close()
        if session is not None and session.outbox is not None:
            session.outbox.close()
        for waiting in pending:
            waiting.link.close()
        with self._threads_lock:
            workers = list(self._threads)
        close_vision = getattr(self.vision, "close", None)
        if close_vision is not None:  # first: it wakes a frame request the loop may wait on
            close_vision(left())
        for t in workers:
            t.join(left())  # returns at once for the calling thread's own worker
        if self.video is not None:
            self.video.close(max(left(), 0.2))  # its own thread, never on the simulator

    def __enter__(self) -> PilotServer:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def pending(self) -> int:
        """TCP connections accepted that have not sent their first packet yet."""
        with self._client_lock:
            return len(self._candidates)

    @property
    def client(self) -> Link | None:
        """The ground-control link being served, if any."""
        return self._client

    # -- clients -------------------------------------------------------------------------
    @property
    def session(self) -> ClientSession | None:
        """The served client's session (link, outbox, packet times), if any."""
        return self._session

    def _silent(self, session: ClientSession | None) -> bool:
        """Has this client been silent for the link timeout (since its last packet)?"""
        if session is None:
            return False
        last = session.last_packet_s if session.last_packet_s is not None else session.connected_s
        return self.clock() - last >= self.boards.settings.link_timeout_s

    def _accept_loop(self) -> None:
        """Accept and hand over at once: this thread never waits on a client."""
        assert self._listener is not None
        said_s = 0.0
        while not self._stop.is_set():
            try:
                sock, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError as exc:
                when = accept_failed(exc, said_s, "pilot")
                if when is None:
                    break
                said_s = when
                continue
            try:
                _tune(sock)
            except OSError:
                pass
            key = socket_peer_key(sock)
            self._candidate(TcpLink(sock, send_timeout_s=SEND_TIMEOUT_S), key)

    def _candidate(self, link: Link, key: str) -> None:
        """A new TCP connection: it reads on its own thread and becomes the served client with
        its first packet. A peer holds at most ``MAX_PENDING_PER_PEER`` such connections
        (its oldest is closed for a new one), all peers together ``MAX_PENDING``."""
        session = ClientSession(link, None, self.clock(), tcp=True, key=key)
        closing: list[ClientSession] = []
        with self._client_lock:
            mine = [c for c in self._candidates if c.key == key]
            if len(mine) >= MAX_PENDING_PER_PEER:
                closing.append(mine[0])
            elif len(self._candidates) >= MAX_PENDING:
                closing.append(self._candidates[0])
            for old in closing:
                self._candidates.remove(old)
            self._candidates.append(session)
        for old in closing:
            self.replaced_pending += 1
            log.info("%s: a newer connection of %s replaces it before its first packet",
                     old.link.name, old.key)
            old.link.close()
        self._spawn(self._read_loop, f"pilot-read-{link.name}", session)

    def _turn_away(self, link: Link, current: str) -> None:
        self.turned_away += 1
        reason = f"busy: this vehicle serves one ground station and {current} is connected"
        log.info("turning away %s: %s", link.name, reason)
        try:
            link.send(encode(Result(NO_COMMAND_PD, ResultCode.BUSY, reason)))
        except LinkClosed:
            pass
        link.close()

    def _serve(self, link: Link) -> None:
        """The serial port: the one client for the whole run."""
        session = ClientSession(link, None, self.clock(), tcp=False)
        self._claim(session)
        self._spawn(self._read_loop, f"pilot-read-{link.name}", session)

    def _busy_with(self) -> str:
        """The served client's name while it is live (connected and not silent), else ""; a
        silent one is closed here (the caller is taking its place). Under ``_client_lock``."""
        client, served = self._client, self._session
        if client is None or client.closed or served is None:
            return ""
        if self._silent(served):
            self.replaced_silent += 1
            log.info("ground control on %s silent for the link timeout: replaced",
                     served.link.name)
            client.close()
            return ""
        return client.name

    def _claim(self, session: ClientSession) -> bool:
        """Make ``session`` the served client if the slot is free (or its holder silent):
        True; else False (it is turned away)."""
        with self._client_changed:
            if session.tcp:
                # The holder may have hung up a moment ago, its reader not yet noticed.
                self._client_changed.wait_for(lambda: not self._busy_with(), HANDOVER_GRACE_S)
                current = self._busy_with()
                if session in self._candidates:
                    self._candidates.remove(session)
                if current:
                    session.claimed = False
                else:
                    session.claimed = True
            else:
                current = ""
                session.claimed = True
            if session.claimed:
                session.outbox = Outbox(session.link).start()
                self._client = session.link
                self._session = session
        if not session.claimed:
            self._turn_away(session.link, current)
            return False
        with self._lock:
            self.boards.client_gone(self.clock())  # a new client starts with no stream
        log.info("serving ground control on %s", session.link.name)
        return True

    def _read_loop(self, session: ClientSession) -> None:
        link = session.link
        parser = CommandStreamParser()
        timeout_s = self.boards.settings.link_timeout_s
        head: bytes | None = b""  # first bytes, until they cannot start an HTTP request
        try:
            if session.tcp:
                # A station that connects while another is served is told so at once (after
                # the hand-over grace), without waiting for its first packet.
                with self._client_changed:
                    self._client_changed.wait_for(lambda: not self._busy_with(),
                                                  HANDOVER_GRACE_S)
                    current = self._busy_with()
                if current:
                    with self._client_lock:
                        if session in self._candidates:
                            self._candidates.remove(session)
                    self._turn_away(link, current)
                    return
            while not self._stop.is_set():
                if session.tcp and session.packets == 0:
                    if self.clock() - session.connected_s >= timeout_s:
                        self.closed_idle += 1
                        log.info(
                            "ground control on %s sent no packet within %g s: closed",
                            link.name,
                            timeout_s,
                        )
                        break
                data = link.recv(0.1)
                if not data:
                    continue
                if session.tcp and head is not None:
                    head += data
                    if any(head.startswith(m) for m in HTTP_METHODS):
                        log.warning("%s sent an HTTP request, not packets: closed", link.name)
                        self.refused_http += 1
                        break
                    if len(head) < max(map(len, HTTP_METHODS)) and any(
                        m.startswith(head) for m in HTTP_METHODS
                    ):
                        continue  # too short to tell yet: wait for more
                    data, head = head, None
                for event in parser.feed(data):
                    now = self.clock()
                    if not session.claimed and not self._claim(session):
                        return  # its first packet (or error) found another station served
                    if arrived_intact(event):
                        session.packets += 1
                        session.last_packet_s = now
                    with self._lock:
                        replies = self.boards.handle(event, now)
                    self._send(session, replies, droppable=False)
        except LinkClosed:
            pass
        finally:
            if session.outbox is not None:
                session.outbox.close()
            link.close()
            with self._client_changed:
                if session in self._candidates:
                    self._candidates.remove(session)
                was_served = self._client is link
                if was_served:
                    self._client = None
                    self._session = None
                self._client_changed.notify_all()
            if was_served:
                with self._lock:
                    self.boards.client_gone(self.clock())
                log.info("ground control on %s went away", link.name)

    def _send(self, session: ClientSession, replies: list[Message], *, droppable: bool) -> None:
        if replies and session.outbox is not None:
            session.outbox.put(b"".join(encode(m) for m in replies), droppable=droppable)

    # -- the loop ------------------------------------------------------------------------
    def _check_vehicle(self) -> None:
        """Raise if the airframe reports its link (the simulator) down."""
        error = getattr(self.airframe, "lost", None)
        if error:
            raise SkeyeError(error)

    def _clock_held(self) -> bool:
        """With ``ground_clock``: True once sim time has reached the granted time (the last tick
        may pass it by less than one tick)."""
        if not self.ground_clock:
            return False
        with self._lock:
            until_s = self.boards.clock_until_s
        return self.airframe.snapshot().time_s >= until_s - 1e-6

    def _lose_vehicle(self, reason: str) -> None:
        if self.vehicle_lost is None:
            self.vehicle_lost = reason
            log.error("vehicle lost: %s; ground link kept, failsafe applies", reason)
            with self._lock:
                self.boards.vehicle_lost(self.clock(), reason)

    # -- re-attaching ----------------------------------------------------------------------
    def _reattach_loop(self) -> None:
        """Off the loop: connect and spawn anew while the airframe needs it; the loop swaps
        the result in. Failures are expected (the simulator is not back yet) and logged once
        per distinct reason."""
        airframe: Any = self.airframe
        said = ""
        while not self._stop.wait(self.reattach_s):
            if self._attached is not None or not airframe.needs_attach:
                said = ""
                continue
            try:
                pair = airframe.attach_new()
            except (SkeyeError, OSError) as exc:
                if str(exc) != said:
                    said = str(exc)
                    log.warning("re-attaching: the simulator is not back yet: %s", exc)
                continue
            self._attached = pair

    def _swap_in(self) -> None:
        """The loop's side: fly the re-attached vehicle (its thread handed it over)."""
        pair, self._attached = self._attached, None
        if pair is None:
            return
        airframe: Any = self.airframe
        with self._lock:
            what = airframe.bind(*pair)
            if self.vision is not None and hasattr(self.vision, "rebind"):
                self.vision.rebind(airframe.robot)
            self.boards.respawned(what)
            self.vehicle_lost = None
        self.reattached += 1
        log.warning("vehicle back: %s", what)

    def _tick(self) -> list[Message]:
        """The boards' tick; a value they cannot handle is reported (counted, logged once per
        kind) and the loop goes on: it is not a lost vehicle."""
        try:
            with self._lock:
                return self.boards.tick(self.clock())
        except Exception as exc:
            self._loop_fault("the boards' tick", exc)
            return []

    def _step_vision(self) -> None:
        """The vision's control-loop side; its failures are reported like the tick's."""
        if self.vision is None:
            return
        try:
            self.vision.step()
        except Exception as exc:
            self._loop_fault("the vision's step", exc)

    def _loop_fault(self, where: str, exc: Exception) -> None:
        self.loop_faults += 1
        kind = f"{where}: {type(exc).__name__}"
        if kind not in self._faults_said:
            self._faults_said.add(kind)
            log.error("%s failed, the loop goes on (said once per kind): %s", where, exc,
                      exc_info=exc)

    def _loop(self) -> None:
        try:
            next_s = self.clock()
            while not self._stop.is_set():
                try:
                    if self._attached is not None:
                        self._swap_in()
                    out = self._tick()
                    session = self._session
                    if session is not None and out:
                        self._send(session, out, droppable=True)  # never blocks the loop
                    if self.vehicle_lost is None and not self._clock_held():
                        self._check_vehicle()
                        self.airframe.advance(self.tick_s)  # no-op for time unless lockstep
                        self._step_vision()
                    elif self.ground_clock:
                        self._stop.wait(0.001)  # wait for a CLOCK grant
                        continue
                except SkeyeError as exc:
                    if self._stop.is_set():  # stopping: the airframe was closed under it
                        break
                    # The simulator (the vehicle's hardware) went away: keep the ground link,
                    # report it, and let the failsafe run; every command now gets a refusal.
                    self._lose_vehicle(str(exc))
                if self.lockstep:
                    if self.lockstep_rate > 0:
                        next_s += self.tick_s / self.lockstep_rate
                        delay = next_s - self.clock()
                        if delay < -1.0:  # fell behind: do not try to catch up in a burst
                            next_s = self.clock()
                        elif delay > 0:
                            self._stop.wait(delay)
                else:
                    next_s += self.tick_s
                    delay = next_s - self.clock()
                    if delay < -1.0:
                        next_s = self.clock()
                    self._stop.wait(max(0.0, delay))
        except BaseException as exc:
            log.exception("pilot loop failed")
            self.loop_error = exc
            self._stop.set()
