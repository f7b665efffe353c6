"""A small blocking client of the image server (docs/protocols/images.md).

Extension requests (camera, format, META, stream) get no reply when they succeed, so a refused
one (an unknown camera, say) surfaces as an error frame in place of the next frame: the next
``get_frame`` raises :class:`~skeye.errors.RemoteProtocolError` with the server's reason. A
connection the server refuses (too many clients) gets an error frame and is closed; the
request that then fails to send raises the same, with that reason (from
:meth:`~skeye.link.transport.Link.leftover`), not the bare ``LinkClosed``.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Iterator

from skeye.errors import (
    LinkClosed,
    LinkTimeout,
    LocalProtocolError,
    PeerClosed,
    RemoteProtocolError,
)
from skeye.link.transport import MAX_SOCKET_TIMEOUT_S, Link, open_link, tcp_uri
from skeye.values import is_finite_number
from skeye.wire.image_requests import (
    NewestFrame,
    NewestInfo,
    Request,
    SelectCamera,
    SetFormat,
    SetMeta,
    SetPrerender,
    Stream,
    SubRect,
    encode_request,
)
from skeye.wire.images import (
    DEFAULT_MAX_FRAME_BYTES,
    DEFAULT_PORT,
    DecodedFrame,
    FrameDecoder,
    FrameEvent,
    ImageFormat,
    InfoFrame,
    MetaHeader,
    ProtocolViolation,
    RemoteError,
)

log = logging.getLogger(__name__)

_RECV_BYTES = 256 * 1024
_STOP_QUIET_S = 0.2  # after STREAM 0, frames still in flight are drained until this long quiet


class ImageClient:
    """One connection to an image server.

    Args:
        host: server address.
        port: server port.
        timeout_s: the deadline for connecting and for each frame.
        max_frame_bytes: larger frames are a protocol error.

    Raises:
        LocalProtocolError: ``timeout_s`` not a number over 0 (at most 1e9 s), or
            ``max_frame_bytes`` not a whole number >= 1.
        LinkTimeout: connecting took longer than ``timeout_s``.
        LinkClosed: the connection was refused (and later: the link broke).
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        timeout_s: float = 5.0,
        *,
        max_frame_bytes: int = DEFAULT_MAX_FRAME_BYTES,
    ) -> None:
        if not (is_finite_number(timeout_s) and 0 < timeout_s <= MAX_SOCKET_TIMEOUT_S):
            raise LocalProtocolError(f"timeout_s must be a number over 0 and at most "
                                     f"{MAX_SOCKET_TIMEOUT_S:g} s, got {timeout_s!r}")
        if (isinstance(max_frame_bytes, bool) or not isinstance(max_frame_bytes, int)
                or max_frame_bytes < 1):
            raise LocalProtocolError(
                f"max_frame_bytes must be a whole number >= 1, got {max_frame_bytes!r}")
        self.timeout_s = timeout_s
        try:
            self._link: Link = open_link(tcp_uri(host, port), timeout_s,
                                         send_timeout_s=timeout_s, recv_bytes=_RECV_BYTES)
        except LinkTimeout as exc:
            raise LinkTimeout(
                f"image server {host}:{port}: no connection in {timeout_s} s"
            ) from exc
        except LinkClosed as exc:  # named as the simulator's connection names the simulator
            # (its kind kept: an UnknownHost stays one)
            raise type(exc)(f"cannot connect to the image server at {host}:{port}: {exc}"
                            ) from exc
        self._decoder = FrameDecoder(max_frame_bytes)
        self._events: deque[FrameEvent] = deque()
        self._stream_fps: float | None = None
        self._closed = False
        self._peer = f"{host}:{port}"

    def __enter__(self) -> ImageClient:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @property
    def link(self) -> Link:
        """The byte link to the server (for tests that send raw bytes; requests go through the
        methods below)."""
        return self._link

    def close(self) -> None:
        """Close the connection; idempotent."""
        if self._closed:
            return
        self._closed = True
        self._link.close()

    # ---------------------------------------------------------------- settings

    def select_camera(self, name: str) -> None:
        """Use camera ``robot/camera`` from now on."""
        self._send(SelectCamera(name))

    def set_format(self, kind: str | ImageFormat, quality: int = 85) -> None:
        """Receive "raw", "jpeg" (at ``quality`` 1-100) or "png" frames from now on."""
        if isinstance(kind, str):
            try:
                kind = ImageFormat(kind.upper())
            except ValueError:
                raise LocalProtocolError(
                    f"image format must be raw, jpeg or png, got {kind!r}"
                ) from None
        self._send(SetFormat(kind, quality if kind is ImageFormat.JPEG else None))

    def set_meta(self, on: bool) -> None:
        """Ask for META frames (frame number, sim time, camera id, size) or plain UPIS ones."""
        self._send(SetMeta(bool(on)))

    def set_prerender(self, on: bool) -> None:
        """Whether the simulator renders this connection's camera frames ahead of its requests
        (on, the default: a frame is ready when asked for) or only the frames it asks for
        (off: each request waits for its render; in lockstep a client that takes some of the
        frames, as the pilot's vision, saves the renders of the others)."""
        self._send(SetPrerender(bool(on)))

    # ---------------------------------------------------------------- frames

    def get_frame(self) -> DecodedFrame:
        """The newest frame of the selected camera.

        Raises:
            RemoteProtocolError: the server answered with an error frame, or broke the protocol.
            LinkTimeout: no frame within ``timeout_s``.
        """
        return self._request(NewestFrame())

    def get_subrect(self, x: int, y: int, width: int, height: int) -> DecodedFrame:
        """A sub-rectangle (origin top-left, px) of the newest frame."""
        return self._request(SubRect(x, y, width, height))

    def frame_info(self) -> MetaHeader:
        """The newest frame's META header (number, sim time, camera id, size) without its
        pixels: the server does not render the frame for it (``SKEYE INFO``).

        Raises:
            RemoteProtocolError: an error frame, a protocol violation, or an image frame in
                place of the answer.
            LinkTimeout: no answer within ``timeout_s``.
        """
        if self._stream_fps is not None:
            raise LocalProtocolError("stop the stream before asking for single frames")
        self._send(NewestInfo())
        event = self._checked(self._next_event())
        if not isinstance(event, InfoFrame):
            raise RemoteProtocolError("image server answered SKEYE INFO with an image frame")
        return event.meta

    def stream(self, fps: float) -> Iterator[DecodedFrame]:
        """Ask the server to push frames at up to ``fps``; iterate to receive them.

        Leaving the iteration early (break, exception) stops the stream. Each frame waits at most
        ``timeout_s`` (LinkTimeout); an error frame raises RemoteProtocolError.
        """
        if fps <= 0:
            raise LocalProtocolError(f"stream rate must be above 0 frames/s, got {fps!r}")
        self._send(Stream(fps))
        self._stream_fps = fps
        return self._stream_frames()

    def stop_stream(self) -> None:
        """Stop a stream and discard the frames that were already on their way."""
        if self._stream_fps is None:
            return
        quiet_s = max(_STOP_QUIET_S, 2.0 / self._stream_fps)
        self._stream_fps = None
        self._send(Stream(0))
        self._events.clear()
        deadline = time.monotonic() + max(self.timeout_s, quiet_s)
        while time.monotonic() < deadline:
            try:
                data = self._link.recv(quiet_s)
            except PeerClosed:
                break
            if not data:
                break  # quiet: nothing more was in flight
            for event in self._decoder.feed(data):
                if not isinstance(event, DecodedFrame):
                    log.debug("image client: discarded while stopping a stream: %s", event)

    def _stream_frames(self) -> Iterator[DecodedFrame]:
        try:
            while self._stream_fps is not None and not self._closed:
                yield self._next_frame()
        finally:
            if self._stream_fps is not None and not self._closed:
                try:
                    self.stop_stream()
                except (LinkClosed, LinkTimeout) as exc:
                    log.info("image client: could not stop the stream cleanly: %s", exc)

    # ---------------------------------------------------------------- plumbing

    def _request(self, request: Request) -> DecodedFrame:
        if self._stream_fps is not None:
            raise LocalProtocolError("stop the stream before asking for single frames")
        self._send(request)
        return self._next_frame()

    def _send(self, request: Request) -> None:
        if self._closed:
            raise LocalProtocolError("the image client is closed")
        try:
            self._link.send(encode_request(request))
        except LinkTimeout as exc:
            raise LinkTimeout(f"image server {self._peer}: send timed out") from exc
        except LinkClosed as exc:
            # A server that refuses the connection (too many clients) sends an error frame and
            # closes; a request sent meanwhile fails, and the reason is in what it sent.
            for event in self._decoder.feed(self._link.leftover()):
                if isinstance(event, RemoteError):
                    raise RemoteProtocolError(f"image server: {event.reason}") from None
            raise LinkClosed(f"image server {self._peer} closed the connection ({exc})") from None

    def _next_frame(self) -> DecodedFrame:
        event = self._checked(self._next_event())
        if isinstance(event, InfoFrame):
            raise RemoteProtocolError("image server sent an INFO frame where an image was due")
        return event

    @staticmethod
    def _checked(event: FrameEvent) -> DecodedFrame | InfoFrame:
        if isinstance(event, RemoteError):
            raise RemoteProtocolError(f"image server: {event.reason}")
        if isinstance(event, ProtocolViolation):
            raise RemoteProtocolError(f"image server broke the protocol: {event.reason}")
        return event

    def _next_event(self) -> FrameEvent:
        deadline = time.monotonic() + self.timeout_s
        while not self._events:
            if self._decoder.failure is not None:
                raise RemoteProtocolError(
                    f"image server broke the protocol: {self._decoder.failure}"
                )
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise LinkTimeout(f"image server {self._peer}: no frame in {self.timeout_s} s")
            try:
                data = self._link.recv(remaining)
            except PeerClosed:
                raise RemoteProtocolError(
                    f"image server {self._peer} closed the connection"
                ) from None
            self._events.extend(self._decoder.feed(data))  # b"": nothing yet, loop
        return self._events.popleft()
