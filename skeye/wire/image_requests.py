"""The image protocol's requests (docs/protocols/images.md): client to server, sans-IO.

How this works: :class:`RequestParser` turns a byte stream into :data:`Request` values. It scans
for three openings: ``OK`` (2 bytes), ``U`` + 16 bytes (four uint32 big-endian) and ``SKEYE ``
up to ``\\n``. Any other byte forms no request and is dropped, as UPIS does. An extension line
that cannot be parsed, or one longer than ``max_line_bytes``, becomes a :class:`RequestError`
(the server answers it with an error frame); an over-long line is then discarded up to its
newline. Invariants: the parser holds at most ``max_line_bytes`` bytes, and the requests it
returns do not depend on how the stream was split into ``feed`` calls. :func:`encode_request`
is its inverse (used by the client), and ``feed(encode_request(r))`` gives back ``[r]`` for
every valid request. The frames the server answers with are :mod:`skeye.wire.images`.
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass

from skeye.errors import LocalProtocolError
from skeye.wire.images import (
    DEFAULT_MAX_LINE_BYTES,
    MAX_STREAM_FPS,
    UINT32_MAX,
    ImageFormat,
    check_quality,
)

_SUBRECT = struct.Struct(">IIII")

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
                or not (0 <= value <= UINT32_MAX)
            ):
                raise LocalProtocolError(f"SubRect.{name} must be a uint32, got {value!r}")


_CAMERA_NAME = re.compile(r"[!-~]{1,200}")  # printable ASCII, no spaces


@dataclass(frozen=True)
class SelectCamera:
    """``SKEYE CAMERA <robot>/<camera>``."""

    name: str

    def __post_init__(self) -> None:
        if not _CAMERA_NAME.fullmatch(self.name):
            shown = (repr(self.name) if len(self.name) <= 60  # a long one is not echoed whole
                     else f"{self.name[:40]!r}... ({len(self.name)} characters)")
            raise LocalProtocolError(
                f"camera name must be 1-200 printable ASCII characters without spaces, "
                f"got {shown}"
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
            check_quality(self.quality)
        elif self.quality is not None:
            raise LocalProtocolError(f"{self.kind.value} format takes no quality")


@dataclass(frozen=True)
class SetMeta:
    """``SKEYE META on|off``."""

    on: bool


@dataclass(frozen=True)
class NewestInfo:
    """``SKEYE INFO``: the newest frame's META header alone (number, sim time, camera id,
    size), answered with an INFO frame; the frame is not rendered for it."""


@dataclass(frozen=True)
class SetPrerender:
    """``SKEYE PRERENDER on|off``: whether this connection's camera frames are rendered ahead
    of its requests (on, the default) or only when it asks for one (off)."""

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


Request = (NewestFrame | SubRect | NewestInfo | SelectCamera | SetFormat | SetMeta
           | SetPrerender | Stream | RequestError)

_EXT_PREFIX = b"SKEYE "
_SWITCHES: dict[str, type[SetMeta] | type[SetPrerender]] = {"META": SetMeta,
                                                           "PRERENDER": SetPrerender}
"""The extension commands that take ``on`` or ``off``."""
_OPENINGS = re.compile(rb"[OUS]")


def encode_request(request: Request) -> bytes:
    """The wire bytes of one request (the client side of :class:`RequestParser`)."""
    match request:
        case NewestFrame():
            return b"OK"
        case SubRect(x=x, y=y, width=w, height=h):
            return b"U" + _SUBRECT.pack(x, y, w, h)
        case NewestInfo():
            return _EXT_PREFIX + b"INFO\n"
        case SelectCamera(name=name):
            return _EXT_PREFIX + b"CAMERA " + name.encode("ascii") + b"\n"
        case SetFormat(kind=kind, quality=quality):
            tail = f" {quality}" if kind is ImageFormat.JPEG else ""
            return _EXT_PREFIX + f"FORMAT {kind.value}{tail}".encode("ascii") + b"\n"
        case SetMeta(on=on):
            return _EXT_PREFIX + (b"META on\n" if on else b"META off\n")
        case SetPrerender(on=on):
            return _EXT_PREFIX + (b"PRERENDER on\n" if on else b"PRERENDER off\n")
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
        if command == "INFO":
            if args:
                return RequestError(f"expected 'INFO', got {shown!r}")
            return NewestInfo()
        if command in _SWITCHES:
            if len(args) != 1 or args[0].lower() not in ("on", "off"):
                return RequestError(f"expected '{command} on|off', got {shown!r}")
            return _SWITCHES[command](args[0].lower() == "on")
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
