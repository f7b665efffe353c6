"""The image protocol (docs/protocols/images.md): USARSim's UPIS byte for byte, plus extensions.

How this works (sans-IO: no sockets, no threads, no clock):

* Client to server, :class:`RequestParser` turns a byte stream into :data:`Request` values.
  It scans for three openings: ``OK`` (2 bytes), ``U`` + 16 bytes (four uint32 big-endian) and
  ``SKEYE `` up to ``\\n``. Any other byte forms no request and is dropped, as UPIS does. An
  extension line that cannot be parsed, or one longer than ``max_line_bytes``, becomes a
  :class:`RequestError` (the server answers it with an error frame); an over-long line is then
  discarded up to its newline. Invariants: the parser holds at most ``max_line_bytes`` bytes, and
  the requests it returns do not depend on how the stream was split into ``feed`` calls.
  :func:`encode_request` is its inverse (used by the client), and ``feed(encode_request(r))``
  gives back ``[r]`` for every valid request.
* Server to client, a frame is ``type (1 byte) | size (uint32 BE) | data``. The payload builders
  (:func:`raw_payload`, :func:`jpeg_payload`, :func:`png_payload`, :func:`meta_header`) and
  :func:`encode_frame` / :func:`encode_error_frame` build bytes; :class:`FrameDecoder` turns a
  byte stream back into :data:`FrameEvent` values. Every frame it returns has been checked
  (known type, size within bounds, META header and RAW geometry consistent); anything else is a
  single :class:`ProtocolViolation` event, after which the decoder stays failed, because a byte
  stream with a bad length prefix cannot be resynchronised. ``feed`` never raises.

JPEG quality bands (UPIS types 1-5, "super, good, normal, fair, bad"): quality >= 90 -> 1,
>= 75 -> 2, >= 50 -> 3, >= 25 -> 4, below 25 -> 5. The type only labels the band; the JPEG
itself is encoded at the exact quality asked for.
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass
from enum import Enum, IntEnum
from typing import ClassVar

import cv2
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
_RAW_PREFIX = struct.Struct(">HH")
_SUBRECT = struct.Struct(">IIII")
_UINT32_MAX = 0xFFFF_FFFF


class FrameType(IntEnum):
    """Base frame types on the wire; META frames add :attr:`META_OFFSET` to a base type."""

    RAW = 0
    JPEG_SUPER = 1
    JPEG_GOOD = 2
    JPEG_NORMAL = 3
    JPEG_FAIR = 4
    JPEG_BAD = 5
    PNG = 6
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
    _check_quality(quality)
    if quality >= 90:
        return FrameType.JPEG_SUPER
    if quality >= 75:
        return FrameType.JPEG_GOOD
    if quality >= 50:
        return FrameType.JPEG_NORMAL
    if quality >= 25:
        return FrameType.JPEG_FAIR
    return FrameType.JPEG_BAD


def _check_quality(quality: int) -> None:
    if isinstance(quality, bool) or not isinstance(quality, int) or not 1 <= quality <= 100:
        raise LocalProtocolError(f"JPEG quality must be an integer 1-100, got {quality!r}")


# --------------------------------------------------------------------------- requests


@dataclass(frozen=True)
class NewestFrame:
    """``OK``: send the newest frame of this connection's camera."""


@dataclass(frozen=True)
class SubRect:
    """``U`` + x, y, width, height (uint32 each): a sub-rectangle of the newest frame, px."""

    x: int
    y: int
    width: int
    height: int

    def __post_init__(self) -> None:
        for name in ("x", "y", "width", "height"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, int)
                or not (0 <= value <= _UINT32_MAX)
            ):
                raise LocalProtocolError(f"SubRect.{name} must be a uint32, got {value!r}")


_CAMERA_NAME = re.compile(r"[!-~]{1,200}")  # printable ASCII, no spaces


@dataclass(frozen=True)
class SelectCamera:
    """``SKEYE CAMERA <robot>/<camera>``."""

    name: str

    def __post_init__(self) -> None:
        if not _CAMERA_NAME.fullmatch(self.name):
            raise LocalProtocolError(
                f"camera name must be 1-200 printable ASCII characters without spaces, "
                f"got {self.name!r}"
            )


@dataclass(frozen=True)
class SetFormat:
    """``SKEYE FORMAT RAW|JPEG <q>|PNG``; ``quality`` is set for JPEG only."""

    kind: ImageFormat
    quality: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.kind, ImageFormat):
            raise LocalProtocolError(f"format must be an ImageFormat, got {self.kind!r}")
        if self.kind is ImageFormat.JPEG:
            if self.quality is None:
                raise LocalProtocolError("JPEG format needs a quality 1-100")
            _check_quality(self.quality)
        elif self.quality is not None:
            raise LocalProtocolError(f"{self.kind.value} format takes no quality")


@dataclass(frozen=True)
class SetMeta:
    """``SKEYE META on|off``."""

    on: bool


@dataclass(frozen=True)
class Stream:
    """``SKEYE STREAM <fps>``: push frames at up to ``fps``; 0 stops."""

    fps: float

    def __post_init__(self) -> None:
        if (
            isinstance(self.fps, bool)
            or not isinstance(self.fps, int | float)
            or not math.isfinite(self.fps)
            or not 0.0 <= self.fps <= MAX_STREAM_FPS
        ):
            raise LocalProtocolError(
                f"stream rate must be 0-{MAX_STREAM_FPS:g} frames/s, got {self.fps!r}"
            )


@dataclass(frozen=True)
class RequestError:
    """An extension line that could not be parsed; the server answers with an error frame."""

    reason: str


Request = NewestFrame | SubRect | SelectCamera | SetFormat | SetMeta | Stream | RequestError

_EXT_PREFIX = b"SKEYE "
_OPENINGS = re.compile(rb"[OUS]")


def encode_request(request: Request) -> bytes:
    """The wire bytes of one request (the client side of :class:`RequestParser`)."""
    match request:
        case NewestFrame():
            return b"OK"
        case SubRect(x=x, y=y, width=w, height=h):
            return b"U" + _SUBRECT.pack(x, y, w, h)
        case SelectCamera(name=name):
            return _EXT_PREFIX + b"CAMERA " + name.encode("ascii") + b"\n"
        case SetFormat(kind=kind, quality=quality):
            tail = f" {quality}" if kind is ImageFormat.JPEG else ""
            return _EXT_PREFIX + f"FORMAT {kind.value}{tail}".encode("ascii") + b"\n"
        case SetMeta(on=on):
            return _EXT_PREFIX + (b"META on\n" if on else b"META off\n")
        case Stream(fps=fps):
            return _EXT_PREFIX + f"STREAM {float(fps)!r}".encode("ascii") + b"\n"
        case RequestError():
            raise LocalProtocolError("a RequestError is the parser's verdict, not a request")
    raise LocalProtocolError(f"not an image protocol request: {request!r}")


def parse_extension(line: bytes) -> Request:
    """Parse one extension line, without ``SKEYE `` and the newline; never raises."""
    try:
        text = line.decode("ascii")
    except UnicodeDecodeError:
        return RequestError("extension line is not ASCII")
    words = text.split()
    if not words:
        return RequestError("empty SKEYE command")
    command, args = words[0].upper(), words[1:]
    shown = text.strip()[:80]
    try:
        if command == "CAMERA":
            if len(args) != 1:
                return RequestError(f"expected 'CAMERA <robot>/<camera>', got {shown!r}")
            return SelectCamera(args[0])
        if command == "FORMAT":
            return _parse_format(args, shown)
        if command == "META":
            if len(args) != 1 or args[0].lower() not in ("on", "off"):
                return RequestError(f"expected 'META on|off', got {shown!r}")
            return SetMeta(args[0].lower() == "on")
        if command == "STREAM":
            if len(args) != 1:
                return RequestError(f"expected 'STREAM <fps>', got {shown!r}")
            try:
                fps = float(args[0])
            except ValueError:
                return RequestError(f"stream rate is not a number: {args[0][:40]!r}")
            return Stream(fps)
    except LocalProtocolError as exc:
        return RequestError(str(exc))
    return RequestError(f"unknown SKEYE command {words[0][:40]!r}")


def _parse_format(args: list[str], shown: str) -> Request:
    kind = args[0].upper() if args else ""
    if kind == "RAW" and len(args) == 1:
        return SetFormat(ImageFormat.RAW)
    if kind == "PNG" and len(args) == 1:
        return SetFormat(ImageFormat.PNG)
    if kind == "JPEG" and len(args) == 2:
        if not args[1].isdigit():
            return RequestError(f"JPEG quality must be an integer 1-100, got {args[1][:20]!r}")
        return SetFormat(ImageFormat.JPEG, int(args[1]))
    return RequestError(f"expected 'FORMAT RAW|JPEG <1-100>|PNG', got {shown!r}")


class RequestParser:
    """Bytes from a client in, requests out (see the module comment for the rules)."""

    def __init__(self, max_line_bytes: int = DEFAULT_MAX_LINE_BYTES) -> None:
        if max_line_bytes < len(_EXT_PREFIX) + 1:
            raise LocalProtocolError(f"max_line_bytes too small: {max_line_bytes}")
        self._max_line_bytes = max_line_bytes
        self._buf = bytearray()
        self._discarding = False  # inside an over-long line, dropping bytes up to its newline

    @property
    def buffered_bytes(self) -> int:
        """Bytes held back waiting for the rest of a request."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[Request]:
        """Add bytes from the stream; return the requests they complete, in order."""
        self._buf += data
        out: list[Request] = []
        buf = self._buf
        pos = 0
        while pos < len(buf):
            if self._discarding:
                newline = buf.find(b"\n", pos)
                if newline < 0:
                    pos = len(buf)
                    break
                pos = newline + 1
                self._discarding = False
                continue
            match = _OPENINGS.search(buf, pos)
            if match is None:
                pos = len(buf)
                break
            pos = match.start()
            opening = buf[pos]
            if opening == ord("O"):
                if pos + 1 >= len(buf):
                    break  # wait for the byte after 'O'
                if buf[pos + 1] == ord("K"):
                    out.append(NewestFrame())
                    pos += 2
                else:
                    pos += 1
            elif opening == ord("U"):
                if len(buf) - pos < 1 + _SUBRECT.size:
                    break
                x, y, w, h = _SUBRECT.unpack_from(buf, pos + 1)
                out.append(SubRect(x, y, w, h))
                pos += 1 + _SUBRECT.size
            else:  # 'S': maybe "SKEYE "
                head = bytes(buf[pos : pos + len(_EXT_PREFIX)])
                if not _EXT_PREFIX.startswith(head):
                    pos += 1
                    continue
                if len(head) < len(_EXT_PREFIX):
                    break  # a prefix of "SKEYE ", wait for more
                newline = buf.find(b"\n", pos, pos + self._max_line_bytes)
                if newline < 0:
                    if len(buf) - pos >= self._max_line_bytes:
                        out.append(
                            RequestError(f"request line longer than {self._max_line_bytes} bytes")
                        )
                        pos += self._max_line_bytes
                        self._discarding = True
                        continue
                    break  # wait for the newline
                line = bytes(buf[pos + len(_EXT_PREFIX) : newline]).rstrip(b"\r")
                out.append(parse_extension(line))
                pos = newline + 1
        del buf[:pos]
        return out


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
                or not (0 <= value <= _UINT32_MAX)
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


def _check_rgb(rgb: np.ndarray) -> None:
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8:
        raise LocalProtocolError("image must be a uint8 numpy array")
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] == 0 or rgb.shape[1] == 0:
        raise LocalProtocolError(f"image must have shape (H, W, 3) with H, W > 0, got {rgb.shape}")


def raw_row_bytes(width_px: int) -> int:
    """Bytes per RAW row: 3 per pixel, padded to a multiple of 4."""
    return (3 * width_px + 3) // 4 * 4


def raw_payload(rgb: np.ndarray) -> bytes:
    """UPIS raw: uint16 BE width, height, then B, G, R rows top to bottom padded to 4 bytes."""
    _check_rgb(rgb)
    height, width = rgb.shape[:2]
    if width > MAX_RAW_SIDE_PX or height > MAX_RAW_SIDE_PX:
        raise LocalProtocolError(f"RAW frames are at most 65535 px a side, got {width}x{height}")
    row = raw_row_bytes(width)
    out = np.empty(RAW_PREFIX_BYTES + row * height, dtype=np.uint8)
    out[:RAW_PREFIX_BYTES] = np.frombuffer(_RAW_PREFIX.pack(width, height), dtype=np.uint8)
    rows = out[RAW_PREFIX_BYTES:].reshape(height, row)
    if row == 3 * width:
        # cv2 swaps channels straight into the output, several times faster than numpy's
        # reversed-stride copy; it needs a C-contiguous source.
        cv2.cvtColor(
            np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR, dst=rows.reshape(height, width, 3)
        )
    else:
        rows[:, 3 * width :] = 0
        rows[:, : 3 * width].reshape(height, width, 3)[...] = rgb[:, :, ::-1]
    return out.tobytes()


def decode_raw(data: bytes | memoryview) -> np.ndarray:
    """A RAW payload back to an (H, W, 3) BGR array, padding removed."""
    if len(data) < RAW_PREFIX_BYTES:
        raise RemoteProtocolError(f"RAW payload shorter than its 4-byte prefix ({len(data)} B)")
    width, height = _RAW_PREFIX.unpack_from(data)
    row = raw_row_bytes(width)
    expected = RAW_PREFIX_BYTES + row * height
    if len(data) != expected:
        raise RemoteProtocolError(
            f"RAW {width}x{height} needs {expected} bytes, frame has {len(data)}"
        )
    rows = np.frombuffer(data, dtype=np.uint8, offset=RAW_PREFIX_BYTES).reshape(height, row)
    return rows[:, : 3 * width].reshape(height, width, 3).copy()


def jpeg_payload(rgb: np.ndarray, quality: int) -> bytes:
    """A JPEG file of ``rgb`` at ``quality`` (1-100)."""
    _check_rgb(rgb)
    _check_quality(quality)
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise LocalProtocolError(f"JPEG encoding failed for a {rgb.shape} image")
    return buf.tobytes()


# zlib level 1 with the "up" row filter: about twice as fast as OpenCV's default adaptive filter
# on rendered images, for a similar size. Lossless either way.
_PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 1]
if hasattr(cv2, "IMWRITE_PNG_FILTER"):
    _PNG_PARAMS += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_UP]


def png_payload(rgb: np.ndarray) -> bytes:
    """A PNG file of ``rgb`` (lossless)."""
    _check_rgb(rgb)
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", bgr, _PNG_PARAMS)
    if not ok:
        raise LocalProtocolError(f"PNG encoding failed for a {rgb.shape} image")
    return buf.tobytes()


def encode_image(
    rgb: np.ndarray, kind: ImageFormat, quality: int | None
) -> tuple[FrameType, bytes]:
    """The base frame type and payload of ``rgb`` in a format (quality for JPEG only)."""
    if kind is ImageFormat.RAW:
        return FrameType.RAW, raw_payload(rgb)
    if kind is ImageFormat.PNG:
        return FrameType.PNG, png_payload(rgb)
    if kind is ImageFormat.JPEG:
        if quality is None:
            raise LocalProtocolError("JPEG needs a quality 1-100")
        return jpeg_type_for_quality(quality), jpeg_payload(rgb, quality)
    raise LocalProtocolError(f"unknown image format {kind!r}")


def is_valid_frame_type(frame_type: int) -> bool:
    """Whether a type byte names a frame this protocol defines."""
    return (
        frame_type == FrameType.ERROR
        or frame_type in _IMAGE_TYPES
        or frame_type - META_OFFSET in _IMAGE_TYPES
    )


def frame_header(frame_type: int, size: int) -> bytes:
    """The 5-byte frame header (type, uint32 BE size)."""
    if isinstance(frame_type, bool) or not isinstance(frame_type, int):
        raise LocalProtocolError(f"frame type must be an int, got {frame_type!r}")
    if not is_valid_frame_type(frame_type):
        raise LocalProtocolError(f"unknown frame type {frame_type}")
    if not 0 <= size <= _UINT32_MAX:
        raise LocalProtocolError(f"frame payload of {size} bytes does not fit a uint32 size")
    return _FRAME_HEADER.pack(frame_type, size)


def encode_frame(frame_type: int, payload: bytes) -> bytes:
    """A whole frame: type byte, uint32 BE size, payload."""
    return frame_header(frame_type, len(payload)) + payload


def encode_error_frame(reason: str) -> bytes:
    """An error frame (type 255) carrying ``reason`` in UTF-8."""
    return encode_frame(FrameType.ERROR, reason.encode("utf-8"))


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

    def image(self) -> np.ndarray:
        """The image as an (H, W, 3) BGR uint8 array (OpenCV's order).

        Raises:
            RemoteProtocolError: the data does not decode, or disagrees with the META header.
        """
        if self.frame_type is FrameType.RAW:
            img = decode_raw(self.data)
        else:
            if not self.data:  # OpenCV raises its own error on an empty buffer
                raise RemoteProtocolError(f"{self.frame_type.name} frame with no image data")
            img_or_none = cv2.imdecode(np.frombuffer(self.data, np.uint8), cv2.IMREAD_COLOR)
            if img_or_none is None:
                raise RemoteProtocolError(
                    f"{self.frame_type.name} frame of {len(self.data)} bytes does not decode"
                )
            img = img_or_none
        if self.meta is not None and img.shape[:2] != (self.meta.height, self.meta.width):
            raise RemoteProtocolError(
                f"image is {img.shape[1]}x{img.shape[0]} but META says "
                f"{self.meta.width}x{self.meta.height}"
            )
        return img

    def image_rgb(self) -> np.ndarray:
        """The image in RGB order."""
        return np.ascontiguousarray(self.image()[:, :, ::-1])


@dataclass(frozen=True)
class RemoteError:
    """An error frame (type 255): the server refused a request, saying why."""

    reason: str


@dataclass(frozen=True)
class ProtocolViolation:
    """The byte stream broke the protocol; the decoder has stopped."""

    reason: str


FrameEvent = DecodedFrame | RemoteError | ProtocolViolation


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
    meta: MetaHeader | None = None
    if frame_type >= META_OFFSET:
        if len(payload) < META_HEADER_BYTES:
            return ProtocolViolation(
                f"META frame of {len(payload)} bytes is shorter than its 24-byte header"
            )
        meta = MetaHeader(*_META_HEADER.unpack_from(payload))
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
    width, height = _RAW_PREFIX.unpack_from(payload)
    expected = RAW_PREFIX_BYTES + raw_row_bytes(width) * height
    if len(payload) != expected:
        return f"RAW {width}x{height} needs {expected} bytes, frame has {len(payload)}"
    if meta is not None and (meta.width, meta.height) != (width, height):
        return f"RAW is {width}x{height} but META says {meta.width}x{meta.height}"
    return None
