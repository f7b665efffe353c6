"""The image protocol's frames (docs/protocols/images.md): USARSim's UPIS byte for byte, plus META.

How this works (sans-IO: no sockets, no threads, no clock; only the standard library and numpy):

* Server to client, a frame is ``type (1 byte) | size (uint32 BE) | data``. :func:`meta_header`,
  :func:`encode_frame`, :func:`encode_error_frame` and :func:`encode_info_frame` build bytes;
  :class:`FrameDecoder` turns a byte stream back into :data:`FrameEvent` values. Every frame it
  returns has been checked (known type, size within bounds, META header and RAW geometry
  consistent, a finite META sim time, an INFO frame exactly a META header); anything else is a
  single :class:`ProtocolViolation` event, after which the decoder stays failed, because a byte
  stream with a bad length prefix cannot be resynchronised. ``feed`` never raises.
* Client to server requests (``OK``, ``U``, ``SKEYE ...`` lines) are in
  :mod:`skeye.wire.image_requests`; turning pixels into payloads and back (RAW with OpenCV's fast
  channel swap, JPEG, PNG) is in :mod:`skeye.pixels`, which needs OpenCV and so is no part of
  this package.

JPEG quality bands (UPIS types 1-5, "super, good, normal, fair, bad"): quality >= 90 -> 1,
>= 75 -> 2, >= 50 -> 3, >= 25 -> 4, below 25 -> 5. The type only labels the band; the JPEG
itself is encoded at the exact quality asked for.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import Enum, IntEnum
from typing import ClassVar

import numpy as np

from skeye.errors import LocalProtocolError, RemoteProtocolError

DEFAULT_PORT = 5003
FRAME_HEADER_BYTES = 5
META_HEADER_BYTES = 24
RAW_PREFIX_BYTES = 4
DEFAULT_MAX_FRAME_BYTES = 64 * 1024 * 1024
DEFAULT_MAX_LINE_BYTES = 1024
MAX_STREAM_FPS = 1000.0
MAX_RAW_SIDE_PX = 0xFFFF  # width and height travel as uint16 in a RAW frame

_FRAME_HEADER = struct.Struct(">BI")
_META_HEADER = struct.Struct(">IdIII")
RAW_PREFIX = struct.Struct(">HH")  # RAW payloads: uint16 BE width, height
UINT32_MAX = 0xFFFF_FFFF


class FrameType(IntEnum):
    """Base frame types on the wire; META frames add :attr:`META_OFFSET` to an image type (RAW
    to PNG). INFO is the answer to ``SKEYE INFO``: a META header alone, without pixels."""

    RAW = 0
    JPEG_SUPER = 1
    JPEG_GOOD = 2
    JPEG_NORMAL = 3
    JPEG_FAIR = 4
    JPEG_BAD = 5
    PNG = 6
    INFO = 15
    ERROR = 255


META_OFFSET = 16
_IMAGE_TYPES = frozenset(range(FrameType.RAW, FrameType.PNG + 1))
JPEG_TYPES = frozenset(range(FrameType.JPEG_SUPER, FrameType.JPEG_BAD + 1))


class ImageFormat(Enum):
    """What a client asked the image to be encoded as (``SKEYE FORMAT``)."""

    RAW = "RAW"
    JPEG = "JPEG"
    PNG = "PNG"


def jpeg_type_for_quality(quality: int) -> FrameType:
    """The UPIS JPEG frame type (1 best .. 5 worst) for a quality of 1-100 (bands atop module)."""
    check_quality(quality)
    if quality >= 90:
        return FrameType.JPEG_SUPER
    if quality >= 75:
        return FrameType.JPEG_GOOD
    if quality >= 50:
        return FrameType.JPEG_NORMAL
    if quality >= 25:
        return FrameType.JPEG_FAIR
    return FrameType.JPEG_BAD


def check_quality(quality: int) -> None:
    """LocalProtocolError unless ``quality`` is an integer 1-100."""
    if isinstance(quality, bool) or not isinstance(quality, int) or not 1 <= quality <= 100:
        raise LocalProtocolError(f"JPEG quality must be an integer 1-100, got {quality!r}")


# --------------------------------------------------------------------------- frames


@dataclass(frozen=True)
class MetaHeader:
    """The 24-byte header of META frames (types 16+)."""

    frame_number: int
    sim_time_s: float
    camera_id: int
    width: int
    height: int

    SIZE: ClassVar[int] = META_HEADER_BYTES

    def __post_init__(self) -> None:
        for name in ("frame_number", "camera_id", "width", "height"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, int)
                or not (0 <= value <= UINT32_MAX)
            ):
                raise LocalProtocolError(f"MetaHeader.{name} must be a uint32, got {value!r}")

    def pack(self) -> bytes:
        """The header's 24 wire bytes."""
        return _META_HEADER.pack(
            self.frame_number, self.sim_time_s, self.camera_id, self.width, self.height
        )

    @classmethod
    def unpack(cls, data: bytes | memoryview) -> MetaHeader:
        """Read a header from the first 24 bytes of ``data``."""
        if len(data) < META_HEADER_BYTES:
            raise RemoteProtocolError(f"META header needs 24 bytes, got {len(data)}")
        return cls(*_META_HEADER.unpack_from(data))


def meta_header(
    frame_number: int, sim_time_s: float, camera_id: int, width: int, height: int
) -> bytes:
    """The 24-byte META header (uint32 number, float64 sim time, uint32 id, width, height)."""
    return MetaHeader(frame_number, sim_time_s, camera_id, width, height).pack()


def raw_row_bytes(width_px: int) -> int:
    """Bytes per RAW row: 3 per pixel, padded to a multiple of 4."""
    return (3 * width_px + 3) // 4 * 4


def decode_raw(data: bytes | memoryview) -> np.ndarray:
    """A RAW payload back to an (H, W, 3) BGR array, padding removed."""
    if len(data) < RAW_PREFIX_BYTES:
        raise RemoteProtocolError(f"RAW payload shorter than its 4-byte prefix ({len(data)} B)")
    width, height = RAW_PREFIX.unpack_from(data)
    row = raw_row_bytes(width)
    expected = RAW_PREFIX_BYTES + row * height
    if len(data) != expected:
        raise RemoteProtocolError(
            f"RAW {width}x{height} needs {expected} bytes, frame has {len(data)}"
        )
    rows = np.frombuffer(data, dtype=np.uint8, offset=RAW_PREFIX_BYTES).reshape(height, row)
    return rows[:, : 3 * width].reshape(height, width, 3).copy()


def is_valid_frame_type(frame_type: int) -> bool:
    """Whether a type byte names a frame this protocol defines."""
    return (
        frame_type in (FrameType.ERROR, FrameType.INFO)
        or frame_type in _IMAGE_TYPES
        or frame_type - META_OFFSET in _IMAGE_TYPES
    )


def frame_header(frame_type: int, size: int) -> bytes:
    """The 5-byte frame header (type, uint32 BE size)."""
    if isinstance(frame_type, bool) or not isinstance(frame_type, int):
        raise LocalProtocolError(f"frame type must be an int, got {frame_type!r}")
    if not is_valid_frame_type(frame_type):
        raise LocalProtocolError(f"unknown frame type {frame_type}")
    if not 0 <= size <= UINT32_MAX:
        raise LocalProtocolError(f"frame payload of {size} bytes does not fit a uint32 size")
    return _FRAME_HEADER.pack(frame_type, size)


def encode_frame(frame_type: int, payload: bytes) -> bytes:
    """A whole frame: type byte, uint32 BE size, payload."""
    return frame_header(frame_type, len(payload)) + payload


def encode_error_frame(reason: str) -> bytes:
    """An error frame (type 255) carrying ``reason`` in UTF-8."""
    return encode_frame(FrameType.ERROR, reason.encode("utf-8"))


def encode_info_frame(meta: MetaHeader) -> bytes:
    """An INFO frame (type 15, the answer to ``SKEYE INFO``): the META header alone."""
    return encode_frame(FrameType.INFO, meta.pack())


# --------------------------------------------------------------------------- decoding


@dataclass(frozen=True)
class DecodedFrame:
    """One image frame as received; ``frame_type`` is the base type (META offset removed)."""

    frame_type: FrameType
    meta: MetaHeader | None
    data: bytes

    @property
    def wire_type(self) -> int:
        """The type byte as it was on the wire."""
        return self.frame_type + (META_OFFSET if self.meta is not None else 0)

@dataclass(frozen=True)
class InfoFrame:
    """An INFO frame (type 15): the newest frame's META header, without its pixels."""

    meta: MetaHeader


@dataclass(frozen=True)
class RemoteError:
    """An error frame (type 255): the server refused a request, saying why."""

    reason: str


@dataclass(frozen=True)
class ProtocolViolation:
    """The byte stream broke the protocol; the decoder has stopped."""

    reason: str


FrameEvent = DecodedFrame | InfoFrame | RemoteError | ProtocolViolation


class FrameDecoder:
    """Bytes from the server in, :data:`FrameEvent` values out; never raises from ``feed``."""

    def __init__(self, max_frame_bytes: int = DEFAULT_MAX_FRAME_BYTES) -> None:
        self._max_frame_bytes = max_frame_bytes
        self._buf = bytearray()
        self._failure: str | None = None

    @property
    def failure(self) -> str | None:
        """Why the decoder stopped, or None while it is healthy."""
        return self._failure

    def feed(self, data: bytes) -> list[FrameEvent]:
        """Add bytes; return the frames, error frames or protocol violation they complete."""
        if self._failure is not None:
            return []
        self._buf += data
        out: list[FrameEvent] = []
        buf = self._buf
        pos = 0
        while len(buf) - pos >= FRAME_HEADER_BYTES:
            frame_type, size = _FRAME_HEADER.unpack_from(buf, pos)
            problem = self._check_header(frame_type, size)
            if problem is not None:
                out.append(self._fail(problem))
                return out
            end = pos + FRAME_HEADER_BYTES + size
            if len(buf) < end:
                break
            with memoryview(buf) as view:
                payload = bytes(view[pos + FRAME_HEADER_BYTES : end])
            pos = end
            event = _frame_event(frame_type, payload)
            if isinstance(event, ProtocolViolation):
                out.append(self._fail(event.reason))
                return out
            out.append(event)
        del buf[:pos]
        return out

    def _check_header(self, frame_type: int, size: int) -> str | None:
        if not is_valid_frame_type(frame_type):
            if 0x41 <= frame_type <= 0x5A:  # "NFO {...": an uppercase word of a text protocol
                return (f"unknown frame type {frame_type} ({chr(frame_type)!r}: text, as the "
                        "simulator's control port sends; the image server has a port of its "
                        "own, skeye sim --image-port, 5003 by default)")
            return f"unknown frame type {frame_type}"
        if size > self._max_frame_bytes:
            return f"frame of {size} bytes exceeds the {self._max_frame_bytes}-byte limit"
        return None

    def _fail(self, reason: str) -> ProtocolViolation:
        self._failure = reason
        self._buf.clear()
        return ProtocolViolation(reason)


def _frame_event(frame_type: int, payload: bytes) -> FrameEvent:
    if frame_type == FrameType.ERROR:
        return RemoteError(payload.decode("utf-8", errors="replace"))
    if frame_type == FrameType.INFO:
        if len(payload) != META_HEADER_BYTES:
            return ProtocolViolation(
                f"INFO frame of {len(payload)} bytes is not a 24-byte META header"
            )
        info = MetaHeader(*_META_HEADER.unpack_from(payload))
        if not math.isfinite(info.sim_time_s):
            return ProtocolViolation(f"INFO frame's sim time is {info.sim_time_s!r}")
        return InfoFrame(info)
    meta: MetaHeader | None = None
    if frame_type >= META_OFFSET:
        if len(payload) < META_HEADER_BYTES:
            return ProtocolViolation(
                f"META frame of {len(payload)} bytes is shorter than its 24-byte header"
            )
        meta = MetaHeader(*_META_HEADER.unpack_from(payload))
        if not math.isfinite(meta.sim_time_s):  # a frame shows a moment: never NaN or inf
            return ProtocolViolation(f"META header's sim time is {meta.sim_time_s!r}")
        payload = payload[META_HEADER_BYTES:]
        frame_type -= META_OFFSET
    base = FrameType(frame_type)
    if base is FrameType.RAW:
        problem = _check_raw(payload, meta)
        if problem is not None:
            return ProtocolViolation(problem)
    return DecodedFrame(base, meta, payload)


def _check_raw(payload: bytes, meta: MetaHeader | None) -> str | None:
    if len(payload) < RAW_PREFIX_BYTES:
        return f"RAW payload of {len(payload)} bytes is shorter than its 4-byte prefix"
    width, height = RAW_PREFIX.unpack_from(payload)
    expected = RAW_PREFIX_BYTES + raw_row_bytes(width) * height
    if len(payload) != expected:
        return f"RAW {width}x{height} needs {expected} bytes, frame has {len(payload)}"
    if meta is not None and (meta.width, meta.height) != (width, height):
        return f"RAW is {width}x{height} but META says {meta.width}x{meta.height}"
    return None
