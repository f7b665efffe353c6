"""The pilot's camera, chosen by URI: the simulator's, a V4L2 device, or a recorded video.

How this works: a :class:`CameraSource` is what the pad vision (:mod:`skeye.pilot.vision`)
reads. ``latest`` announces the newest frame (its number and capture time, cheap, never
blocking long) and ``image()`` returns that frame's pixels; a frame the source cannot give
(a device unplugged, a server gone, a video ended) raises :class:`CameraError`, which the
vision counts as "pad not seen" and holds the pad modes still for (docs/pilot.md). Capture
times are on the vehicle's clock, the one the airframe's snapshots carry (simulator time, or
the onboard computer's monotonic clock), so the vision's latency handling works unchanged.

- ``sim://HOST:PORT/ROBOT/CAMERA`` (or ``/CAMERA``, the pilot's robot): the simulator's image
  server (:mod:`skeye.pilot.camera_sim`);
- ``v4l2:///dev/video0?width=800&height=600&fps=30``: a camera through OpenCV's V4L2 capture
  (:mod:`skeye.pilot.camera_v4l2`);
- ``file://video.mp4``: a recorded video, played at its frame rate (:mod:`skeye.pilot.camera_file`).

Every source takes ``fov_deg=`` (or ``fov_rad=``) for a detector without a calibration file;
the registry works as the airframes' (:mod:`skeye.pilot.airframe`): one ``"module:function"``
entry per scheme. tests/pilot/test_camera_sources.py is the conformance test every source
passes.
"""

from __future__ import annotations

import importlib
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol, cast, runtime_checkable

import numpy as np

from skeye.errors import LocalProtocolError, SkeyeError
from skeye.uris import query_of, split_uri


class CameraError(SkeyeError):
    """A camera gave no frame (disconnected, unplugged, ended); the message names it."""


@dataclass(frozen=True)
class FrameInfo:
    """A frame's number (from 1, increasing) and capture time (the vehicle's clock, s)."""

    frame: int
    time_s: float


@dataclass(frozen=True)
class CameraImage:
    """One frame: its number, capture time and BGR uint8 pixels (H, W, 3)."""

    frame: int
    time_s: float
    bgr: np.ndarray


@runtime_checkable
class CameraSource(Protocol):
    """A camera the vision reads (see the module docstring)."""

    uri: str
    fov_h_rad: float | None  # from the URI's fov_deg= / fov_rad=, or the simulator; else None

    @property
    def latest(self) -> FrameInfo | None:
        """The newest frame announced (None before the first)."""
        ...

    def image(self) -> CameraImage:
        """The newest frame's pixels.

        Raises:
            CameraError: no frame can be had now (the message says why).
        """
        ...

    @property
    def lost(self) -> str | None:
        """Why the camera gives no frames now (None while it does)."""
        ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class CameraOptions:
    """What the pilot tells every camera source.

    ``clock``: the vehicle's clock (the airframe's time); ``clock_is_sim``: that clock is the
    simulator's (a ``sim://`` camera then passes its frame times through; otherwise it maps
    them); ``robot``: the pilot's robot name (``sim://HOST:PORT/CAMERA``); ``fov_h_rad``: the
    field of view when the pilot knows it (``sim://`` airframe: asked of the simulator);
    ``size_px``: the (width, height) the calibration was made for (a camera giving another
    size is an error, said at its first frame).
    """

    clock: Callable[[], float] = time.monotonic
    clock_is_sim: bool = False
    robot: str = "R1"
    fov_h_rad: float | None = None
    size_px: tuple[int, int] | None = None
    timeout_s: float = 5.0


BACKENDS: dict[str, str] = {
    "sim": "skeye.pilot.camera_sim:open_sim_camera",
    "v4l2": "skeye.pilot.camera_v4l2:open_v4l2_camera",
    "file": "skeye.pilot.camera_file:open_file_camera",
}
"""Scheme -> ``"module:function"`` opening a source of that scheme."""

URI_CHECKS: dict[str, str] = {
    "sim": "skeye.pilot.camera_sim:parse_sim_camera",
    "v4l2": "skeye.pilot.camera_v4l2:parse_v4l2_uri",
    "file": "skeye.pilot.camera_file:check_file_camera",
}
"""Scheme -> ``"module:function"`` parsing a URI of that scheme without opening anything (what
:func:`check_camera_uri` runs, so ``skeye pilot`` refuses a bad ``--camera`` at start; a
``file://`` camera's file is also opened once: missing, a directory, unreadable, empty or no
video is said then)."""


def camera_scheme(uri: str) -> str:
    """The scheme of a camera URI, checked against the registry.

    Raises:
        LocalProtocolError: not a URI, or no source for its scheme.
    """
    scheme, sep, _ = uri.partition("://")
    if not sep or not scheme:
        raise LocalProtocolError(
            f"camera {uri!r}: expected a URI such as sim://127.0.0.1:5003/R1/Down, "
            "v4l2:///dev/video0 or file://video.mp4")
    scheme = scheme.lower()
    if scheme not in BACKENDS:
        raise LocalProtocolError(f"camera {uri!r}: no source for {scheme}:// (known: "
                                 f"{', '.join(s + '://' for s in sorted(BACKENDS))})")
    return scheme


def _entry(table: dict[str, str], scheme: str) -> Callable[..., object]:
    module, _, name = table[scheme].partition(":")
    function: Callable[..., object] = getattr(importlib.import_module(module), name)
    return function


def check_camera_uri(uri: str) -> None:
    """Parse a camera URI, scheme, options and all, without opening the camera.

    Raises:
        LocalProtocolError: naming what is wrong.
        CameraError: a ``file://`` camera's file cannot be played (missing, a directory,
            unreadable, empty, not a video or one cut short).
    """
    _entry(URI_CHECKS, camera_scheme(uri))(uri)


def open_camera(uri: str, options: CameraOptions | None = None) -> CameraSource:
    """Open the camera a URI names.

    Raises:
        LocalProtocolError: a malformed URI or option.
        CameraError: the camera cannot be opened (no such device or file).
    """
    return cast(CameraSource, _entry(BACKENDS, camera_scheme(uri))(uri, options or CameraOptions()))


def needs_fov_option(uri: str) -> bool:
    """Whether a camera URI (already checked) leaves its field of view unknown: a ``v4l2://``
    or ``file://`` camera without ``fov_deg=``/``fov_rad=``, whose frames carry none (a
    ``sim://`` camera's is the simulator's). Without ``--calibration`` the pad detector needs it,
    so ``skeye pilot`` says so before it opens the vehicle."""
    if camera_scheme(uri) == "sim":
        return False
    query = query_of(uri, split_uri(uri, "camera", "SCHEME://..."), "camera")
    return fov_option(uri, query) is None


def fov_option(uri: str, query: Mapping[str, list[str]]) -> float | None:
    """``fov_deg=`` or ``fov_rad=`` of a camera URI, in rad (None when absent).

    Raises:
        LocalProtocolError: both given, or not a field of view in (0, 180) deg.
    """
    if "fov_deg" in query and "fov_rad" in query:
        raise LocalProtocolError(f"camera {uri!r}: give fov_deg= or fov_rad=, not both")
    for key, to_rad in (("fov_deg", math.radians), ("fov_rad", float)):
        if key in query:
            text = query[key][-1]
            try:
                value = to_rad(float(text))
            except ValueError:
                value = math.nan
            if not (math.isfinite(value) and 0 < value < math.pi):
                raise LocalProtocolError(f"camera {uri!r}: {key}={text} is not a field of view "
                                         "between 0 and 180 deg")
            return value
    return None


def check_size(uri: str, expected: tuple[int, int] | None, width: int, height: int) -> None:
    """Raise CameraError when a frame's size is not the calibration's."""
    if expected is not None and (width, height) != expected:
        raise CameraError(
            f"camera {uri}: frames are {width}x{height}, the calibration is for "
            f"{expected[0]}x{expected[1]}: calibrate it at that resolution (or set the "
            "camera's size)")


class _NoReading:
    latest = None


@dataclass
class CameraMount:
    """What the pad vision reads from (``PadVision``'s ``robot``): a camera source, and no
    INS of its own (the vision takes the attitude at each frame from its pose history)."""

    camera: CameraSource
    ins: object = field(default_factory=_NoReading)
