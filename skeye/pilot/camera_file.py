"""``file://video.mp4``: a recorded video as the pilot's camera, played at its frame rate.

How this works: OpenCV reads the file (its FFmpeg backend: MP4, MKV, AVI...). The video is
paced on the vehicle's clock: the first ``latest`` starts it, and frame k (from 0) is due
``k / fps`` seconds later, its capture time that instant, so in lockstep a video plays in sim
time and a run stays reproducible. ``image()`` decodes up to the due frame (frames the vision
had no time for are skipped, as a live camera's would be). At the end the camera is reported
ended (``lost``; the pad modes hold still), unless ``loop=1`` starts it again: the file is
opened again (a seek to frame 0 is ignored by OpenCV's reader of a photo), and whole passes
the vision had no time for are skipped without decoding them.

URI: ``file://video.mp4`` (relative to the working directory), ``file:///abs/video.mkv``
(``%`` escapes as in any URI: ``flight%233.mkv`` for ``flight#3.mkv``; a ``#`` is refused, not
taken as a fragment that cuts the name short);
options ``fps=`` (when the file's own rate is missing or wrong), ``loop=1``, ``fov_deg=`` /
``fov_rad=``. A lossless recording (FFV1 in MKV or AVI) gives the detector the very pixels
that were recorded; a lossy one (MP4) close ones. A photo (JPEG, PNG) plays as a one-frame
video; one cut short is refused when the camera opens (:mod:`skeye.image_files`), and so is a
file the pilot may not read (named with the system's reason: OpenCV would only warn that it
cannot open it) and a video whose first frame does not decode (an MP4 whose last bytes, its
index, never arrived opens with a size, a rate and a frame count, and gives no frame). A photo
of more pixels than FFmpeg decodes is refused naming the size its header declares.
"""

from __future__ import annotations

import math
import os
import threading
from pathlib import Path
from urllib.parse import unquote

import cv2
import numpy as np

from skeye.errors import LocalProtocolError
from skeye.image_files import PNG_SIGNATURE, file_damage
from skeye.pilot.camera import (
    CameraError,
    CameraImage,
    CameraOptions,
    FrameInfo,
    check_size,
    fov_option,
)
from skeye.pixels import declared_size
from skeye.uris import query_of, split_uri
from skeye.wire.images import FrameType


def parse_file_camera(uri: str) -> tuple[Path, float | None, bool, float | None]:
    """(path, fps or None, loop, fov or None) of a ``file://`` camera URI.

    Raises:
        LocalProtocolError: naming what is wrong.
    """
    parts = split_uri(uri, "camera", "file://PATH")
    if parts.scheme.lower() != "file":
        raise LocalProtocolError(f"camera {uri!r}: expected file://PATH")
    if "#" in uri:  # urlsplit would cut the name there and drop the rest without a word
        raise LocalProtocolError(f"camera {uri!r}: '#' starts a URI fragment, which a file "
                                 "camera has none of: write a '#' in a file's name as %23")
    # file:///abs and file://localhost/abs (RFC 8089: the local host) are absolute paths;
    # file://name.mp4 and file://dir/name.mp4 are relative ones
    netloc = "" if parts.netloc.lower() == "localhost" and parts.path else parts.netloc
    path = unquote(netloc + parts.path)
    if not path:
        raise LocalProtocolError(f"camera {uri!r}: expected file://PATH (a video file)")
    if any(ord(c) < 0x20 or c == "\x7f" for c in path):  # frames/%04d.png: %04 is \x04
        raise LocalProtocolError(f"camera {uri!r}: the name decodes to {path!r}, with a control "
                                 "character: '%' starts an escape in a URI, write a '%' in a "
                                 "file's name as %25")
    query = query_of(uri, parts, "camera")
    unknown = sorted(set(query) - {"fps", "loop", "fov_deg", "fov_rad"})
    if unknown:
        raise LocalProtocolError(f"camera {uri!r}: unknown option(s) {unknown} (fps, loop, "
                                 "fov_deg, fov_rad)")
    fps = None
    if "fps" in query:
        try:
            fps = float(query["fps"][-1])
        except ValueError:
            fps = math.nan
        if not (math.isfinite(fps) and 0 < fps <= 1000):
            raise LocalProtocolError(f"camera {uri!r}: fps={query['fps'][-1]} is not 0..1000")
    loop_text = query.get("loop", ["0"])[-1]
    if loop_text not in ("0", "1"):
        raise LocalProtocolError(f"camera {uri!r}: loop={loop_text} is not 0 or 1")
    return Path(path), fps, loop_text == "1", fov_option(uri, query)


def check_file_camera(uri: str) -> None:
    """Parse a ``file://`` camera URI and open its file once, as the camera will: everything
    :class:`FileCamera` refuses (missing, a directory, unreadable, empty, not a video, a photo
    cut short, no frame rate, a first frame that does not decode) is said when ``skeye pilot``
    starts, before it opens the vehicle. Until 2026-11-28 only what the file system tells was
    said so: a text file named ``.mp4`` was found out after the LL board was connected, and a
    vehicle that did not answer hid it. A FIFO or a device is only looked at, as before: read
    once here, a FIFO's video would be gone (its writer ended), and the camera then waited for
    another writer forever; with none yet, this check waited.

    Raises:
        LocalProtocolError: a bad URI; CameraError: a file that cannot be played.
    """
    path, fps, loop, fov = parse_file_camera(uri)
    _refuse_unplayable(uri, path)
    if not path.is_file():  # a FIFO or a device: what it gives is read once, by the camera
        return
    FileCamera(uri, path, CameraOptions(), fps=fps, loop=loop, fov_h_rad=fov).close()


def _refuse_unplayable(uri: str, path: Path) -> None:
    """CameraError when the file system tells ``path`` cannot be played (:func:`_unplayable`)."""
    problem = _unplayable(path)
    if problem is not None:
        raise CameraError(f"camera {uri}: cannot open {path} as a video ({problem})")


def _unplayable(path: Path) -> str | None:
    """Why ``path`` cannot be played as far as the file system tells, else None."""
    try:
        if path.is_dir():
            return "a directory"
        if not path.exists():
            return "no such file"
        if path.is_file():  # not a FIFO or a device: opening one may block
            with open(path, "rb") as f:  # unreadable: OpenCV would warn, and say no more
                if f.seek(0, 2) == 0:
                    return "an empty file"
    except OSError as exc:
        return exc.strerror or str(exc)
    return None


def _why_not(path: Path) -> str:
    """Why OpenCV could not open ``path`` as a video, as far as the file system tells."""
    return _unplayable(path) or "not a video, or one cut short or damaged"


FFMPEG_MAX_PIXELS = 1 << 28
"""FFmpeg decodes a picture only if ``(width + 128) * (height + 128)`` is under this
(libavutil's ``av_image_check_size2``: 8 bytes a pixel, padded, under 2 GiB)."""


def _too_large(path: Path) -> str | None:
    """Why OpenCV's video reader gave a photo (a PNG or JPEG) no frame size, when its header
    declares more pixels than FFmpeg decodes; None otherwise."""
    try:
        with open(path, "rb") as f:
            head = f.read(1 << 20)  # the JPEG frame header follows its EXIF: within 1 MiB
    except OSError:
        return None
    kind = FrameType.PNG if head.startswith(PNG_SIGNATURE) else FrameType.JPEG_SUPER
    size = declared_size(kind, head)
    if size is None or (size[0] + 128) * (size[1] + 128) < FFMPEG_MAX_PIXELS:
        return None
    return (f"its header declares {size[0]}x{size[1]} px, more than FFmpeg decodes (about "
            f"{FFMPEG_MAX_PIXELS / 1e6:.0f} million): give a smaller copy")


FFMPEG_LOG_LEVEL = "8"
"""AV_LOG_FATAL: FFmpeg's own messages about a file it cannot read ("moov atom not found",
"Invalid PNG signature") are not printed (OpenCV reads ``OPENCV_FFMPEG_LOGLEVEL`` when its
FFmpeg reader first opens a file); the camera's refusal says what is wrong in one line. A
``OPENCV_FFMPEG_LOGLEVEL`` already set (32: FFmpeg's errors and warnings) is kept."""


def _video_capture(path: Path) -> cv2.VideoCapture:
    """OpenCV's reader of ``path``, FFmpeg's own log quiet unless the environment asks for it."""
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", FFMPEG_LOG_LEVEL)
    return cv2.VideoCapture(str(path))


class FileCamera:
    """A video file, paced at its frame rate on the vehicle's clock."""

    def __init__(self, uri: str, path: Path, options: CameraOptions, *, fps: float | None = None,
                 loop: bool = False, fov_h_rad: float | None = None) -> None:
        self.uri = uri
        self.path = path
        self.options = options
        self.loop = loop
        self.fov_h_rad = fov_h_rad if fov_h_rad is not None else options.fov_h_rad
        _refuse_unplayable(uri, path)
        try:  # a photo plays as a one-frame video; OpenCV would half decode a cut-off one
            problem = file_damage(path)
        except OSError:
            problem = None  # VideoCapture says what is wrong with the file
        if problem is not None:
            raise CameraError(f"camera {uri}: {path} is truncated or corrupt: {problem}")
        self._cap = _video_capture(path)
        if not self._cap.isOpened():
            raise CameraError(f"camera {uri}: cannot open {path} as a video ({_why_not(path)})")
        file_fps = self._cap.get(cv2.CAP_PROP_FPS)
        self.fps = fps or (file_fps if file_fps and math.isfinite(file_fps) else 0.0)
        if not self.fps > 0:
            self._cap.release()
            raise CameraError(f"camera {uri}: the file gives no frame rate: add ?fps=")
        count = self._cap.get(cv2.CAP_PROP_FRAME_COUNT)
        self.frame_count = int(count) if count and count > 0 else None
        self.width_px = int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        self.height_px = int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        if self.width_px <= 0 or self.height_px <= 0:  # OpenCV "opened" it, but has no frames
            self._cap.release()
            raise CameraError(f"camera {uri}: cannot open {path} as a video "
                              f"({_too_large(path) or 'not a video: no frame size'})")
        check_size(uri, options.size_px, self.width_px, self.height_px)
        ok, first = self._cap.read()  # a file cut short opens with a size and a rate, and
        if not ok or first is None:  # gives no frame: refused now, not "ended" once flying
            self._cap.release()
            raise CameraError(f"camera {uri}: cannot open {path} as a video (no frame decodes: "
                              "cut short or damaged)")
        self._lock = threading.Lock()
        self._start_s: float | None = None
        self._decoded = 1  # frames read from the file so far (this pass): the first, above
        self._pass = 0  # times the video started over (loop)
        self._ended = False
        self._loop_failed = ""
        self._frame: np.ndarray | None = first

    def _due(self) -> int:
        """How many frames are due by now (1 = the first)."""
        now = self.options.clock()
        if self._start_s is None:
            self._start_s = now
        return math.floor((now - self._start_s) * self.fps + 1e-9) + 1

    @property
    def latest(self) -> FrameInfo | None:
        if self._ended:  # nothing new will come
            return None if self._frame is None else self._info(self._decoded)
        return self._info(self._due())  # past the end: image() then says it ended

    def _info(self, number: int) -> FrameInfo:
        assert self._start_s is not None
        return FrameInfo(number, self._start_s + (number - 1) / self.fps)

    def image(self) -> CameraImage:
        with self._lock:
            if self._ended:
                raise CameraError(self.lost or f"camera {self.uri}: ended")
            due = self._due() - self._pass * (self.frame_count or 0)
            frame = self._frame
            while self._decoded < due:
                ok = self._cap.grab()
                if not ok:
                    if self.loop and self._decoded > 0:
                        count = self.frame_count = self._decoded
                        laps = (due - 1) // count  # whole passes due, the frames of the last
                        self._pass += laps  # ones skipped without decoding them
                        due -= laps * count
                        self._decoded = 0
                        self._reopen()
                        continue
                    self._ended = True
                    raise CameraError(self.lost or f"camera {self.uri}: ended")
                self._decoded += 1
                if self._decoded == due:
                    ok, frame = self._cap.retrieve()
                    if not ok:
                        raise CameraError(f"camera {self.uri}: frame {self._decoded} does not "
                                          "decode")
                    self._frame = frame
            if frame is None:
                raise CameraError(f"camera {self.uri}: no frame yet")
            number = self._decoded + self._pass * (self.frame_count or 0)
            info = self._info(number)
            return CameraImage(info.frame, info.time_s, frame)

    def _reopen(self) -> None:
        """Open the file again, at its first frame (a loop). Not a seek to frame 0: OpenCV's
        reader of a single image (a photo) ignores that, and its next read fails."""
        self._cap.release()
        self._cap = _video_capture(self.path)
        if not self._cap.isOpened():
            self._ended = True
            self._loop_failed = f"cannot open {self.path} again to loop it ({_why_not(self.path)})"
            raise CameraError(self.lost or f"camera {self.uri}: ended")

    @property
    def lost(self) -> str | None:
        if self._loop_failed:
            return f"camera {self.uri}: {self._loop_failed}"
        if self._ended:
            n = self._decoded
            return f"camera {self.uri}: the video ended after {n} frame{'' if n == 1 else 's'}"
        return None

    def close(self) -> None:
        with self._lock:
            self._cap.release()


def open_file_camera(uri: str, options: CameraOptions) -> FileCamera:
    """The ``file://`` camera source.

    Raises:
        LocalProtocolError: a bad URI; CameraError: the file cannot be read as a video.
    """
    path, fps, loop, fov = parse_file_camera(uri)
    return FileCamera(uri, path, options, fps=fps, loop=loop, fov_h_rad=fov)
