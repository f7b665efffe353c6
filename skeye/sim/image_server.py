"""The image server: camera frames to many TCP clients (docs/protocols/images.md, port 5003).

How this works:

* The engine's render step publishes each rendered :class:`Frame` to a :class:`FrameBuffer`
  (:mod:`skeye.sim.frame_store`: it never blocks the simulator, and caches encodings).
* :class:`ImageServer` runs one accept thread and one thread per client. Each client thread owns
  its socket (non-blocking) and a wake-up socket pair, and runs a select loop: requests are parsed
  by the sans-IO :class:`~skeye.wire.images.RequestParser` and queued; the head of the
  queue is served when nothing is being sent. At most one frame is in flight per client, and it is
  built from the newest frame only when the previous one has gone out: a slow or stalled client
  simply receives fewer frames, and never holds a lock or blocks anyone else. Reading stops while
  the request queue is full, so a client that floods requests is held back by TCP.
* Slots are bounded: ``max_clients`` connections, ``max_clients_per_peer`` of one peer
  (:func:`skeye.peers.peer_key`: a local user however many loopback addresses it binds, or a
  remote address). A peer at its cap that connects again replaces its own connection that has
  made no progress longest among those not streaming (it gets an error frame saying so); only
  when all of them stream is the new one refused. A connection that sends no complete request
  within ``handshake_timeout_s`` of connecting, or that makes no progress (no request received,
  no byte sent to it; a stream that has taken every frame sent and waits for a newer one is
  making progress) for ``idle_timeout_s``, gets an error frame naming the reason (after the
  frame under way, if any, so the stream stays whole) and is closed; one that takes none of it
  for another ``idle_timeout_s`` is closed without it: idle or stalled clients cannot hold the
  slots. The accept thread never waits on a
  client, and a shortage of file descriptors is logged and waited out.
* A client watches its camera (:meth:`FrameBuffer.watch`: the simulator renders each frame
  as it is taken) until it says ``SKEYE PRERENDER off``; from then on its frames are rendered
  when it asks for one (a lockstep client that takes some of the frames, the pilot's vision).
  ``SKEYE INFO`` is answered with the newest frame's META header alone and never renders it
  (a client asking which frame is newest before it decides to fetch one).
* ``close()`` wakes every thread through its socket pair and joins them all within a deadline.
"""

from __future__ import annotations

import logging
import selectors
import socket
import threading
import time
from collections import deque
from dataclasses import dataclass

from skeye.errors import SkeyeError
from skeye.peers import accept_failed, listen, socket_peer_key
from skeye.pixels import encode_image
from skeye.sim.frame_store import Frame, FrameBuffer
from skeye.sim.limits import check_server_limits
from skeye.wire.image_requests import (
    NewestFrame,
    NewestInfo,
    Request,
    RequestError,
    RequestParser,
    SelectCamera,
    SetFormat,
    SetMeta,
    SetPrerender,
    Stream,
    SubRect,
)
from skeye.wire.images import (
    DEFAULT_PORT,
    META_HEADER_BYTES,
    META_OFFSET,
    ImageFormat,
    MetaHeader,
    encode_error_frame,
    encode_info_frame,
    frame_header,
    meta_header,
)
from skeye.workers import Worker

log = logging.getLogger(__name__)

__all__ = ["ClientStats", "Frame", "FrameBuffer", "ImageServer"]  # the store, re-exported

NO_FRAME_WAIT_S = 1.0  # how long an OK waits for a camera's first frame before an error frame
_RECV_BYTES = 4096  # bounds the requests one read can add to the queue
_QUEUE_LIMIT = 64  # stop reading a client's requests while this many are waiting
_IDLE_WAKE_S = 1.0  # safety net: a client loop looks around at least this often
_STREAM_EARLY = 0.2  # a stream frame may go this fraction of a period before its slot
HANDSHAKE_TIMEOUT_S = 10.0  # a new connection must send a complete request within this
IDLE_TIMEOUT_S = 120.0  # no request and no byte sent for this long: the connection is closed
MAX_CLIENTS_PER_PEER = 32  # connections of one peer, a user or address (half the 64 slots)


@dataclass(frozen=True)
class ClientStats:
    """What the server has sent one client so far (``frames_sent``: image and INFO frames)."""

    address: str
    camera: str | None
    frames_sent: int
    errors_sent: int
    bytes_sent: int


class _ClientHandler:
    """Serves one client on its own thread (see the module comment)."""

    def __init__(
        self,
        server: ImageServer,
        sock: socket.socket,
        address: str,
        default_format: ImageFormat,
        default_quality: int | None,
    ) -> None:
        self._server = server
        self._buffer = server.buffer
        self._sock = sock
        self.address = address
        self._wake_r, self._wake_w = socket.socketpair()
        for s in (self._sock, self._wake_r, self._wake_w):
            s.setblocking(False)
        self._parser = RequestParser()
        self._queue: deque[Request] = deque()
        self._out: list[memoryview] = []
        self._out_is_error = False
        self._frame_before_error = False  # _out holds a frame and then an error frame
        self._stop = False
        self._eof = False
        self._want_wake = False
        self.camera: str | None = None  # None: the buffer's first camera
        self._format = default_format
        self._quality = default_quality
        self._meta = False
        self._stream_period_s: float | None = None
        self._next_stream_s = 0.0
        self._stream_starved = False  # a stream frame is due but no newer frame exists yet
        # The newest frame sent: (camera id, frame number). A camera that went and came back
        # under the same name (its robot spawned again) has a new id and counts from 1 again.
        self._last_sent: tuple[int, int] = (0, 0)
        self._said_gone = False  # the stream's camera went and the client was told so
        self._wait_deadline_s: float | None = None
        self._got_request = False
        self._active_s = time.monotonic()  # last request received or byte sent
        self.closed_reason: str | None = None
        self._watch = 0  # the buffer's watcher handle (set on the client's thread)
        self._prerender = True  # frames rendered ahead for it (SKEYE PRERENDER off: when asked)
        self.peer_host = address.rpartition(":")[0]
        self.peer_key = self.peer_host  # whose slot it takes (skeye.peers); set by the server
        self.replaced: str | None = None  # why a newer connection of its peer took its slot
        self.frames_sent = 0
        self.errors_sent = 0
        self.bytes_sent = 0
        self.thread = Worker(self._run, f"image-client {address}")

    # ---------------------------------------------------------------- thread plumbing

    def stop(self) -> None:
        """Ask the thread to end soon; safe from any thread."""
        self._stop = True
        self._poke()

    def _poke(self) -> None:
        try:
            self._wake_w.send(b"\0")
        except OSError:
            pass  # buffer full (a wake-up is pending anyway) or already closed

    def _on_publish(self, camera: str) -> None:
        if self._want_wake:
            self._want_wake = False
            self._poke()

    def _run(self) -> None:
        log.info("image client %s connected", self.address)
        self._buffer.add_listener(self._on_publish)
        self._watch = self._buffer.watch(None)  # frames of the first camera until SELECT
        try:
            self._loop()
        except OSError as exc:
            log.info("image client %s: connection lost (%s)", self.address, exc)
        except Exception:
            log.exception("image client %s: handler failed", self.address)
        finally:
            self._buffer.unwatch(self._watch)
            self._buffer.remove_listener(self._on_publish)
            for s in (self._sock, self._wake_r, self._wake_w):
                s.close()
            self._server._forget(self)
            log.info(
                "image client %s disconnected (%d frames, %d errors sent)",
                self.address,
                self.frames_sent,
                self.errors_sent,
            )

    def _loop(self) -> None:
        with selectors.DefaultSelector() as sel:
            sel.register(self._wake_r, selectors.EVENT_READ)
            registered = 0
            while not self._stop:
                now = time.monotonic()
                self._check_idle(now)
                self._advance(now)
                if self._eof and not self._queue and not self._out:
                    return
                interest = 0
                if not self._eof and len(self._queue) < _QUEUE_LIMIT:
                    interest |= selectors.EVENT_READ
                if self._out:
                    interest |= selectors.EVENT_WRITE
                if interest != registered:
                    if registered and interest:
                        sel.modify(self._sock, interest)
                    elif interest:
                        sel.register(self._sock, interest)
                    else:
                        sel.unregister(self._sock)
                    registered = interest
                for key, mask in sel.select(self._timeout(now)):
                    if key.fileobj is self._wake_r:
                        self._drain_wake()
                        continue
                    if mask & selectors.EVENT_READ and not self._read():
                        self._eof = True
                    if mask & selectors.EVENT_WRITE:
                        self._write()

    def _idle_deadline_s(self) -> float:
        if not self._got_request:
            return self._active_s + self._server.handshake_timeout_s
        return self._active_s + self._server.idle_timeout_s

    @property
    def idle_since_s(self) -> float:
        """When it last made progress (a request received or a byte sent)."""
        return self._active_s

    @property
    def streaming(self) -> bool:
        """Whether it streams, or has work under way: a connection a new one never replaces."""
        return self._stream_period_s is not None or bool(self._queue) or bool(self._out)

    def replace(self, reason: str) -> None:
        """A newer connection of the same peer takes this one's slot (safe from any thread):
        it gets an error frame with ``reason`` and is closed."""
        self.replaced = reason
        self._poke()

    def _check_idle(self, now: float) -> None:
        """Close a connection that sent no request in time, made no progress for long, or was
        replaced."""
        if self.closed_reason is not None:
            if now >= self._idle_deadline_s():  # its error frame had a whole idle period
                log.info("image client %s: took no byte of its error frame in %g s; closed "
                         "without it", self.address, self._server.idle_timeout_s)
                self._stop = True
            return
        if self._stream_period_s is not None and not self._out and not self._queue:
            # A stream that has taken every frame sent waits for a newer one (in lockstep
            # between steps, or while its camera is gone): it is not idle, the camera is.
            self._active_s = now
        if self.replaced is None and now < self._idle_deadline_s():
            return
        server = self._server
        if self.replaced is not None:
            reason = self.replaced
        elif not self._got_request:
            reason = f"no request within {server.handshake_timeout_s:g} s of connecting; closed"
        else:
            reason = f"idle for {server.idle_timeout_s:g} s (no request, nothing read); closed"
        log.info("image client %s: %s", self.address, reason)
        self.closed_reason = reason
        self._eof = True
        self._queue.clear()
        self._stream_period_s = None
        if self._out and not self._out_is_error:
            # A frame is under way (a stalled client): the error frame goes after it, so the
            # stream stays whole; the frame counts as sent if it gets out.
            self._out.append(memoryview(encode_error_frame(reason)))
            self._out_is_error = True
            self._frame_before_error = True
        else:
            self._send_error(reason)
        self._active_s = now  # the error frame gets one more idle period to go out
        self._got_request = True

    def _drain_wake(self) -> None:
        try:
            while self._wake_r.recv(256):
                pass
        except BlockingIOError:
            pass

    def _read(self) -> bool:
        """Read requests; False at end of stream."""
        try:
            data = self._sock.recv(_RECV_BYTES)
        except BlockingIOError:
            return True
        if not data:
            return False
        requests = self._parser.feed(data)
        if requests:
            self._got_request = True
            self._active_s = time.monotonic()
        self._queue.extend(requests)
        return True

    def _write(self) -> None:
        if not self._out:
            return
        try:
            sent = self._sock.sendmsg(self._out)
        except BlockingIOError:
            return
        self.bytes_sent += sent
        if sent:
            self._active_s = time.monotonic()
        while sent:
            head = self._out[0]
            if sent >= len(head):
                sent -= len(head)
                self._out.pop(0)
            else:
                self._out[0] = head[sent:]
                sent = 0
        if not self._out:
            if self._out_is_error:
                self.errors_sent += 1
                self.frames_sent += self._frame_before_error
                self._frame_before_error = False
            else:
                self.frames_sent += 1

    def _timeout(self, now: float) -> float:
        timeout = min(_IDLE_WAKE_S, self._idle_deadline_s() - now)
        if self._wait_deadline_s is not None:
            timeout = min(timeout, self._wait_deadline_s - now)
        if (
            self._stream_period_s is not None
            and not self._stream_starved
            and not self._out
            and not self._queue
        ):
            early = _STREAM_EARLY * self._stream_period_s
            timeout = min(timeout, self._next_stream_s - early - now)
        return max(timeout, 0.0)

    # ---------------------------------------------------------------- requests

    def _advance(self, now: float) -> None:
        """Fill the (empty) output with the next thing to send, if any is ready."""
        self._stream_starved = False
        while not self._out and not self._stop:
            if self._queue:
                if not self._serve(self._queue[0], now):
                    return  # waiting for a first frame
                self._queue.popleft()
                continue
            if (
                self._stream_period_s is not None
                and now >= self._next_stream_s - _STREAM_EARLY * self._stream_period_s
            ):
                self._want_wake = True  # before looking, so a publish in between is not missed
                camera = self._camera_name()
                frame = None if camera is None else self._buffer.latest(camera)
                if frame is None and self._stream_camera_gone():
                    return  # its error frame is under way; the stream goes on if it comes back
                if frame is None or self._sent_already(frame):
                    self._stream_starved = True  # the publisher's listener will wake us
                    return
                self._want_wake = False
                self._said_gone = False
                self._send_frame(frame, None)
                # A token bucket of one frame: the long-run rate never exceeds the requested
                # one, yet a frame arriving a little before its slot (camera and stream at the
                # same rate, with jitter) goes out at once instead of waiting up to a period.
                self._next_stream_s = max(self._next_stream_s, now) + self._stream_period_s
            return

    def _serve(self, request: Request, now: float) -> bool:
        """Act on one request; False if it must wait for a frame to exist."""
        match request:
            case NewestFrame() | SubRect() | NewestInfo():
                return self._serve_image(request, now)
            case SelectCamera(name=name):
                if name in self._buffer.cameras():
                    if name != self.camera:
                        self._said_gone = False
                    self.camera = name
                    self._buffer.rewatch(self._watch, name)
                else:
                    known = ", ".join(self._buffer.cameras()) or "none"
                    self._send_error(f"unknown camera {name!r} (cameras: {known})")
            case SetFormat(kind=kind, quality=quality):
                self._format, self._quality = kind, quality
            case SetMeta(on=on):
                self._meta = on
            case SetPrerender(on=on):
                if on and not self._prerender:
                    self._watch = self._buffer.watch(self.camera)
                elif not on and self._prerender:
                    self._buffer.unwatch(self._watch)
                self._prerender = on
            case Stream(fps=fps):
                self._stream_period_s = 1.0 / fps if fps > 0 else None
                self._next_stream_s = now
            case RequestError(reason=reason):
                self._send_error(reason)
        return True

    def _sent_already(self, frame: Frame) -> bool:
        """True if ``frame`` is no newer than the last frame sent of its camera."""
        camera_id, number = self._last_sent
        return frame.camera_id == camera_id and frame.number <= number

    def _stream_camera_gone(self) -> bool:
        """A stream whose selected camera went (its robot left): the client is told once, with
        an error frame (True then); frames follow again if a camera of that name comes back."""
        camera = self.camera
        if self._said_gone or camera is None or self._buffer.camera_id(camera) is not None:
            return False
        self._said_gone = True
        self._send_error(f"camera {camera!r} is gone; the stream goes on if it comes back")
        return True

    def _camera_name(self) -> str | None:
        if self.camera is not None:
            return self.camera
        cameras = self._buffer.cameras()
        return cameras[0] if cameras else None

    def _serve_image(self, request: NewestFrame | SubRect | NewestInfo, now: float) -> bool:
        camera = self._camera_name()
        frame = None if camera is None else self._buffer.latest(camera)
        if frame is None:
            if self.camera is not None and self._buffer.camera_id(self.camera) is None:
                self._wait_deadline_s = None
                self._send_error(f"camera {self.camera!r} is gone")
                return True
            if self._wait_deadline_s is None:
                self._wait_deadline_s = now + NO_FRAME_WAIT_S
            if now < self._wait_deadline_s:
                self._want_wake = True
                return False
            self._wait_deadline_s = None
            self._send_error(f"no frame available from camera {camera or '(none yet)'}")
            return True
        self._wait_deadline_s = None
        if isinstance(request, NewestInfo):  # its size and number are known before its pixels
            meta = MetaHeader(frame.number, frame.sim_time_s, frame.camera_id, frame.width,
                              frame.height)
            self._out = [memoryview(encode_info_frame(meta))]
            self._out_is_error = False
            return True
        if isinstance(request, NewestFrame):
            self._send_frame(frame, None)
            return True
        x, y, w, h = request.x, request.y, request.width, request.height
        if w == 0 or h == 0 or x + w > frame.width or y + h > frame.height:
            self._send_error(
                f"bad rectangle x={x} y={y} width={w} height={h} "
                f"for a {frame.width}x{frame.height} frame"
            )
            return True
        self._send_frame(frame, (x, y, w, h))
        return True

    def _send_frame(self, frame: Frame, rect: tuple[int, int, int, int] | None) -> None:
        try:  # a frame published before its pixels: this waits for its render
            if rect is None:
                base, payload = self._buffer.encoded(frame, self._format, self._quality)
                width, height = frame.width, frame.height
            else:
                x, y, width, height = rect
                crop = frame.rgb[y : y + height, x : x + width]
                base, payload = encode_image(crop, self._format, self._quality)
        except SkeyeError as exc:
            self._send_error(f"camera {frame.camera} frame {frame.number}: {exc}")
            return
        finally:
            if rect is None and (self.camera is None or frame.camera == self.camera):
                if not self._sent_already(frame):
                    self._last_sent = (frame.camera_id, frame.number)
        if self._meta:
            head = meta_header(frame.number, frame.sim_time_s, frame.camera_id, width, height)
            parts = [
                frame_header(base + META_OFFSET, META_HEADER_BYTES + len(payload)) + head,
                payload,
            ]
        else:
            parts = [frame_header(base, len(payload)), payload]
        self._out = [memoryview(p) for p in parts]
        self._out_is_error = False

    def _send_error(self, reason: str) -> None:
        log.debug("image client %s: error frame: %s", self.address, reason)
        self._out = [memoryview(encode_error_frame(reason))]
        self._out_is_error = True

    def stats(self) -> ClientStats:
        return ClientStats(
            self.address, self.camera, self.frames_sent, self.errors_sent, self.bytes_sent
        )


class ImageServer:
    """Serves a :class:`FrameBuffer` over TCP; a context manager, listening once constructed.

    Args:
        buffer: where the engine publishes frames.
        host: address to bind (127.0.0.1 unless told otherwise).
        port: TCP port; 0 picks a free one (read it back from :attr:`port`).
        default_format: the format a client gets until it sends ``SKEYE FORMAT``.
        default_quality: JPEG quality when ``default_format`` is JPEG.
        max_clients: connections beyond this get an error frame and are closed.
        max_clients_per_peer: the same, for connections from one peer address.
        handshake_timeout_s: a connection with no complete request this long after connecting
            gets an error frame and is closed.
        idle_timeout_s: the same for a connection with no request and no byte sent this long.
        close_timeout_s: how long ``close()`` waits for all threads in total.
    """

    def __init__(
        self,
        buffer: FrameBuffer,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        *,
        default_format: ImageFormat = ImageFormat.RAW,
        default_quality: int | None = None,
        max_clients: int = 64,
        max_clients_per_peer: int = MAX_CLIENTS_PER_PEER,
        handshake_timeout_s: float = HANDSHAKE_TIMEOUT_S,
        idle_timeout_s: float = IDLE_TIMEOUT_S,
        close_timeout_s: float = 2.0,
    ) -> None:
        SetFormat(default_format, default_quality)  # same rules as a client's request
        check_server_limits("image server", max_clients=max_clients,
                            max_clients_per_peer=max_clients_per_peer,
                            handshake_timeout_s=handshake_timeout_s, idle_timeout_s=idle_timeout_s)
        self.max_clients_per_peer = max_clients_per_peer
        self.handshake_timeout_s = handshake_timeout_s
        self.idle_timeout_s = idle_timeout_s
        self.buffer = buffer
        self._default_format = default_format
        self._default_quality = default_quality
        self._max_clients = max_clients
        self._close_timeout_s = close_timeout_s
        self._lock = threading.Lock()
        self._handlers: list[_ClientHandler] = []
        self._closed = False
        # A full accept queue drops new SYNs: a real client then waits out TCP's 1 s (3 s, ...)
        # retransmission while attackers' connections wait to be turned away. Keep it long.
        self._listener = listen(host, port, backlog=socket.SOMAXCONN)
        self._listener.setblocking(False)
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self.host = host
        self.port: int = self._listener.getsockname()[1]
        self._accept_thread = Worker(self._accept_loop, f"image-server accept :{self.port}")
        self._accept_thread.start()
        log.info("image server listening on %s:%d", host, self.port)

    def __enter__(self) -> ImageServer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def stats(self) -> list[ClientStats]:
        """What each connected client has been sent, in order of connection."""
        with self._lock:
            return [h.stats() for h in self._handlers]

    def client_count(self) -> int:
        """Connected clients."""
        with self._lock:
            return len(self._handlers)

    def close(self) -> None:
        """Stop accepting, end every client thread and close every socket; idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        deadline = time.monotonic() + self._close_timeout_s
        try:
            self._wake_w.send(b"\0")
        except OSError:
            pass
        self._accept_thread.join(max(0.0, deadline - time.monotonic()))
        with self._lock:
            handlers = list(self._handlers)
        for handler in handlers:
            handler.stop()
        for handler in handlers:
            handler.thread.join(max(0.0, deadline - time.monotonic()))
        stuck = [h.address for h in handlers if h.thread.is_alive()]
        if self._accept_thread.is_alive():
            stuck.append("accept")
        if stuck:
            log.warning("image server: threads still running after close: %s", stuck)
        else:
            self._listener.close()
            self._wake_r.close()
            self._wake_w.close()
        log.info("image server on port %d closed", self.port)

    def _forget(self, handler: _ClientHandler) -> None:
        with self._lock:
            if handler in self._handlers:
                self._handlers.remove(handler)

    def _accept_loop(self) -> None:
        said_s = 0.0
        try:  # a failure is logged with its traceback by the Worker and kept as its error
            with selectors.DefaultSelector() as sel:
                sel.register(self._listener, selectors.EVENT_READ)
                sel.register(self._wake_r, selectors.EVENT_READ)
                while not self._closed:
                    for key, _ in sel.select(_IDLE_WAKE_S):
                        if key.fileobj is not self._listener:
                            continue
                        try:
                            while self._accept_one():  # every connection waiting, at once
                                pass
                        except OSError as exc:
                            when = accept_failed(exc, said_s, "image server")
                            if when is None:
                                raise
                            said_s = when
        finally:
            if self._closed:
                self._listener.close()

    def _accept_one(self) -> bool:
        """Accept one waiting connection; False when none waits (or the server closes)."""
        if self._closed:
            return False
        try:
            sock, peer = self._listener.accept()
        except BlockingIOError:
            return False
        except ConnectionAbortedError:
            return True
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except OSError:  # the client went already
            sock.close()
            return True
        address = f"{peer[0]}:{peer[1]}"
        key = socket_peer_key(sock)
        with self._lock:
            mine = [h for h in self._handlers if h.peer_key == key and h.replaced is None]
            reason = ""
            replaced: _ClientHandler | None = None
            if self._closed:
                reason = "the image server is closing"
            elif len(mine) >= self.max_clients_per_peer:
                quiet = [h for h in mine if not h.streaming]
                if quiet:
                    replaced = min(quiet, key=lambda h: h.idle_since_s)
                    replaced.replace(f"replaced by a newer connection of {key} "
                                     f"({self.max_clients_per_peer} per user or address); "
                                     "closed")
                else:
                    reason = (f"too many clients from {key} ({self.max_clients_per_peer} per "
                              "user or address, all streaming)")
            elif len(self._handlers) >= self._max_clients:
                reason = "too many clients"
            refuse = bool(reason)
            if not refuse:
                handler = _ClientHandler(
                    self, sock, address, self._default_format, self._default_quality
                )
                handler.peer_key = key
                self._handlers.append(handler)
                handler.thread.start()
        if refuse:
            log.warning("image server: refusing %s: %s", address, reason)
            try:
                sock.setblocking(False)
                sock.send(encode_error_frame(reason))
            except OSError:
                pass
            sock.close()
        return True
