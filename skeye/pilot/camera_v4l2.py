"""``v4l2:///dev/video0?width=800&height=600&fps=30``: a USB or CSI camera through V4L2.

How this works: OpenCV's V4L2 capture (``cv2.VideoCapture(device, cv2.CAP_V4L2)``) opens the
device with the URI's settings, applied before streaming starts and read back (the driver
may pick the nearest size or rate it has; the start-up log says what it took):

- ``width``, ``height`` (px), ``fps``; ``fourcc`` (``MJPG``, ``YUYV``: the USB webcams' two
  formats; MJPG is what reaches 30 fps at 800x600 over USB 2.0);
- ``exposure``: ``auto`` (the driver's aperture-priority mode) or a fixed exposure in V4L2's
  units of 100 us (``exposure_absolute``; a short one, 50-100, keeps motion blur down);
  ``gain`` (driver units);
- ``buffers``: driver buffers (default 1: the newest frame, never a queue of stale ones);
- ``fov_deg`` / ``fov_rad``: the horizontal field of view, for a detector without a
  calibration file (``skeye calibrate`` gives a better one).

A grabber thread (``pilot-v4l2``) reads frames as the driver delivers them and keeps the
newest; the vision takes that one, so a slow detector skips frames instead of falling behind.
Capture time: the driver's buffer timestamp (``CAP_PROP_POS_MSEC``, the kernel's monotonic
clock at the end of exposure) where it has one, else the moment the read returned; it is put
on the vehicle's clock as "that long before now". A read that fails (the camera unplugged) is
reported (``lost``) and the device is reopened every second; the pad modes hold still
meanwhile. While its device node is not there, or is no V4L2 video capture device (asked with
``VIDIOC_QUERYCAP``: a UVC camera's second node, which carries metadata, or no V4L2 device at
all), OpenCV is not asked (it would print a warning on stderr at every try, and say no more
than that it could not open it); the reason is said instead.
"""

from __future__ import annotations

import errno
import fcntl
import logging
import math
import os
import stat
import struct
import threading
import time
from dataclasses import dataclass
from typing import Any
from urllib.parse import unquote

import cv2
import numpy as np

from skeye.errors import LocalProtocolError
from skeye.pilot.camera import (
    CameraError,
    CameraImage,
    CameraOptions,
    FrameInfo,
    check_size,
    fov_option,
)
from skeye.uris import query_of, split_uri
from skeye.workers import Worker

log = logging.getLogger(__name__)

REOPEN_EVERY_S = 1.0
# linux/videodev2.h: VIDIOC_QUERYCAP = _IOR('V', 0, struct v4l2_capability), 104 bytes:
# driver[16], card[32], bus_info[32], version, capabilities, device_caps (u32), reserved[3].
VIDIOC_QUERYCAP = 0x80685600
_CAPABILITY = struct.Struct("=16s32s32sIII12x")
V4L2_CAP_VIDEO_CAPTURE = 0x00000001
V4L2_CAP_VIDEO_CAPTURE_MPLANE = 0x00001000
V4L2_CAP_DEVICE_CAPS = 0x80000000  # device_caps is filled in: this node's own capabilities
MAX_TIMESTAMP_AGE_S = 2.0  # a driver timestamp older than this is not the monotonic clock's


@dataclass(frozen=True)
class V4l2Settings:
    """A ``v4l2://`` URI, parsed."""

    device: str
    width: int | None = None
    height: int | None = None
    fps: float | None = None
    fourcc: str | None = None
    exposure: str | int | None = None  # "auto" or 100 us units
    gain: float | None = None
    buffers: int = 1
    fov_h_rad: float | None = None


def parse_v4l2_uri(uri: str) -> V4l2Settings:
    """Parse ``v4l2:///dev/videoN?key=value&...`` (see the module docstring).

    Raises:
        LocalProtocolError: naming the key and value that are wrong.
    """
    parts = split_uri(uri, "camera", "v4l2:///dev/videoN")
    if parts.scheme.lower() != "v4l2":
        raise LocalProtocolError(f"camera {uri!r}: expected v4l2:///dev/videoN")
    device = unquote(parts.netloc + parts.path)
    if not device.startswith("/dev/"):
        raise LocalProtocolError(f"camera {uri!r}: expected a device path, v4l2:///dev/video0")
    query = query_of(uri, parts, "camera")
    known = {"width", "height", "fps", "fourcc", "exposure", "gain", "buffers", "fov_deg",
             "fov_rad"}
    unknown = sorted(set(query) - known)
    if unknown:
        raise LocalProtocolError(f"camera {uri!r}: unknown option(s) {unknown} (known: "
                                 f"{', '.join(sorted(known))})")

    def value(key: str) -> str | None:
        return query[key][-1] if key in query else None

    def integer(key: str, low: int, high: int) -> int | None:
        text = value(key)
        if text is None:
            return None
        # isascii: str.isdigit() also accepts digits int() refuses (superscripts such as "²")
        if not (text.isascii() and text.isdigit()) or not low <= int(text) <= high:
            raise LocalProtocolError(f"camera {uri!r}: {key}={text} is not a whole number "
                                     f"{low}..{high}")
        return int(text)

    def number(key: str, low: float, high: float) -> float | None:
        text = value(key)
        if text is None:
            return None
        try:
            x = float(text)
        except ValueError:
            x = math.nan
        if not (math.isfinite(x) and low <= x <= high):
            raise LocalProtocolError(f"camera {uri!r}: {key}={text} is not a number "
                                     f"{low:g}..{high:g}")
        return x

    fourcc = value("fourcc")
    if fourcc is not None and (len(fourcc) != 4 or not fourcc.isascii()):
        raise LocalProtocolError(f"camera {uri!r}: fourcc={fourcc} is not four characters "
                                 "(MJPG, YUYV)")
    exposure: str | int | None = value("exposure")
    if exposure is not None and exposure != "auto":
        exposure = integer("exposure", 1, 100_000)
    fps = number("fps", 0.1, 1000.0)
    return V4l2Settings(
        device=device,
        width=integer("width", 1, 16384),
        height=integer("height", 1, 16384),
        fps=fps,
        fourcc=fourcc.upper() if fourcc else None,
        exposure=exposure,
        gain=number("gain", 0.0, 100_000.0),
        buffers=integer("buffers", 1, 32) or 1,
        fov_h_rad=fov_option(uri, query),
    )


def capture_problem(device: str) -> str | None:
    """Why ``device`` is no V4L2 video capture node, or None when it is one (the kernel's
    ``VIDIOC_QUERYCAP`` answer, read as OpenCV's V4L2 capture would need it)."""
    try:
        if not stat.S_ISCHR(os.stat(device).st_mode):
            return "not a device"
        fd = os.open(device, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        return exc.strerror or str(exc)
    try:
        answer = bytearray(_CAPABILITY.size)
        fcntl.ioctl(fd, VIDIOC_QUERYCAP, answer)
    except OSError as exc:
        if exc.errno in (errno.ENOTTY, errno.EINVAL):
            return "not a V4L2 device"
        return exc.strerror or str(exc)
    finally:
        os.close(fd)
    _, card, _, _, caps, device_caps = _CAPABILITY.unpack(answer)
    if caps & V4L2_CAP_DEVICE_CAPS:
        caps = device_caps
    if caps & (V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_VIDEO_CAPTURE_MPLANE):
        return None
    name = card.split(b"\0", 1)[0].decode("utf-8", "replace")
    return (f"{name or 'a V4L2 device'} has no video capture on this node (a UVC camera's "
            "second node carries metadata: its first is the camera)")


def apply_settings(cap: Any, s: V4l2Settings) -> dict[str, float]:
    """Set a capture's properties from ``s`` (format first: it decides the sizes a driver
    offers); returns what the driver reports back."""
    if s.fourcc:
        cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*s.fourcc))
    if s.width:
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, s.width)
    if s.height:
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, s.height)
    if s.fps:
        cap.set(cv2.CAP_PROP_FPS, s.fps)
    cap.set(cv2.CAP_PROP_BUFFERSIZE, s.buffers)
    if s.exposure == "auto":
        cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, 3)  # V4L2_EXPOSURE_APERTURE_PRIORITY
    elif s.exposure is not None:
        cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, 1)  # V4L2_EXPOSURE_MANUAL
        cap.set(cv2.CAP_PROP_EXPOSURE, float(s.exposure))
    if s.gain is not None:
        cap.set(cv2.CAP_PROP_GAIN, s.gain)
    return {
        "width": cap.get(cv2.CAP_PROP_FRAME_WIDTH),
        "height": cap.get(cv2.CAP_PROP_FRAME_HEIGHT),
        "fps": cap.get(cv2.CAP_PROP_FPS),
        "exposure": cap.get(cv2.CAP_PROP_EXPOSURE),
    }


class V4l2Camera:
    """A V4L2 device, read by a grabber thread (see the module docstring)."""

    def __init__(self, uri: str, settings: V4l2Settings, options: CameraOptions) -> None:
        self.uri = uri
        self.settings = settings
        self.options = options
        self.fov_h_rad = settings.fov_h_rad if settings.fov_h_rad is not None else (
            options.fov_h_rad)
        self.applied: dict[str, float] = {}
        self.driver_timestamps = 0  # frames stamped by the driver (the rest: at read time)
        self._cond = threading.Condition()
        self._newest: tuple[int, float, np.ndarray] | None = None
        self._count = 0
        self._lost: str | None = None
        self._stop = threading.Event()
        self._cap: Any = None
        self._open()  # a missing device is said at once (and retried by the grabber)
        self._grabber = Worker(self._grab_loop, "pilot-v4l2").start()

    def _open(self) -> bool:
        if not os.path.exists(self.settings.device):  # unplugged: OpenCV would warn at each try
            self._lost = f"camera {self.uri}: cannot open {self.settings.device} (no such device)"
            return False
        problem = capture_problem(self.settings.device)  # OpenCV would warn, and say less
        if problem is not None:
            self._lost = f"camera {self.uri}: cannot open {self.settings.device} ({problem})"
            return False
        cap = cv2.VideoCapture(self.settings.device, cv2.CAP_V4L2)
        if not cap.isOpened():
            cap.release()
            self._lost = f"camera {self.uri}: cannot open {self.settings.device}"
            return False
        self.applied = apply_settings(cap, self.settings)
        s = self.settings
        log.info("camera %s: %gx%g at %g fps (asked %sx%s at %s)", self.uri,
                 self.applied["width"], self.applied["height"], self.applied["fps"],
                 s.width, s.height, s.fps)
        self._cap = cap
        return True

    def _grab_loop(self) -> None:
        while not self._stop.is_set():
            if self._cap is None and not self._open():
                self._stop.wait(REOPEN_EVERY_S)
                continue
            ok, frame = self._cap.read()
            returned = time.monotonic()
            if not ok or frame is None:
                was = self._lost
                self._lost = f"camera {self.uri}: no frame from {self.settings.device} " \
                             "(unplugged?)"
                if was is None:
                    log.warning("%s; reopening it every %g s", self._lost, REOPEN_EVERY_S)
                self._cap.release()
                self._cap = None
                self._stop.wait(REOPEN_EVERY_S)
                continue
            stamp_ms = self._cap.get(cv2.CAP_PROP_POS_MSEC)
            age = returned - stamp_ms / 1e3 if stamp_ms and stamp_ms > 0 else math.nan
            if 0.0 <= age <= MAX_TIMESTAMP_AGE_S:
                self.driver_timestamps += 1
            else:
                age = 0.0
            capture_s = self.options.clock() - age
            if self._lost is not None:
                log.warning("camera %s: frames again", self.uri)
                self._lost = None
            with self._cond:
                self._count += 1
                self._newest = (self._count, capture_s, frame)
                self._cond.notify_all()
        if self._cap is not None:
            self._cap.release()

    @property
    def latest(self) -> FrameInfo | None:
        newest = self._newest
        return None if newest is None else FrameInfo(newest[0], newest[1])

    def image(self) -> CameraImage:
        self._grabber.check()
        newest = self._newest
        if self._lost is not None or newest is None:
            raise CameraError(self._lost or f"camera {self.uri}: no frame yet")
        number, capture_s, frame = newest
        check_size(self.uri, self.options.size_px, frame.shape[1], frame.shape[0])
        return CameraImage(number, capture_s, frame)

    @property
    def lost(self) -> str | None:
        return self._lost

    def close(self) -> None:
        self._stop.set()
        self._grabber.join(3.0)


def open_v4l2_camera(uri: str, options: CameraOptions) -> V4l2Camera:
    """The ``v4l2://`` camera source.

    A device that is not there yet is reported (``lost``) and looked for every second: the
    pilot starts, and the pad modes hold still until it appears.

    Raises:
        LocalProtocolError: a bad URI.
    """
    return V4l2Camera(uri, parse_v4l2_uri(uri), options)
