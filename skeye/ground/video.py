"""Camera relay: the vehicle's frames and its own pad detection, from the pilot's video port.

How this works: ``VideoRelay`` runs one worker thread (:class:`skeye.workers.Worker`) that
alone owns a TCP connection to the vehicle's video port (``skeye pilot --video-port``, the same
on the simulator and on a real vehicle; docs/protocols/video.md). It subscribes at ``fps``,
reads HELLO and then FRAME messages through a sans-IO
:class:`~skeye.wire.video.VideoConnection`, and publishes each as a ``VideoFrame``: the JPEG as
the vehicle encoded it plus the vehicle's detection (ring ellipses and centre in pixels,
height, offsets, quality) as JSON. Nothing is detected here: the page shows what the vehicle saw
and detected. The page draws the frame and overlays the ellipses itself, so the JPEG is relayed
without re-encoding. Browsers read ``latest()``; nothing waits on a browser. Any failure (the
vehicle gone, an ERROR, bytes that are not the protocol, no frame for ``timeout_s``) closes the
connection and the worker reconnects after ``retry_s``; ``state`` and ``last_error`` say why.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from skeye.errors import LinkTimeout, LocalProtocolError, RemoteProtocolError, SkeyeError
from skeye.uris import port_of, split_uri
from skeye.wire.video import (
    Error,
    Frame,
    Hello,
    Role,
    Subscribe,
    VideoConnection,
    detection_to_json,
)
from skeye.workers import Worker

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class VideoFrame:
    """One relayed frame and what the vehicle's detector saw in it."""

    seq: int
    jpeg: bytes
    width: int
    height: int
    frame_number: int | None
    sim_time_s: float | None
    detection: dict[str, Any]
    detect_ms: float

    def meta_json(self) -> dict[str, Any]:
        """Everything but the image, for the page's overlay and readouts."""
        return {
            "type": "frame",
            "seq": self.seq,
            "width": self.width,
            "height": self.height,
            "frame_number": self.frame_number,
            "sim_time_s": self.sim_time_s,
            "bytes": len(self.jpeg),
            "detect_ms": round(self.detect_ms, 1),
            "detection": self.detection,
        }


def frame_detection_json(frame: Frame) -> dict[str, Any]:
    """The page's detection object: the vehicle's estimate, its ring ellipses, and whether
    its detector compensated roll and pitch."""
    out = detection_to_json(frame.detection)
    out["tilt_compensated"] = frame.detection.roll_rad is not None
    return out


def parse_video_uri(uri: str) -> tuple[str, int]:
    """``tcp://host:port`` (or ``host:port``) of a vehicle's video port.

    Raises:
        LocalProtocolError: anything else, naming what is expected.
    """
    parts = split_uri(uri if "://" in uri else f"tcp://{uri}", "video source",
                      "tcp://host:port (the pilot's --video-port)")
    port = port_of(parts)
    if parts.scheme != "tcp" or not parts.hostname or port is None:
        raise LocalProtocolError(
            f"video source {uri!r}: expected tcp://host:port (the pilot's --video-port)"
        )
    return parts.hostname, port


class VideoRelay:
    """Relay the camera of a vehicle's video port (a context manager).

    Args:
        host, port: the vehicle's video port (``skeye pilot --video-port``).
        fps: the most frames per second asked of the vehicle.
        retry_s: wait before reconnecting after a failure.
        timeout_s: connecting, and the longest wait for the next whole message (bytes that
            trickle in without completing one do not extend it).
    """

    def __init__(
        self,
        host: str,
        port: int,
        *,
        fps: float = 8.0,
        retry_s: float = 1.0,
        timeout_s: float = 10.0,
    ) -> None:
        if not fps > 0:
            raise LocalProtocolError(f"video rate must be above 0 frames/s, got {fps}")
        if not timeout_s > 0 or retry_s < 0:
            raise LocalProtocolError(f"video timeout_s > 0 and retry_s >= 0 needed "
                                     f"({timeout_s}, {retry_s})")
        self.subscribe = Subscribe(fps)  # checks the range
        self.host = host
        self.port = port
        self.fps = fps
        self.retry_s = retry_s
        self.timeout_s = timeout_s
        self.state = "connecting"
        self.last_error = ""
        self.frames = 0
        self.failures = 0  # connections that ended in an error
        self.hello: Hello | None = None
        self._latest: VideoFrame | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._sock: socket.socket | None = None
        self._worker: Worker | None = None

    @property
    def address(self) -> str:
        return f"tcp://{self.host}:{self.port}"

    def start(self) -> VideoRelay:
        if self._worker is None:
            self._worker = Worker(self._run, "ground-video").start()
        return self

    def close(self, timeout_s: float = 3.0) -> None:
        """Stop the worker and close the connection (idempotent)."""
        self._stop.set()
        with self._lock:
            sock = self._sock
        if sock is not None:
            try:
                sock.shutdown(socket.SHUT_RDWR)  # unblocks a worker waiting for a frame
            except OSError:
                pass
        if self._worker is not None:
            self._worker.join(timeout_s)
        self.state = "closed"

    def __enter__(self) -> VideoRelay:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def check(self) -> None:
        """Raise :class:`~skeye.workers.WorkerFailed` if the worker died (a bug)."""
        if self._worker is not None:
            self._worker.check()

    def latest(self) -> VideoFrame | None:
        """The newest frame, or None before the first."""
        return self._latest

    def status_json(self) -> dict[str, Any]:
        frame = self._latest
        hello = self.hello
        return {
            "source": self.address,
            "camera": hello.camera if hello is not None else "(not connected yet)",
            "state": self.state,
            "frames": self.frames,
            "last_error": self.last_error,
            "fps": self.fps,
            "last_seq": None if frame is None else frame.seq,
        }

    # -- the worker ------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._relay()
            except (SkeyeError, OSError) as exc:
                if self._stop.is_set():
                    break
                self.last_error = str(exc) or type(exc).__name__
                self.state = "reconnecting"
                self.failures += 1
                log.info("video relay %s: %s", self.address, self.last_error)
            finally:
                with self._lock:
                    sock, self._sock = self._sock, None
                if sock is not None:
                    sock.close()
            self._stop.wait(self.retry_s)

    def _relay(self) -> None:
        sock = socket.create_connection((self.host, self.port), timeout=self.timeout_s)
        with self._lock:
            self._sock = sock
        if self._stop.is_set():
            return
        conn = VideoConnection(Role.CLIENT)
        sock.sendall(conn.send(self.subscribe))
        self.state = "subscribed"
        # The wait is for whole messages, not bytes: a vehicle that trickles a byte now and
        # then (a stalled encoder, a peer that is not really one) must not hold the relay.
        deadline = time.monotonic() + self.timeout_s
        while not self._stop.is_set():
            left = deadline - time.monotonic()
            try:
                if left <= 0:
                    raise TimeoutError
                sock.settimeout(left)
                data = sock.recv(256 * 1024)
            except TimeoutError:
                raise LinkTimeout(
                    f"no video from {self.address} for {self.timeout_s:g} s"
                    + (f" ({conn.buffered} bytes of an unfinished message)"
                       if conn.buffered else "")
                ) from None
            if not data:
                raise RemoteProtocolError(f"the vehicle closed the video connection {self.address}")
            messages = conn.receive_data(data)
            if messages:
                deadline = time.monotonic() + self.timeout_s
            for msg in messages:
                if isinstance(msg, Hello):
                    self.hello = msg
                    self.state = "waiting for frames"
                elif isinstance(msg, Error):
                    raise RemoteProtocolError(f"the vehicle refused the video: {msg.reason}")
                elif isinstance(msg, Frame):
                    self._publish(msg)

    def _publish(self, frame: Frame) -> None:
        self.frames += 1
        self._latest = VideoFrame(
            seq=self.frames,
            jpeg=frame.jpeg,
            width=frame.width,
            height=frame.height,
            frame_number=frame.frame_number,
            sim_time_s=frame.time_s,
            detection=frame_detection_json(frame),
            detect_ms=frame.detect_ms,
        )
        self.state = "streaming"
        self.last_error = ""
