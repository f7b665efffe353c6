"""The pilot's video port: its camera frames, each with its own pad detection, to ground control.

How this works: the vision thread (:mod:`skeye.pilot.vision`) hands every frame it has looked
at to :meth:`VideoServer.publish`: the BGR pixels, the frame number and capture time, and the
detector's result. ``publish`` only replaces the newest-frame slot and wakes the server's one
I/O thread (a :class:`~skeye.workers.Worker`); it never waits, so neither the vision thread nor
the control loop can be slowed by a viewer. That thread alone owns every socket of the port
(a ``selectors`` loop over non-blocking sockets) and speaks docs/protocols/video.md through one
sans-IO :class:`~skeye.wire.video.VideoConnection` per client:

- a client must SUBSCRIBE within ``subscribe_timeout_s`` of connecting, else it gets ERROR and
  is closed (an idle connection does not hold one of the ``max_clients`` slots); one peer (a
  local user however many loopback addresses it binds, or a remote address:
  :func:`skeye.peers.peer_key`) holds all slots but one (at least one); a new connection
  beyond a cap takes the place of the oldest connection that has not subscribed (its peer's own
  first), and only when every one in its way streams does it get ERROR ("busy") and is closed
  at once; running short of file descriptors is waited out;
- bytes that are not the protocol (an HTTP request, garbage, a message the client may not send)
  get ERROR naming the problem and the connection is closed; other clients are not touched; a
  message under way to that client goes out whole first (the client is ``closing``: nothing
  more is read from it, and it is closed when its ERROR has gone out or it takes nothing for
  ``send_timeout_s``);
- the newest frame is JPEG-encoded once (OpenCV, ``jpeg_quality``) when some client will take
  it, and queued to each subscribed client whose previous frame has left its buffer and whose
  rate (the smaller of its SUBSCRIBE and the server's ``max_fps``) allows; a client still
  sending the previous frame misses this one (counted in its ``dropped``): a slow viewer gets
  fewer frames, never old ones, and costs the server one frame of memory;
- a client that takes no byte for ``send_timeout_s`` is closed.

The listener binds 127.0.0.1 unless told otherwise. ``close`` is idempotent and joins the thread
with a deadline; a failure of the thread reaches the owner through :meth:`check`.
"""

from __future__ import annotations

import logging
import selectors
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType

import cv2
import numpy as np

from skeye.errors import ConfigError, LocalProtocolError, RemoteProtocolError
from skeye.peers import accept_failed, listen, socket_peer_key
from skeye.wire.video import (
    DEFAULT_JPEG_QUALITY,
    Detection,
    Error,
    Frame,
    Hello,
    Role,
    State,
    Subscribe,
    VideoConnection,
    encode,
)
from skeye.workers import Worker

log = logging.getLogger(__name__)

DEFAULT_VIDEO_PORT = 7001
DEFAULT_MAX_FPS = 10.0
DEFAULT_MAX_CLIENTS = 4
SUBSCRIBE_TIMEOUT_S = 5.0
SEND_TIMEOUT_S = 5.0
SEND_BUFFER_BYTES = 64 * 1024
_POLL_S = 0.02  # the loop's longest sleep: rate slots and timeouts are this fine


@dataclass(frozen=True)
class CameraFrame:
    """What the vision thread publishes: one frame it looked at and what it saw."""

    frame_number: int
    time_s: float
    bgr: np.ndarray
    detection: Detection
    detect_ms: float


@dataclass(frozen=True)
class ClientStats:
    """One client as the server sees it."""

    peer: str
    state: str
    max_fps: float
    frames_sent: int
    dropped: int
    buffered_bytes: int


@dataclass
class _Client:
    sock: socket.socket
    peer: str
    conn: VideoConnection
    connected_s: float
    out: bytearray
    max_fps: float = 0.0
    last_frame_s: float = -1e9
    last_seq: int = 0
    stalled_since_s: float | None = None  # output waiting, no byte taken since
    frames_sent: int = 0
    dropped: int = 0
    key: str = ""  # whose connection it is (skeye.peers)
    closing: bool = False  # its ERROR queued after a message under way; closed once out

    @property
    def streaming(self) -> bool:
        return self.conn.state is State.STREAMING


class VideoServer:
    """Serve the vehicle's camera and detections on a TCP port (a context manager).

    Args:
        host, port: where to listen (port 0: any free port; see ``self.port``).
        camera: the camera's name, told to clients in HELLO.
        fov_h_rad: its horizontal field of view, told to clients.
        jpeg_quality: OpenCV JPEG quality 1..100.
        max_fps: the most frames per second sent to any client.
        max_clients: clients served at once; more are refused with ERROR.
        subscribe_timeout_s: a client that has not subscribed by then is closed.
        send_timeout_s: a client that takes no byte for this long is closed.
        clock: monotonic seconds (injectable).
    """

    def __init__(
        self,
        *,
        host: str = "127.0.0.1",
        port: int = DEFAULT_VIDEO_PORT,
        camera: str = "Down",
        fov_h_rad: float,
        jpeg_quality: int = DEFAULT_JPEG_QUALITY,
        max_fps: float = DEFAULT_MAX_FPS,
        max_clients: int = DEFAULT_MAX_CLIENTS,
        subscribe_timeout_s: float = SUBSCRIBE_TIMEOUT_S,
        send_timeout_s: float = SEND_TIMEOUT_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        try:
            self.hello = Hello(camera, fov_h_rad, jpeg_quality, max_fps)
        except LocalProtocolError as exc:
            raise ConfigError(f"video server: {exc}") from None
        if max_clients < 1 or not subscribe_timeout_s > 0 or not send_timeout_s > 0:
            raise ConfigError(
                f"video server: max_clients >= 1 and timeouts > 0 needed ({max_clients}, "
                f"{subscribe_timeout_s}, {send_timeout_s})"
            )
        self.max_clients = max_clients
        self.max_clients_per_peer = max(1, max_clients - 1)  # one slot left for someone else
        self.subscribe_timeout_s = subscribe_timeout_s
        self.send_timeout_s = send_timeout_s
        self.clock = clock
        self.host = host
        self.published = 0  # frames handed over by the vision thread
        self.encoded = 0  # frames JPEG-encoded (only while some client takes them)
        self.bad_frames = 0  # frames that could not be encoded (logged, skipped)
        self.frames_sent = 0
        self.turned_away = 0  # refused: all slots taken
        self._accept_said_s = 0.0  # when a failing accept() was last logged
        self.bad_clients = 0  # closed for bytes that are not the protocol
        self.idle_closed = 0  # closed for not subscribing in time
        self.slow_closed = 0  # closed for taking nothing for send_timeout_s
        self._lock = threading.Lock()
        self._pending: CameraFrame | None = None
        self._seq = 0  # of the newest published frame
        self._jpeg: tuple[int, bytes] | None = None  # (seq, FRAME message bytes)
        self._current: tuple[int, CameraFrame] | None = None
        self._clients: dict[int, _Client] = {}
        self._stop = threading.Event()
        self._listener = listen(host, port, backlog=socket.SOMAXCONN)
        self._listener.setblocking(False)
        self.port: int = self._listener.getsockname()[1]
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._worker: Worker | None = None

    @property
    def address(self) -> str:
        return f"tcp://{self.host}:{self.port}"

    # -- lifecycle -----------------------------------------------------------------------
    def start(self) -> VideoServer:
        if self._worker is None:
            self._worker = Worker(self._run, "pilot-video").start()
        return self

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop the thread, close every socket (idempotent)."""
        self._stop.set()
        self._wake()
        if self._worker is not None:
            self._worker.join(timeout_s)
        if self._worker is None or not self._worker.alive:
            for client in list(self._clients.values()):
                client.sock.close()
            self._clients.clear()
            self._listener.close()
            self._wake_r.close()
            self._wake_w.close()

    def __enter__(self) -> VideoServer:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def check(self) -> None:
        """Raise :class:`~skeye.workers.WorkerFailed` if the server's thread died."""
        if self._worker is not None:
            self._worker.check()

    # -- the vision thread's side ----------------------------------------------------------
    def publish(self, frame: CameraFrame) -> None:
        """Offer the newest frame; returns at once (see the module comment)."""
        with self._lock:
            self._pending = frame
            self.published += 1
        self._wake()

    def _wake(self) -> None:
        try:
            self._wake_w.send(b"\0")
        except (BlockingIOError, OSError):
            pass  # already woken (buffer full) or closed

    def clients(self) -> list[ClientStats]:
        """The connected clients (a snapshot, for tests and the log)."""
        with self._lock:
            clients = list(self._clients.values())
        return [
            ClientStats(c.peer, c.conn.state.value, c.max_fps, c.frames_sent, c.dropped,
                        len(c.out))
            for c in clients
        ]

    # -- the I/O thread ----------------------------------------------------------------------
    def _run(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self._listener, selectors.EVENT_READ, "listen")
        sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        try:
            while not self._stop.is_set():
                for key, mask in sel.select(_POLL_S):
                    if key.data == "listen":
                        self._accept(sel)
                    elif key.data == "wake":
                        self._drain_wake()
                    else:
                        client = self._clients.get(key.fd)
                        if client is None:
                            continue
                        if mask & selectors.EVENT_READ:
                            self._read(sel, client)
                        if mask & selectors.EVENT_WRITE and key.fd in self._clients:
                            self._flush(sel, client)
                self._take_pending()
                self._distribute(sel)
                self._housekeeping(sel)
        finally:
            for client in list(self._clients.values()):
                self._drop(sel, client, None)
            sel.close()
            self._listener.close()
            self._wake_r.close()
            self._wake_w.close()

    def _drain_wake(self) -> None:
        try:
            while self._wake_r.recv(4096):
                pass
        except (BlockingIOError, OSError):
            pass

    def _accept(self, sel: selectors.BaseSelector) -> None:
        try:
            sock, addr = self._listener.accept()
        except BlockingIOError:
            return
        except OSError as exc:
            when = accept_failed(exc, self._accept_said_s, "video server")
            if when is not None:
                self._accept_said_s = when  # waited a moment: the selector would spin
            return
        peer = f"{addr[0]}:{addr[1]}" if isinstance(addr, tuple) else str(addr)
        sock.setblocking(False)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER_BYTES)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except OSError:
            pass
        conn = VideoConnection(Role.SERVER)
        key = socket_peer_key(sock)
        mine = [c for c in self._clients.values() if c.key == key]
        at_cap = len(mine) >= self.max_clients_per_peer
        full = len(self._clients) >= self.max_clients
        if at_cap or full:
            idle = [c for c in (mine if at_cap else self._clients.values()) if not c.streaming]
            if idle:
                old = min(idle, key=lambda c: c.connected_s)
                self._drop(sel, old, f"replaced by a newer connection of {old.key} (it had "
                           "not subscribed)")
                full = False
            else:
                full = True
        if full:
            self.turned_away += 1
            reason = f"busy: this vehicle serves {self.max_clients} video clients at once"
            if len(mine) >= self.max_clients_per_peer:
                reason = (f"busy: {key} has {len(mine)} of this vehicle's {self.max_clients} "
                          f"video slots, all streaming (at most {self.max_clients_per_peer} "
                          "per user or address)")
            log.info("video: turning away %s: %s", peer, reason)
            self._send_last(sock, conn, reason)
            sock.close()
            return
        client = _Client(sock, peer, conn, self.clock(), bytearray(), key=key)
        with self._lock:
            self._clients[sock.fileno()] = client
        sel.register(sock, selectors.EVENT_READ, "client")
        log.info("video: client %s connected", peer)

    def _send_last(self, sock: socket.socket, conn: VideoConnection, reason: str) -> None:
        """ERROR with ``reason``, as far as the socket takes it now (never waits)."""
        try:
            data = conn.send(Error(reason[:500]))
        except LocalProtocolError:
            return
        try:
            sock.send(data)
        except OSError:
            pass

    def _drop(self, sel: selectors.BaseSelector, client: _Client, reason: str | None) -> None:
        if reason is not None:
            log.info("video: closing %s: %s", client.peer, reason)
            if client.conn.state is not State.CLOSED:
                if client.out:  # a message under way: ERROR after it, else it lands inside it
                    try:
                        client.out += client.conn.send(Error(reason[:500]))
                    except LocalProtocolError:
                        pass
                    else:
                        client.closing = True  # read no more; closed once out or stalled
                        self._want_write(sel, client)
                        return
                self._send_last(client.sock, client.conn, reason)
        with self._lock:
            self._clients.pop(client.sock.fileno(), None)
        try:
            sel.unregister(client.sock)
        except (KeyError, ValueError):
            pass
        client.sock.close()

    def _read(self, sel: selectors.BaseSelector, client: _Client) -> None:
        try:
            data = client.sock.recv(4096)
        except BlockingIOError:
            return
        except OSError as exc:
            self._drop(sel, client, None)
            log.info("video: client %s: %s", client.peer, exc)
            return
        if not data:
            self._drop(sel, client, None)
            log.info("video: client %s went away", client.peer)
            return
        try:
            messages = client.conn.receive_data(data)
        except RemoteProtocolError as exc:
            self.bad_clients += 1
            self._drop(sel, client, f"not the skeye video protocol: {exc}")
            return
        for msg in messages:
            if isinstance(msg, Subscribe):
                client.max_fps = min(msg.max_fps, self.hello.max_fps)
                if client.conn.state is State.WAIT_HELLO:
                    client.out += client.conn.send(self.hello)
                    self._want_write(sel, client)
            elif isinstance(msg, Error):
                self._drop(sel, client, None)
                log.info("video: client %s closed: %s", client.peer, msg.reason)
                return

    def _want_write(self, sel: selectors.BaseSelector, client: _Client) -> None:
        events = ((0 if client.closing else selectors.EVENT_READ)
                  | (selectors.EVENT_WRITE if client.out else 0))
        try:
            sel.modify(client.sock, events, "client")
        except (KeyError, ValueError):
            pass
        if client.out and client.stalled_since_s is None:
            client.stalled_since_s = self.clock()

    def _flush(self, sel: selectors.BaseSelector, client: _Client) -> None:
        if not client.out:
            return
        try:
            n = client.sock.send(client.out)
        except BlockingIOError:
            return
        except OSError as exc:
            self._drop(sel, client, None)
            log.info("video: client %s: %s", client.peer, exc)
            return
        del client.out[:n]
        client.stalled_since_s = None if n else client.stalled_since_s
        if client.closing and not client.out:
            self._drop(sel, client, None)  # its ERROR has gone out
            return
        self._want_write(sel, client)

    def _take_pending(self) -> None:
        with self._lock:
            frame, self._pending = self._pending, None
        if frame is not None:
            self._seq += 1
            self._current = (self._seq, frame)
            for client in self._clients.values():
                if client.streaming and client.out:
                    client.dropped += 1  # its buffer still holds an earlier frame: it misses this

    def _encoded(self) -> bytes | None:
        """The current frame as a FRAME message, encoded once; None if it cannot be (logged:
        one bad frame is skipped, the server goes on)."""
        assert self._current is not None
        seq, frame = self._current
        if self._jpeg is None or self._jpeg[0] != seq:
            try:
                ok, buf = cv2.imencode(".jpg", frame.bgr,
                                       [cv2.IMWRITE_JPEG_QUALITY, self.hello.jpeg_quality])
                if not ok:
                    raise LocalProtocolError("OpenCV could not encode the frame as JPEG")
                height, width = frame.bgr.shape[:2]
                message = Frame(frame.frame_number, frame.time_s, int(width), int(height),
                                frame.detection, frame.detect_ms, buf.tobytes())
                self._jpeg = (seq, encode(message))
            except (LocalProtocolError, cv2.error, ValueError) as exc:
                self.bad_frames += 1
                log.warning("video: frame %d not served: %s", frame.frame_number, exc)
                self._jpeg = (seq, b"")
            else:
                self.encoded += 1
        return self._jpeg[1] or None

    def _distribute(self, sel: selectors.BaseSelector) -> None:
        if self._current is None:
            return
        seq = self._current[0]
        now = self.clock()
        for client in list(self._clients.values()):
            if not client.streaming or client.last_seq >= seq:
                continue
            if client.out:
                continue  # still sending an earlier frame (counted as dropped in _take_pending)
            if now - client.last_frame_s < 1.0 / client.max_fps:
                continue  # its rate: it gets the newest frame when its slot comes
            data = self._encoded()
            if data is None:
                return  # this frame cannot be served: wait for the next
            client.out += data
            client.last_seq = seq
            client.last_frame_s = now
            client.frames_sent += 1
            self.frames_sent += 1
            self._want_write(sel, client)
            self._flush(sel, client)

    def _housekeeping(self, sel: selectors.BaseSelector) -> None:
        now = self.clock()
        for client in list(self._clients.values()):
            if client.conn.state is State.WAIT_SUBSCRIBE:
                if now - client.connected_s >= self.subscribe_timeout_s:
                    self.idle_closed += 1
                    self._drop(sel, client, f"no SUBSCRIBE within {self.subscribe_timeout_s:g} s")
            elif client.out and client.stalled_since_s is not None:
                if now - client.stalled_since_s >= self.send_timeout_s:
                    self.slow_closed += 1
                    self._drop(sel, client, None)
                    log.info("video: client %s took nothing for %g s: closed", client.peer,
                             self.send_timeout_s)
