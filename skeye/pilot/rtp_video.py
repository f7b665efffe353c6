"""The pilot's camera as H.264 over RTP on UDP, for MAVLink ground stations (QGroundControl's
UDP 5600 convention).

How this works: :class:`RtpVideo` takes the frames the pad vision looked at
(:meth:`publish`, from the vision thread: it only swaps the newest-frame slot, never waits), and
its own worker thread (``pilot-rtp-video``) draws the detection over each frame (the pad centre,
the ring ellipses, the height), encodes it with FFmpeg's libx264 through PyAV (``ultrafast``,
``zerolatency``: no B-frames, a key frame every second) and sends it as RTP (payload type 96,
RFC 6184 packetisation by FFmpeg's RTP muxer) to ``udp://HOST:PORT``. At most ``max_fps``
frames a second are encoded; a frame that comes while one is being encoded replaces the older.
QGroundControl shows it with its video source set to "UDP h.264 Video Stream" on port 5600;
other players need the stream described by :meth:`sdp` (docs/protocols/mavlink.md). The
encoder opens on the first frame (the camera's size). ``close`` is idempotent.
"""

from __future__ import annotations

import errno
import logging
import math
import socket
import threading
import time
from fractions import Fraction
from typing import Any

import cv2
import numpy as np

from skeye.errors import ConfigError
from skeye.pilot.video_server import CameraFrame
from skeye.uris import port_of, split_uri, url_host
from skeye.workers import Worker

log = logging.getLogger(__name__)

PAYLOAD_TYPE = 96
DEFAULT_RTP_FPS = 10.0
MIN_RTP_FPS, MAX_RTP_FPS = 0.1, 60.0  # frames/s (--rtp-fps)
DEFAULT_BITRATE = 1_000_000  # bit/s
RESOLVE_TIMEOUT_S = 5.0
"""How long the start check waits for the system resolver (glibc's own: 5 s a try, 2 tries
per name server, so an unreachable DNS server holds a lookup for tens of seconds)."""
GREEN = (0, 200, 0)
RED = (0, 0, 230)


def parse_rtp_uri(uri: str) -> tuple[str, int]:
    """``udp://HOST:PORT`` -> (host, port).

    Raises:
        ConfigError: another scheme, or no port.
    """
    parts = split_uri(uri, "video stream", "rtp://HOST:PORT", ConfigError)
    port = port_of(parts)
    if parts.scheme != "udp" or not parts.hostname or not port:
        raise ConfigError(f"{uri}: the RTP video goes to udp://HOST:PORT (port 1-65535), e.g. "
                          "udp://127.0.0.1:5600")
    return parts.hostname, port


def _resolve(uri: str, host: str, port: int, timeout_s: float) -> list[Any]:
    """``socket.getaddrinfo`` for UDP, waited for at most ``timeout_s``: the system resolver
    takes no timeout, so it runs on a daemon thread, left behind if it does not answer."""
    answer: list[Any] = []
    done = threading.Event()

    def lookup() -> None:
        try:
            answer.append(socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM))
        except (OSError, UnicodeError) as exc:
            answer.append(exc)
        finally:
            done.set()

    Worker(lookup, f"resolve-{host}").start()
    if not done.wait(timeout_s):
        raise ConfigError(f"{uri}: the host {host!r} did not resolve within {timeout_s:g} s "
                          "(is a DNS server reachable? an IP address needs none)")
    if not answer:  # a bug in the resolver: the worker logged it
        raise ConfigError(f"{uri}: resolving the host {host!r} failed (see the log)")
    if isinstance(answer[0], Exception):
        raise ConfigError(f"{uri}: cannot resolve the host {host!r} ({answer[0]})")
    return list(answer[0])


def check_rtp_destination(uri: str, timeout_s: float | None = None) -> tuple[str, int, str]:
    """:func:`parse_rtp_uri`, and whether this machine can send UDP there now: the host
    resolves within ``timeout_s`` (``RESOLVE_TIMEOUT_S``) and a UDP socket can be pointed at
    it (a route exists; not a broadcast address). FFmpeg would find the same only on the first
    frame, in the worker, as a bare ``Input/output error``. Returns the host, the port and the
    address it resolved to (the stream goes there: FFmpeg does not resolve the name again).

    Raises:
        ConfigError: naming the URI and what is wrong with it.
    """
    host, port = parse_rtp_uri(uri)
    infos = _resolve(uri, host, port, RESOLVE_TIMEOUT_S if timeout_s is None else timeout_s)
    family, kind, proto, _, address = infos[0]
    try:
        with socket.socket(family, kind, proto) as probe:
            probe.connect(address)  # UDP: nothing is sent; the kernel checks the route
    except OSError as exc:
        reason = exc.strerror or str(exc)
        if exc.errno == errno.EACCES:
            reason += " (a broadcast address: the RTP video goes to one host or a multicast group)"
        raise ConfigError(f"{uri}: cannot send UDP to {address[0]} port {port}: {reason}") from None
    return host, port, str(address[0])


MAX_DRAWN_PX = 1 << 20
"""The largest coordinate or semi-axis (px, either sign) overlay draws: OpenCV takes only C
ints, and a shape that far out is no part of any camera's image anyway."""


def _drawable(*values: float) -> bool:
    return all(abs(v) <= MAX_DRAWN_PX for v in values)


def overlay(frame: CameraFrame) -> np.ndarray:
    """The frame with its detection drawn on it (a copy); a shape too far out to draw
    (:data:`MAX_DRAWN_PX`) is left out."""
    img = np.ascontiguousarray(frame.bgr).copy()
    det = frame.detection
    for ring in det.ellipses:
        (cx, cy), (a, b) = ring.center_px, ring.semi_axes_px
        if not _drawable(cx, cy, a, b):
            continue
        cv2.ellipse(img, (round(cx), round(cy)), (max(1, round(a)), max(1, round(b))),
                    math.degrees(ring.angle_rad), 0, 360, GREEN, 1, cv2.LINE_AA)
    if det.found and det.center_px is not None and _drawable(*det.center_px):
        cx, cy = (round(v) for v in det.center_px)
        cv2.drawMarker(img, (cx, cy), RED, cv2.MARKER_CROSS, 14, 2)
    text = (f"pad {det.height_m:.2f} m" if det.found and det.height_m is not None
            else "no pad")
    cv2.putText(img, f"{text}  t={frame.time_s:.1f}s", (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                GREEN if det.found else RED, 1, cv2.LINE_AA)
    return img


class RtpVideo:
    """Encode published frames as H.264 and send them as RTP to one UDP address."""

    def __init__(self, uri: str, *, max_fps: float = DEFAULT_RTP_FPS,
                 bitrate: int = DEFAULT_BITRATE) -> None:
        import av  # the `mavlink` extra (PyAV: FFmpeg with libx264)

        if "libx264" not in av.codecs_available:
            raise ConfigError("PyAV has no libx264 encoder here: no H.264 RTP video")
        if not MIN_RTP_FPS <= max_fps <= MAX_RTP_FPS:
            raise ConfigError(f"RTP video frame rate must be {MIN_RTP_FPS:g}..{MAX_RTP_FPS:g} "
                              f"frames/s, got {max_fps:g}")
        self.host, self.port, self.ip = check_rtp_destination(uri)
        self.address = f"udp://{url_host(self.host)}:{self.port}"
        self.max_fps = max_fps
        self.bitrate = bitrate
        self.frames_sent = 0
        self.packets_sent = 0
        self.size: tuple[int, int] | None = None
        self._slot: CameraFrame | None = None
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._worker: Worker | None = None

    def publish(self, frame: CameraFrame) -> None:
        """Offer a frame (the newest wins; never blocks)."""
        with self._cond:
            self._slot = frame
            self._cond.notify()

    def start(self) -> RtpVideo:
        if self._worker is None:
            self._worker = Worker(self._run, "pilot-rtp-video").start()
        return self

    def check(self) -> None:
        if self._worker is not None:
            self._worker.check()

    def close(self, timeout_s: float = 2.0) -> None:
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        if self._worker is not None:
            self._worker.join(timeout_s)

    def __enter__(self) -> RtpVideo:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def sdp(self) -> str:
        """The session description a player needs for this stream (QGroundControl does not)."""
        ip = "IP6" if ":" in self.ip else "IP4"
        return (f"v=0\r\no=- 0 0 IN {ip} {self.ip}\r\ns=skeye pilot camera\r\n"
                f"c=IN {ip} {self.ip}\r\nt=0 0\r\nm=video {self.port} RTP/AVP {PAYLOAD_TYPE}\r\n"
                f"a=rtpmap:{PAYLOAD_TYPE} H264/90000\r\n"
                f"a=fmtp:{PAYLOAD_TYPE} packetization-mode=1\r\n")

    def _open(self, width: int, height: int) -> tuple[Any, Any]:
        import av

        url = f"rtp://{url_host(self.ip)}:{self.port}?pkt_size=1200"  # resolved at start
        try:
            container = av.open(url, mode="w", format="rtp")
        except (av.error.FFmpegError, OSError) as exc:  # checked at start: the network changed
            raise ConfigError(f"RTP video to {self.address}: FFmpeg: {exc}") from None
        stream = container.add_stream("libx264", rate=Fraction(round(self.max_fps * 1000), 1000))
        stream.width, stream.height = width, height
        stream.pix_fmt = "yuv420p"
        stream.bit_rate = self.bitrate
        stream.options = {"preset": "ultrafast", "tune": "zerolatency",
                          "g": str(max(1, round(self.max_fps))), "bf": "0"}
        stream.codec_context.time_base = Fraction(1, 90_000)
        return container, stream

    def _run(self) -> None:
        import av

        container: Any = None
        stream: Any = None
        last_s = -math.inf
        start_s = time.monotonic()
        try:
            while not self._stop.is_set():
                with self._cond:
                    self._cond.wait_for(lambda: self._slot is not None or self._stop.is_set(),
                                        0.5)
                    frame, self._slot = self._slot, None
                if frame is None or self._stop.is_set():
                    continue
                wait = last_s + 1.0 / self.max_fps - time.monotonic()
                if wait > 0:
                    self._stop.wait(wait)
                    with self._cond:  # a newer frame may have come meanwhile
                        frame = self._slot or frame
                        self._slot = None
                last_s = time.monotonic()
                img = overlay(frame)
                height, width = img.shape[:2]
                width, height = width - width % 2, height - height % 2  # 4:2:0 needs even sizes
                if container is None:
                    container, stream = self._open(width, height)
                    self.size = (width, height)
                picture = av.VideoFrame.from_ndarray(img[:height, :width], format="bgr24")
                picture.pts = round((last_s - start_s) * 90_000)
                picture.time_base = Fraction(1, 90_000)
                try:
                    for packet in stream.encode(picture):
                        container.mux(packet)  # the first one opens the UDP socket
                        self.packets_sent += 1
                except (av.error.FFmpegError, OSError) as exc:
                    raise ConfigError(f"RTP video to {self.address}: FFmpeg: {exc}") from None
                self.frames_sent += 1
        finally:
            if container is not None:
                try:
                    container.close()
                except Exception as exc:  # closing a UDP sender: nothing to lose
                    log.debug("RTP video close: %s", exc)
