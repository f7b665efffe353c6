"""The control server: docs/protocols/simulator.md over TCP, many clients, one robot per connection.

How this works: an accept thread hands each connection to a
:class:`~skeye.sim.session.ClientSession` (its reader and writer threads, its states, its
commands: see :mod:`skeye.sim.session`), after checking the slots; the first line every client
gets is the ``NFO`` greeting.

Slots are bounded: at most ``max_clients`` connections, at most ``max_clients_per_peer`` from
one peer (:func:`skeye.peers.peer_key`: a local user, however many loopback addresses it
binds, or a remote address), and a connection that sends no line within
``handshake_timeout_s`` of connecting, or (while it drives no robot) none for
``idle_timeout_s``, gets ``ERR {Command CONNECT}`` with the reason and is closed. A connection
driving a robot is never closed for being quiet (a hovering robot needs no commands); TCP
keepalive finds its dead peers. A peer at its cap that connects again replaces its own
connection that has been quiet longest among those without a robot (it gets ``ERR {Command
CONNECT}`` saying so); only when all of them drive robots is the new one refused. The accept
thread never waits on a client: a refusal is one non-blocking send, and running out of file
descriptors (``EMFILE``) is logged (once a second at most) and waited out, never the end of it.

A command waits for the engine thread at most ``command_timeout_s`` (in lockstep another
client's long STEP holds it); one not taken up by then is withdrawn, never done, and answered
with an ``ERR`` saying so (:meth:`SimulationRunner.call`).

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
import socket
import threading
from collections.abc import Callable

from skeye.peers import accept_failed, listen, socket_peer_key
from skeye.sim.clock_barrier import ClockBarrier
from skeye.sim.limits import check_server_limits
from skeye.sim.runner import SimulationRunner
from skeye.sim.session import (
    OUTBOX_BYTES,
    ClientSession,
    LineObserver,
    set_camera,
    set_wind,
)
from skeye.wire.sim import encode
from skeye.wire.sim_messages import Err, Nfo, Set
from skeye.workers import Worker, WorkerFailed

__all__ = ["OUTBOX_BYTES", "ClientSession", "ControlServer", "LineObserver"]

log = logging.getLogger(__name__)

HANDSHAKE_TIMEOUT_S = 10.0  # a new connection must send its first line within this
COMMAND_TIMEOUT_S = 30.0  # a command the engine has not taken up by then is withdrawn
IDLE_TIMEOUT_S = 120.0  # a connection without a robot must send a line at least this often
MAX_CLIENTS_PER_PEER = 64  # connections of one peer, a user or address (half the 128 slots)


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
        command_timeout_s: float = COMMAND_TIMEOUT_S,
    ) -> None:
        check_server_limits("control server", max_clients=max_clients,
                            max_clients_per_peer=max_clients_per_peer,
                            handshake_timeout_s=handshake_timeout_s, idle_timeout_s=idle_timeout_s,
                            command_timeout_s=command_timeout_s)
        self.runner = runner
        self.max_clients = max_clients
        self.max_clients_per_peer = max_clients_per_peer
        self.handshake_timeout_s = handshake_timeout_s
        self.idle_timeout_s = idle_timeout_s
        self.command_timeout_s = command_timeout_s
        self.set_handlers: dict[str, Callable[[ClientSession, Set], None]] = {
            "wind": set_wind,
            "camera": set_camera,
        }
        self.observers: list[LineObserver] = []
        self.clock_barrier = ClockBarrier()  # STEP {Sync true}: engine thread only
        self._conn_ids = itertools.count(1)
        self._sessions: set[ClientSession] = set()
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self._listener = listen(host, port, backlog=socket.SOMAXCONN)
        self._listener.settimeout(0.2)
        self.host = host
        self.port = self._listener.getsockname()[1]
        self._accept_thread = Worker(self._accept_loop, "sim-accept").start()
        runner.failure_listeners.append(self.clock_barrier.fail)
        runner.failure_listeners.append(self._engine_failed)
        if runner.error is not None:
            self._engine_failed(runner.error)

    def _engine_error_line(self, error: WorkerFailed) -> bytes:
        return encode(Err("ENGINE", reason=f"{error}; the simulator is stopping"))

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
        return encode(Nfo(gametype="skeye", level=sim.world.name, time_limit=0,
                          time_step_s=sim.dt, mode=self.runner.mode))

    def _accept_loop(self) -> None:
        said_s = 0.0
        while not self._closing.is_set():
            try:
                sock, addr = self._listener.accept()
            except TimeoutError:
                continue
            except OSError as exc:
                when = accept_failed(exc, said_s, "control server")
                if when is None:
                    break
                said_s = when
                continue
            try:
                self._admit(sock, f"{addr[0]}:{addr[1]}")
            except OSError as exc:  # the client went already: nothing to serve
                log.info("client %s:%s gone while connecting: %s", addr[0], addr[1], exc)
                sock.close()
            except Exception:  # a fault in greeting one client never ends the accepting
                log.exception("could not admit client %s:%s; its connection is closed",
                              addr[0], addr[1])
                sock.close()

    def _admit(self, sock: socket.socket, peer: str) -> None:
        """A new connection: served, or refused with one non-blocking line (never waits)."""
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        _keepalive(sock)
        key = socket_peer_key(sock)
        session = ClientSession(self, sock, peer, next(self._conn_ids), peer_key=key)
        refusal: bytes | None = None
        replaced: ClientSession | None = None
        with self._lock:
            mine = [s for s in self._sessions if s.peer_key == key and not s.replaced]
            if self.runner.error is not None:
                refusal = self._engine_error_line(self.runner.error)
            elif len(mine) >= self.max_clients_per_peer:
                idle = [s for s in mine if s.robot_name is None]
                if idle:
                    replaced = min(idle, key=lambda s: s.last_line_s)
                    replaced.replaced = True
                    self._sessions.add(session)
                else:
                    refusal = encode(Err(
                        "CONNECT", reason=f"too many clients from {key} "
                        f"({self.max_clients_per_peer} per user or address, all driving "
                        "robots)"))
            elif len(self._sessions) >= self.max_clients:
                refusal = encode(Err("CONNECT", reason="too many clients"))
            else:
                self._sessions.add(session)
        if replaced is not None:
            log.info("client %s replaces %s, its quietest connection without a robot (%s)",
                     peer, replaced.peer, key)
            replaced.send(encode(Err(
                "CONNECT", reason=f"replaced by a newer connection of {key} "
                f"({self.max_clients_per_peer} per user or address); closed")))
            replaced.end()
        if refusal is not None:
            log.warning("refusing client %s: %s", session.peer, refusal.decode().strip())
            try:
                sock.setblocking(False)
                sock.send(refusal)
            except OSError:
                pass
            sock.close()
            return
        try:
            if self.observers:
                self.notify(session.conn_id, "+", session.peer.encode())
            session.send(self.nfo_line())
            session.start()
        except BaseException:  # not served: its slot is free again
            with self._lock:
                self._sessions.discard(session)
            raise
        log.info("client %s connected (%s)", session.peer, key)

    def forget(self, session: ClientSession) -> None:
        """A session ended: free its slot and tell the observers."""
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
