"""Camera relay: JPEG frames from the simulator's image server, with the pad detection.

How this works: ``VideoRelay`` runs one worker thread that alone owns an ``ImageClient``: it
selects the camera (or takes the server's default: the first camera of the first robot), asks
for JPEG frames with META headers at up to ``fps``, and for every frame decodes it, runs
``skeye.vision.detect`` (tilt-compensated with the vehicle's attitude when an ``attitude``
source is given) and publishes a ``VideoFrame``: the JPEG bytes as received plus the detection
(ring ellipses and centre in pixels, height, offset, quality) as JSON. The page draws the frame
and overlays the ellipses itself, so the JPEG is relayed without re-encoding. Browsers read
``latest()``; nothing waits on a browser. Any failure (server gone, a bad frame) closes the
client and the worker reconnects after ``retry_s``; ``state`` and ``last_error`` say why.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Any

import cv2
import numpy as np

from skeye.control.image_client import ImageClient
from skeye.errors import LocalProtocolError, SkeyeError
from skeye.pixels import frame_image
from skeye.vision.detector import detect

log = logging.getLogger(__name__)

Attitude = Callable[[], tuple[float, float] | None]  # (roll_rad, pitch_rad) or None


@dataclass(frozen=True)
class VideoFrame:
    """One relayed frame and what the detector saw in it."""

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


def detection_json(image: np.ndarray, fov_h_rad: float, attitude: tuple[float, float] | None
                   ) -> dict[str, Any]:
    """Run the detector on one BGR frame; its estimate plus every identified ring ellipse."""
    roll, pitch = attitude if attitude is not None else (None, None)
    est = detect(image, fov_h_rad, roll_rad=roll, pitch_rad=pitch)
    out = est.to_json_dict()
    out["ellipses"] = [e.to_json_dict() for e in est.ellipses]
    out["tilt_compensated"] = attitude is not None
    return out


class VideoRelay:
    """Relay one camera from an image server (a context manager).

    Args:
        host, port: the image server.
        fov_h_rad: the camera's horizontal field of view (for the detector's geometry).
        camera: ``robot/camera`` to select, or None for the server's default camera.
        fps: frames per second asked of the server.
        quality: JPEG quality 1..100.
        attitude: returns the vehicle's (roll_rad, pitch_rad) for tilt compensation, or None.
        retry_s: wait before reconnecting after a failure.
    """

    def __init__(
        self,
        host: str,
        port: int,
        *,
        fov_h_rad: float,
        camera: str | None = None,
        fps: float = 8.0,
        quality: int = 80,
        attitude: Attitude | None = None,
        retry_s: float = 1.0,
    ) -> None:
        if not 0 < fov_h_rad < np.pi:
            raise LocalProtocolError(f"camera field of view must be in (0, pi) rad: {fov_h_rad}")
        if not fps > 0:
            raise LocalProtocolError(f"video rate must be above 0 frames/s, got {fps}")
        self.host = host
        self.port = port
        self.fov_h_rad = fov_h_rad
        self.camera = camera
        self.fps = fps
        self.quality = quality
        self.attitude = attitude
        self.retry_s = retry_s
        self.state = "connecting"
        self.last_error = ""
        self.frames = 0
        self._latest: VideoFrame | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._client: ImageClient | None = None
        self._thread: threading.Thread | None = None

    @property
    def address(self) -> str:
        return f"tcp://{self.host}:{self.port}"

    def start(self) -> VideoRelay:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="ground-video", daemon=True)
            self._thread.start()
        return self

    def close(self, timeout_s: float = 3.0) -> None:
        """Stop the worker and close the image connection (idempotent)."""
        self._stop.set()
        with self._lock:
            client = self._client
        if client is not None:
            client.close()  # unblocks a worker waiting for a frame
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
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

    def latest(self) -> VideoFrame | None:
        """The newest frame, or None before the first."""
        return self._latest

    def status_json(self) -> dict[str, Any]:
        frame = self._latest
        return {
            "source": self.address,
            "camera": self.camera or "(server default)",
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
            except (SkeyeError, OSError, cv2.error) as exc:
                if self._stop.is_set():
                    break
                self.state = "reconnecting"
                self.last_error = str(exc)
                log.info("video relay %s: %s", self.address, exc)
            finally:
                with self._lock:
                    client, self._client = self._client, None
                if client is not None:
                    client.close()
            self._stop.wait(self.retry_s)

    def _relay(self) -> None:
        client = ImageClient(self.host, self.port, timeout_s=5.0)
        with self._lock:
            self._client = client
        if self._stop.is_set():
            return
        if self.camera:
            client.select_camera(self.camera)
        client.set_format("jpeg", self.quality)
        client.set_meta(True)
        for frame in client.stream(self.fps):
            if self._stop.is_set():
                return
            image = frame_image(frame)
            t0 = time.perf_counter()
            detection = detection_json(
                image, self.fov_h_rad, self.attitude() if self.attitude else None
            )
            detect_ms = (time.perf_counter() - t0) * 1e3
            meta = frame.meta
            self.frames += 1
            self._latest = VideoFrame(
                seq=self.frames,
                jpeg=frame.data,
                width=int(image.shape[1]),
                height=int(image.shape[0]),
                frame_number=None if meta is None else int(meta.frame_number),
                sim_time_s=None if meta is None else float(meta.sim_time_s),
                detection=detection,
                detect_ms=detect_ms,
            )
            self.state = "streaming"
            self.last_error = ""
