"""The frame store between the render thread and the image server's clients.

How this works: the engine's render step calls :meth:`FrameBuffer.publish` with each rendered
:class:`Frame`. That only stores a reference under a lock, notifies a Condition and pokes
listeners that never block, so the simulator never waits on a client. Encoded images are cached
per (camera, its id, frame number, format, quality): the first client thread that needs an encoding
makes it, the others wait for that one (single flight), so four clients asking for the same
frame in the same format cost one encoding. The cache is a small LRU. The TCP side is
:mod:`skeye.sim.image_server`.
"""

from __future__ import annotations

import logging
import math
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from skeye.errors import LocalProtocolError
from skeye.pixels import encode_image
from skeye.wire.image_requests import SelectCamera
from skeye.wire.images import UINT32_MAX, FrameType, ImageFormat, jpeg_type_for_quality

log = logging.getLogger(__name__)

_ENCODE_WAIT_S = 5.0  # a thread waiting on another's encoding gives up and encodes itself

FrameListener = Callable[[str], None]


class PixelSource(Protocol):
    """Where a frame's pixels come from when it was published before they existed (the
    simulator renders a frame only when someone asks for it: skeye.sim.cameras)."""

    def pixels(self) -> tuple[np.ndarray, bytes | None]:
        """The frame's RGB pixels and its camera's JPEG bytes (None for a raw camera); blocks
        until they exist. Raises SkeyeError when they cannot be made."""
        ...


class Frame:
    """One image of one camera.

    ``number`` counts the camera's frames, from 1; ``rgb`` is (H, W, 3) uint8, rows top to
    bottom, RGB order. Publishing hands the array over: the buffer marks it read-only. A frame
    may be published before its pixels exist (``source``, with ``width`` and ``height``): the
    first reader of ``rgb`` (or ``jpeg``) waits for them, the others share the result. ``jpeg``
    holds the camera's own JPEG bytes of the same pixels (a webcam's MJPEG), coded at
    ``jpeg_quality``; an image client asking for JPEG at that quality gets them as they are.
    """

    __slots__ = ("_jpeg", "_lock", "_rgb", "_source", "camera", "camera_id", "height",
                 "jpeg_quality", "number", "sim_time_s", "width")

    def __init__(
        self,
        camera: str,
        camera_id: int,
        number: int,
        sim_time_s: float,
        rgb: np.ndarray | None = None,
        *,
        jpeg: bytes | None = None,
        jpeg_quality: int = 0,
        source: PixelSource | None = None,
        width: int = 0,
        height: int = 0,
    ) -> None:
        SelectCamera(camera)  # the same naming rule as the wire
        for name, value, low in (("camera_id", camera_id, 0), ("number", number, 1)):
            if (
                isinstance(value, bool)
                or not isinstance(value, int)
                or not (low <= value <= UINT32_MAX)
            ):
                raise LocalProtocolError(
                    f"Frame.{name} must be an integer {low}-2^32-1, got {value!r}"
                )
        if not math.isfinite(sim_time_s):
            raise LocalProtocolError(f"Frame.sim_time_s must be finite, got {sim_time_s!r}")
        self.camera = camera
        self.camera_id = camera_id
        self.number = number
        self.sim_time_s = sim_time_s
        self.jpeg_quality = jpeg_quality
        self._jpeg = jpeg
        self._source = source
        self._lock = threading.Lock()
        if rgb is not None:
            _check_rgb(rgb)
            self._rgb: np.ndarray | None = rgb
            self.height, self.width = int(rgb.shape[0]), int(rgb.shape[1])
        elif source is None:
            raise LocalProtocolError("Frame.rgb must be an (H, W, 3) uint8 array")
        else:
            if width < 1 or height < 1:
                raise LocalProtocolError("a Frame without pixels yet needs its width and height")
            self._rgb = None
            self.width, self.height = width, height

    @property
    def ready(self) -> bool:
        """True once the pixels exist."""
        return self._rgb is not None

    @property
    def rgb(self) -> np.ndarray:
        """The pixels (read-only once published); made on first use for a frame with a source."""
        rgb = self._rgb
        if rgb is None:
            rgb = self._fetch()
        return rgb

    @property
    def jpeg(self) -> bytes | None:
        """The camera's JPEG of these pixels, or None."""
        if self._rgb is None:
            self._fetch()
        return self._jpeg

    def _fetch(self) -> np.ndarray:
        with self._lock:
            if self._rgb is None:
                assert self._source is not None
                rgb, jpeg = self._source.pixels()
                _check_rgb(rgb)
                if rgb.shape[:2] != (self.height, self.width):
                    raise LocalProtocolError(
                        f"frame {self.camera} {self.number}: pixels are {rgb.shape[1]}x"
                        f"{rgb.shape[0]}, not {self.width}x{self.height}")
                rgb.flags.writeable = False
                self._jpeg = jpeg
                self._rgb = rgb
                self._source = None
            return self._rgb

    def __repr__(self) -> str:
        state = "" if self.ready else ", pixels pending"
        return (f"Frame({self.camera!r}, id {self.camera_id}, #{self.number}, "
                f"t={self.sim_time_s:.3f}, {self.width}x{self.height}{state})")


def _check_rgb(rgb: object) -> None:
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8 or rgb.ndim != 3:
        raise LocalProtocolError("Frame.rgb must be an (H, W, 3) uint8 array")
    if rgb.shape[2] != 3 or rgb.shape[0] == 0 or rgb.shape[1] == 0:
        raise LocalProtocolError(f"Frame.rgb must have shape (H, W, 3), got {rgb.shape}")


@dataclass
class _CameraSlot:
    camera_id: int
    frame: Frame | None = None


@dataclass
class _Encoding:
    done: threading.Event = field(default_factory=threading.Event)
    result: tuple[FrameType, bytes] | None = None


_CacheKey = tuple[str, int, int, ImageFormat, int | None]


class _EncodeCache:
    """Small LRU of encoded images with single-flight encoding (see module comment)."""

    def __init__(self, max_entries: int) -> None:
        if max_entries < 1:
            raise LocalProtocolError(f"encode cache needs at least one entry, got {max_entries}")
        self._max_entries = max_entries
        self._lock = threading.Lock()
        self._entries: OrderedDict[_CacheKey, _Encoding] = OrderedDict()
        self.encodes = 0

    def get(self, frame: Frame, kind: ImageFormat, quality: int | None) -> tuple[FrameType, bytes]:
        # The camera's id too: a robot spawned again under a gone one's name numbers its
        # frames from 1 again, and its frame 1 is not the gone robot's.
        key: _CacheKey = (frame.camera, frame.camera_id, frame.number, kind, quality)
        with self._lock:
            entry = self._entries.get(key)
            owner = entry is None
            if entry is None:
                entry = _Encoding()
                self._entries[key] = entry
                while len(self._entries) > self._max_entries:
                    self._entries.popitem(last=False)
            else:
                self._entries.move_to_end(key)
        if owner:
            try:
                entry.result = _encode(frame, kind, quality)
            finally:
                entry.done.set()
                with self._lock:
                    self.encodes += 1
                    if entry.result is None and self._entries.get(key) is entry:
                        del self._entries[key]
            return entry.result
        if entry.done.wait(_ENCODE_WAIT_S) and entry.result is not None:
            return entry.result
        return _encode(frame, kind, quality)  # the owner failed or is stuck


def _encode(frame: Frame, kind: ImageFormat, quality: int | None) -> tuple[FrameType, bytes]:
    """The frame in a format: the camera's own JPEG when it is one at the quality asked for
    (a webcam's MJPEG stream, passed on as a real image server passes a camera's frames)."""
    if kind is ImageFormat.JPEG and quality is not None and quality == frame.jpeg_quality:
        jpeg = frame.jpeg
        if jpeg is not None:
            return jpeg_type_for_quality(quality), jpeg
    return encode_image(frame.rgb, kind, quality)


class FrameBuffer:
    """Thread-safe store of the newest frame of each camera, shared by the engine and servers."""

    def __init__(self, cache_entries: int = 16) -> None:
        self._cond = threading.Condition()
        self._slots: dict[str, _CameraSlot] = {}  # insertion order = registration order
        self._listeners: tuple[FrameListener, ...] = ()
        self._cache = _EncodeCache(cache_entries)
        # Who may receive each camera's frames: watcher handle -> camera (None: the first).
        self._watchers: dict[int, str | None] = {}
        self._next_watcher = 1

    def register_camera(self, name: str, camera_id: int) -> None:
        """Make a camera known before its first frame (keeps the camera order stable)."""
        SelectCamera(name)
        with self._cond:
            slot = self._slots.get(name)
            if slot is None:
                self._slots[name] = _CameraSlot(camera_id)
            elif slot.camera_id != camera_id:
                raise LocalProtocolError(
                    f"camera {name} is registered with id {slot.camera_id}, not {camera_id}"
                )
        self._notify(name)

    def remove_camera(self, name: str) -> None:
        """Forget a camera (its robot went); waiters for it wake up empty-handed."""
        with self._cond:
            removed = self._slots.pop(name, None) is not None
            self._cond.notify_all()
        if removed:
            self._notify(name)

    def publish(self, frame: Frame) -> None:
        """Store ``frame`` as its camera's newest; cheap, never waits on a client.

        Raises:
            LocalProtocolError: the camera id changed or the frame number did not increase.
        """
        if frame.ready:
            frame.rgb.flags.writeable = False
        with self._cond:
            slot = self._slots.get(frame.camera)
            if slot is None:
                slot = self._slots[frame.camera] = _CameraSlot(frame.camera_id)
            elif slot.camera_id != frame.camera_id:
                raise LocalProtocolError(
                    f"camera {frame.camera} has id {slot.camera_id}, frame says {frame.camera_id}"
                )
            if slot.frame is not None and frame.number <= slot.frame.number:
                raise LocalProtocolError(
                    f"camera {frame.camera}: frame {frame.number} after {slot.frame.number}"
                )
            slot.frame = frame
            self._cond.notify_all()
        self._notify(frame.camera)

    def watch(self, camera: str | None = None) -> int:
        """Say that someone (an image client) may ask for ``camera``'s frames (None: whichever
        camera is first); returns a handle for :meth:`rewatch` and :meth:`unwatch`. The
        simulator renders a frame at once only for a watched camera (:meth:`wanted`), else
        when it is asked for."""
        with self._cond:
            handle = self._next_watcher
            self._next_watcher += 1
            self._watchers[handle] = camera
            return handle

    def rewatch(self, handle: int, camera: str | None) -> None:
        """The watcher ``handle`` now wants ``camera`` (None: the first camera)."""
        with self._cond:
            if handle in self._watchers:
                self._watchers[handle] = camera

    def unwatch(self, handle: int) -> None:
        """The watcher is gone; unknown handles are ignored."""
        with self._cond:
            self._watchers.pop(handle, None)

    def wanted(self, camera: str) -> bool:
        """True while some watcher may ask for this camera's frames."""
        with self._cond:
            if not self._watchers:
                return False
            first = next(iter(self._slots), None)
            return any(w == camera or (w is None and first == camera)
                       for w in self._watchers.values())

    def cameras(self) -> list[str]:
        """Camera names in order of registration or first publication."""
        with self._cond:
            return list(self._slots)

    def camera_id(self, name: str) -> int | None:
        """The id of a camera, or None if it is unknown."""
        with self._cond:
            slot = self._slots.get(name)
            return None if slot is None else slot.camera_id

    def latest(self, camera: str) -> Frame | None:
        """The newest frame of ``camera``, or None (no frame yet, or no such camera)."""
        with self._cond:
            slot = self._slots.get(camera)
            return None if slot is None else slot.frame

    def wait_newer(self, camera: str, after_number: int, timeout_s: float) -> Frame | None:
        """The newest frame of ``camera`` numbered above ``after_number``, waiting up to
        ``timeout_s``; None on timeout or if the camera is removed meanwhile."""

        def ready() -> bool:
            slot = self._slots.get(camera)
            return slot is None or (slot.frame is not None and slot.frame.number > after_number)

        with self._cond:
            self._cond.wait_for(ready, timeout=timeout_s)
            slot = self._slots.get(camera)
            if slot is None or slot.frame is None or slot.frame.number <= after_number:
                return None
            return slot.frame

    def encoded(
        self, frame: Frame, kind: ImageFormat, quality: int | None = None
    ) -> tuple[FrameType, bytes]:
        """The base frame type and payload of ``frame`` in a format, encoded at most once."""
        return self._cache.get(frame, kind, quality)

    @property
    def encode_count(self) -> int:
        """How many encodings were actually made (cache misses); for tests and benchmarks."""
        return self._cache.encodes

    def add_listener(self, listener: FrameListener) -> None:
        """Call ``listener(camera)`` after each publish or camera change; it must not block."""
        with self._cond:
            self._listeners = (*self._listeners, listener)

    def remove_listener(self, listener: FrameListener) -> None:
        """Stop calling ``listener``; unknown listeners are ignored.

        Listeners are compared with ``==``, not ``is``: a bound method (an image client's
        ``_on_publish``) is a new object at each attribute access, equal to the one added."""
        with self._cond:
            self._listeners = tuple(x for x in self._listeners if x != listener)

    def _notify(self, camera: str) -> None:
        for listener in self._listeners:
            try:
                listener(camera)
            except Exception:
                log.exception("image frame listener failed")
