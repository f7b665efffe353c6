"""The vehicle's video protocol (docs/protocols/video.md), sans-IO: messages, codec, states.

How this works: the pilot serves its camera frames, each with its own landing-pad detection,
on a TCP port of the vehicle (as an onboard computer streams over Wi-Fi); ground control is a
client. Every message is one frame on the stream::

    offset  size  field
    0       2     magic b"SV"
    2       1     protocol version (1)
    3       1     message type (:class:`MsgType`)
    4       4     header length H, unsigned big-endian, at most MAX_HEADER_BYTES
    8       4     payload length P, unsigned big-endian; 0 except for FRAME (the JPEG)
    12      H     header: a UTF-8 JSON object (the message's fields)
    12+H    P     payload: the frame's JPEG bytes

A client connects, sends SUBSCRIBE (the most frames per second it wants) and then reads: the
server answers HELLO (camera, field of view, JPEG quality, its own rate limit) and then FRAME
messages. Either side may send ERROR with a reason before it closes. Who may send what and when
is the transition table :data:`TRANSITIONS`; :class:`VideoConnection` keeps one side's state,
turns bytes into messages (:meth:`~VideoConnection.receive_data`) and messages into bytes
(:meth:`~VideoConnection.send`), without sockets, threads or clocks.

Invariants: every message is checked when it is built (:class:`~skeye.errors.LocalProtocolError`
for our own bad values); arbitrary bytes from a peer give messages or a
:class:`~skeye.errors.RemoteProtocolError` naming the problem, never another exception. The
detection carried is what the vehicle's detector produced (docs/landing-pad.md): "not found"
has every figure None.
"""

from __future__ import annotations

import enum
import json
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from skeye.errors import LocalProtocolError, RemoteProtocolError, SkeyeError

MAGIC = b"SV"
VERSION = 1
PREFIX = struct.Struct(">2sBBII")
MAX_HEADER_BYTES = 16 * 1024
MAX_PAYLOAD_BYTES = 8 * 1024 * 1024
MAX_CLIENT_HEADER_BYTES = 1024
"""A client has nothing long to say: a longer header is garbage, refused before it is read."""
DEFAULT_JPEG_QUALITY = 80
"""The pilot's JPEG quality (OpenCV's 0..100 scale): an 800x600 frame of the pad world is
about 40-60 kB, 8 frames/s fit a 2.4 GHz Wi-Fi link several times over."""
MAX_ELLIPSES = 64
JPEG_SOI = b"\xff\xd8"


class MsgType(enum.IntEnum):
    HELLO = 1  # server -> client, once, after SUBSCRIBE
    FRAME = 2  # server -> client
    ERROR = 3  # either way, then the sender closes
    SUBSCRIBE = 4  # client -> server: first message, may be repeated to change the rate


class Role(enum.Enum):
    SERVER = "server"
    CLIENT = "client"


class State(enum.Enum):
    WAIT_SUBSCRIBE = "wait-subscribe"  # the client has not subscribed yet
    WAIT_HELLO = "wait-hello"  # subscribed, HELLO not yet sent/seen
    STREAMING = "streaming"
    CLOSED = "closed"


TRANSITIONS: dict[tuple[State, MsgType], State] = {
    (State.WAIT_SUBSCRIBE, MsgType.SUBSCRIBE): State.WAIT_HELLO,
    (State.WAIT_HELLO, MsgType.SUBSCRIBE): State.WAIT_HELLO,
    (State.WAIT_HELLO, MsgType.HELLO): State.STREAMING,
    (State.STREAMING, MsgType.SUBSCRIBE): State.STREAMING,
    (State.STREAMING, MsgType.FRAME): State.STREAMING,
    (State.WAIT_SUBSCRIBE, MsgType.ERROR): State.CLOSED,
    (State.WAIT_HELLO, MsgType.ERROR): State.CLOSED,
    (State.STREAMING, MsgType.ERROR): State.CLOSED,
}
"""``(state, message) -> state``, the same for both sides of one connection; a pair not here is
a protocol error (the peer's: RemoteProtocolError; ours: LocalProtocolError)."""

SENT_BY: dict[MsgType, Role | None] = {
    MsgType.HELLO: Role.SERVER,
    MsgType.FRAME: Role.SERVER,
    MsgType.SUBSCRIBE: Role.CLIENT,
    MsgType.ERROR: None,  # either
}


# -- messages --------------------------------------------------------------------------------
def _show(value: Any) -> str:
    """A value for an error message, cut short (it may be a peer's garbage)."""
    try:
        text = repr(value)
    except ValueError:  # an int too long to print
        text = f"<{type(value).__name__}>"
    return text if len(text) <= 60 else text[:57] + "..."


def _finite(name: str, value: float, lo: float = -math.inf, hi: float = math.inf) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise LocalProtocolError(f"{name} must be a number, got {_show(value)}")
    try:
        finite = math.isfinite(value)
    except OverflowError:  # an integer too large for a float
        finite = False
    if not finite:
        raise LocalProtocolError(f"{name} must be a finite number, got {_show(value)}")
    if not lo <= value <= hi:
        raise LocalProtocolError(f"{name} must be in [{lo:g}, {hi:g}], got {_show(value)}")


def _int(name: str, value: int, lo: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise LocalProtocolError(f"{name} must be an integer in [{lo}, {hi}], got {_show(value)}")


def _text(name: str, value: str, max_len: int = 200) -> None:
    if not isinstance(value, str) or len(value) > max_len:
        raise LocalProtocolError(f"{name} must be text of at most {max_len} characters")


def _pair(name: str, value: tuple[float, float] | None) -> None:
    if value is None:
        return
    if not isinstance(value, tuple) or len(value) != 2:
        raise LocalProtocolError(f"{name} must be a pair of numbers, got {_show(value)}")
    for i, v in enumerate(value):
        _finite(f"{name}[{i}]", v)


@dataclass(frozen=True)
class RingEllipse:
    """One identified ring border as the detector saw it in the image (pixels)."""

    ring: int  # 1 = outermost
    border: str  # "outer" or "inner"
    center_px: tuple[float, float]
    semi_axes_px: tuple[float, float]  # (major, minor)
    angle_rad: float  # of the major axis, from image +u towards +v

    def __post_init__(self) -> None:
        _int("ellipse ring", self.ring, 1, 255)
        if self.border not in ("outer", "inner"):
            raise LocalProtocolError(
                f"ellipse border must be 'outer' or 'inner': {_show(self.border)}"
            )
        _pair("ellipse center_px", self.center_px)
        _pair("ellipse semi_axes_px", self.semi_axes_px)
        _finite("ellipse angle_rad", self.angle_rad)


@dataclass(frozen=True)
class Detection:
    """The vehicle's detector output for one frame (docs/landing-pad.md's JSON, typed).

    ``roll_rad``/``pitch_rad``: the attitude the detector was given (None: it took the camera
    as level). Not found: every figure None, no rings, no ellipses.
    """

    found: bool
    center_px: tuple[float, float] | None = None
    height_m: float | None = None
    offset_cam_m: tuple[float, float] | None = None
    offset_body_m: tuple[float, float] | None = None
    rings: tuple[int, ...] = ()
    ellipses: tuple[RingEllipse, ...] = ()
    quality: float = 0.0
    roll_rad: float | None = None
    pitch_rad: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.found, bool):
            raise LocalProtocolError(f"detection found must be true or false: {_show(self.found)}")
        for name in ("center_px", "offset_cam_m", "offset_body_m"):
            _pair(f"detection {name}", getattr(self, name))
        if self.height_m is not None:
            _finite("detection height_m", self.height_m, 0.0)
        for name in ("roll_rad", "pitch_rad"):
            value = getattr(self, name)
            if value is not None:
                _finite(f"detection {name}", value, -math.pi, math.pi)
        _finite("detection quality", self.quality, 0.0, 1.0)
        if not isinstance(self.rings, tuple) or len(self.rings) > MAX_ELLIPSES:
            raise LocalProtocolError("detection rings must be a tuple of ring numbers")
        for r in self.rings:
            _int("detection ring", r, 1, 255)
        if not isinstance(self.ellipses, tuple) or len(self.ellipses) > MAX_ELLIPSES:
            raise LocalProtocolError(f"detection ellipses: a tuple of at most {MAX_ELLIPSES}")
        if not all(isinstance(e, RingEllipse) for e in self.ellipses):
            raise LocalProtocolError("detection ellipses must be RingEllipse values")
        figures = (self.center_px, self.height_m, self.offset_cam_m, self.offset_body_m)
        if self.found and any(f is None for f in figures):
            raise LocalProtocolError("a found pad needs center_px, height_m and both offsets")
        if not self.found and (any(f is not None for f in figures) or self.rings):
            raise LocalProtocolError("a pad not found has no figures and no rings")


MIN_FPS, MAX_FPS = 0.01, 1000.0
"""The frame rates SUBSCRIBE and HELLO carry (frames/s)."""


@dataclass(frozen=True)
class Subscribe:
    """Client -> server: send me frames, at most ``max_fps`` per second."""

    max_fps: float

    def __post_init__(self) -> None:
        _finite("subscribe max_fps", self.max_fps, MIN_FPS, MAX_FPS)


@dataclass(frozen=True)
class Hello:
    """Server -> client, once: what is streamed."""

    camera: str
    fov_h_rad: float
    jpeg_quality: int
    max_fps: float

    def __post_init__(self) -> None:
        _text("hello camera", self.camera)
        _finite("hello fov_h_rad", self.fov_h_rad, 1e-6, math.pi)
        _int("hello jpeg_quality", self.jpeg_quality, 1, 100)
        _finite("hello max_fps", self.max_fps, MIN_FPS, MAX_FPS)


@dataclass(frozen=True)
class Frame:
    """Server -> client: one camera frame (JPEG) and the vehicle's detection in it.

    ``frame_number``: the camera's frame counter; ``time_s``: when the frame was captured (sim
    time on the simulator, the camera clock on a vehicle); ``detect_ms``: the detector's time.
    """

    frame_number: int
    time_s: float
    width: int
    height: int
    detection: Detection
    detect_ms: float
    jpeg: bytes = field(repr=False)

    def __post_init__(self) -> None:
        _int("frame frame_number", self.frame_number, 0, 2**53)
        _finite("frame time_s", self.time_s, 0.0)
        _int("frame width", self.width, 1, 65535)
        _int("frame height", self.height, 1, 65535)
        _finite("frame detect_ms", self.detect_ms, 0.0)
        if not isinstance(self.detection, Detection):
            raise LocalProtocolError("frame detection must be a Detection")
        if not isinstance(self.jpeg, bytes) or not self.jpeg.startswith(JPEG_SOI):
            raise LocalProtocolError("frame jpeg must be JPEG bytes (starting FF D8)")
        if len(self.jpeg) > MAX_PAYLOAD_BYTES:
            raise LocalProtocolError(f"frame jpeg over {MAX_PAYLOAD_BYTES} bytes")


@dataclass(frozen=True)
class Error:
    """Either way: why the sender is about to close the connection."""

    reason: str

    def __post_init__(self) -> None:
        _text("error reason", self.reason, 500)


Message = Subscribe | Hello | Frame | Error


# -- the codec: one entry per message type ---------------------------------------------------
def _pair_json(p: tuple[float, float] | None) -> list[float] | None:
    return None if p is None else [float(p[0]), float(p[1])]


def _pair_from(value: Any) -> tuple[float, float] | None:
    if value is None:
        return None
    if not isinstance(value, list) or len(value) != 2:
        raise LocalProtocolError(f"expected a pair of numbers, got {_show(value)}")
    return (value[0], value[1])


def detection_to_json(d: Detection) -> dict[str, Any]:
    """The JSON form (also what ground control shows)."""
    return {
        "found": d.found,
        "center_px": _pair_json(d.center_px),
        "height_m": d.height_m,
        "offset_cam_m": _pair_json(d.offset_cam_m),
        "offset_body_m": _pair_json(d.offset_body_m),
        "rings": list(d.rings),
        "quality": d.quality,
        "ellipses": [
            {
                "ring": e.ring,
                "border": e.border,
                "center_px": _pair_json(e.center_px),
                "semi_axes_px": _pair_json(e.semi_axes_px),
                "angle_rad": e.angle_rad,
            }
            for e in d.ellipses
        ],
        "roll_rad": d.roll_rad,
        "pitch_rad": d.pitch_rad,
    }


def _f(obj: dict[str, Any], key: str) -> Any:
    """A field of a decoded JSON object (None when absent: the message's check names it)."""
    return obj.get(key)


def _object(value: Any, what: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise LocalProtocolError(f"{what} must be a JSON object")
    return value


def _list(value: Any, what: str) -> list[Any]:
    if not isinstance(value, list):
        raise LocalProtocolError(f"{what} must be a JSON list")
    return value


def detection_from_json(obj: Any) -> Detection:
    o = _object(obj, "detection")
    ellipses = []
    for e in _list(o.get("ellipses", []), "detection ellipses")[: MAX_ELLIPSES + 1]:
        e = _object(e, "ellipse")
        centre, axes = _pair_from(_f(e, "center_px")), _pair_from(_f(e, "semi_axes_px"))
        if centre is None or axes is None:
            raise LocalProtocolError("an ellipse needs center_px and semi_axes_px")
        ellipses.append(RingEllipse(_f(e, "ring"), _f(e, "border"), centre, axes,
                                    _f(e, "angle_rad")))
    return Detection(
        found=_f(o, "found"),
        center_px=_pair_from(_f(o, "center_px")),
        height_m=_f(o, "height_m"),
        offset_cam_m=_pair_from(_f(o, "offset_cam_m")),
        offset_body_m=_pair_from(_f(o, "offset_body_m")),
        rings=tuple(_list(o.get("rings", []), "detection rings")[: MAX_ELLIPSES + 1]),
        ellipses=tuple(ellipses),
        quality=o.get("quality", 0.0),
        roll_rad=_f(o, "roll_rad"),
        pitch_rad=_f(o, "pitch_rad"),
    )


@dataclass(frozen=True)
class _Codec:
    mtype: MsgType
    cls: type
    to_json: Callable[[Any], dict[str, Any]]
    from_json: Callable[[dict[str, Any], bytes], Any]
    payload: Callable[[Any], bytes] = lambda m: b""


CODECS: tuple[_Codec, ...] = (
    _Codec(MsgType.SUBSCRIBE, Subscribe, lambda m: {"max_fps": m.max_fps},
           lambda o, p: Subscribe(_f(o, "max_fps"))),
    _Codec(MsgType.HELLO, Hello,
           lambda m: {"camera": m.camera, "fov_h_rad": m.fov_h_rad,
                      "jpeg_quality": m.jpeg_quality, "max_fps": m.max_fps},
           lambda o, p: Hello(_f(o, "camera"), _f(o, "fov_h_rad"), _f(o, "jpeg_quality"),
                              _f(o, "max_fps"))),
    _Codec(MsgType.FRAME, Frame,
           lambda m: {"frame_number": m.frame_number, "time_s": m.time_s, "width": m.width,
                      "height": m.height, "detect_ms": m.detect_ms,
                      "detection": detection_to_json(m.detection)},
           lambda o, p: Frame(_f(o, "frame_number"), _f(o, "time_s"), _f(o, "width"),
                              _f(o, "height"), detection_from_json(_f(o, "detection")),
                              _f(o, "detect_ms"), p),
           lambda m: m.jpeg),
    _Codec(MsgType.ERROR, Error, lambda m: {"reason": m.reason},
           lambda o, p: Error(_f(o, "reason"))),
)
BY_TYPE = {c.mtype: c for c in CODECS}
BY_CLASS = {c.cls: c for c in CODECS}


def encode(msg: Message) -> bytes:
    """One message as bytes on the wire."""
    codec = BY_CLASS.get(type(msg))
    if codec is None:
        raise LocalProtocolError(f"not a video message: {msg!r}")
    header = json.dumps(codec.to_json(msg), separators=(",", ":"), allow_nan=False).encode()
    payload = codec.payload(msg)
    if len(header) > MAX_HEADER_BYTES:
        raise LocalProtocolError(f"{codec.mtype.name} header over {MAX_HEADER_BYTES} bytes")
    return PREFIX.pack(MAGIC, VERSION, codec.mtype, len(header), len(payload)) + header + payload


def decode(mtype: int, header: bytes, payload: bytes) -> Message:
    """One message from its parts (the prefix already checked); RemoteProtocolError if bad."""
    codec = BY_TYPE[MsgType(mtype)]
    try:
        obj = json.loads(header.decode("utf-8"), parse_constant=_no_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise RemoteProtocolError(f"{codec.mtype.name} header is not UTF-8 JSON: {exc}") from None
    if not isinstance(obj, dict):
        raise RemoteProtocolError(f"{codec.mtype.name} header is not a JSON object")
    if payload and codec.mtype is not MsgType.FRAME:
        raise RemoteProtocolError(f"{codec.mtype.name} carries no payload, got {len(payload)} B")
    try:
        msg: Message = codec.from_json(obj, payload)
    except LocalProtocolError as exc:
        raise RemoteProtocolError(f"bad {codec.mtype.name}: {exc}") from None
    return msg


def _no_constant(name: str) -> None:
    raise ValueError(f"{name} is not allowed")


class VideoDecoder:
    """Bytes in, messages out, for a stream in any pieces (sans-IO).

    Args:
        max_header_bytes / max_payload_bytes: the largest accepted; a prefix announcing more
            is refused at once, before its bytes arrive.
    """

    def __init__(self, max_header_bytes: int = MAX_HEADER_BYTES,
                 max_payload_bytes: int = MAX_PAYLOAD_BYTES) -> None:
        self.max_header_bytes = max_header_bytes
        self.max_payload_bytes = max_payload_bytes
        self._buf = bytearray()

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def feed(self, data: bytes) -> list[Message]:
        """Every complete message in ``data`` (and what came before it).

        Raises:
            RemoteProtocolError: the stream is not this protocol (it cannot be resynchronised:
                the caller closes the connection).
        """
        self._buf += data
        out: list[Message] = []
        while True:
            if len(self._buf) >= 2 and self._buf[:2] != MAGIC:
                start = bytes(self._buf[:8])
                raise RemoteProtocolError(f"not a skeye video stream: starts {start!r}")
            if len(self._buf) < PREFIX.size:
                return out
            _, version, mtype, hlen, plen = PREFIX.unpack_from(self._buf)
            if version != VERSION:
                raise RemoteProtocolError(f"video protocol version {version}, expected {VERSION}")
            if mtype not in BY_TYPE:
                raise RemoteProtocolError(f"unknown video message type {mtype}")
            if hlen > self.max_header_bytes:
                raise RemoteProtocolError(f"header of {hlen} bytes, over {self.max_header_bytes}")
            if plen > self.max_payload_bytes:
                raise RemoteProtocolError(f"payload of {plen} bytes, over {self.max_payload_bytes}")
            end = PREFIX.size + hlen + plen
            if len(self._buf) < end:
                return out
            header = bytes(self._buf[PREFIX.size:PREFIX.size + hlen])
            payload = bytes(self._buf[PREFIX.size + hlen:end])
            del self._buf[:end]
            out.append(decode(mtype, header, payload))


class VideoConnection:
    """One side of one video connection: the decoder plus the states of :data:`TRANSITIONS`.

    ``receive_data`` checks what the peer sends (RemoteProtocolError: the caller sends
    :class:`Error` if it can and closes); ``send`` checks what we send (LocalProtocolError).
    """

    def __init__(self, role: Role) -> None:
        self.role = role
        self.state = State.WAIT_SUBSCRIBE
        peer_is_client = role is Role.SERVER
        self._decoder = VideoDecoder(
            MAX_CLIENT_HEADER_BYTES if peer_is_client else MAX_HEADER_BYTES,
            0 if peer_is_client else MAX_PAYLOAD_BYTES,
        )

    def _step(self, msg: Message, sender: Role, error: type[SkeyeError]) -> None:
        mtype = BY_CLASS[type(msg)].mtype
        allowed = SENT_BY[mtype]
        if allowed is not None and allowed is not sender:
            raise error(f"a {sender.value} does not send {mtype.name}")
        nxt = TRANSITIONS.get((self.state, mtype))
        if nxt is None:
            raise error(f"{mtype.name} is not allowed in state {self.state.value}")
        self.state = nxt

    @property
    def buffered(self) -> int:
        """Bytes received of a message not complete yet."""
        return self._decoder.buffered

    def receive_data(self, data: bytes) -> list[Message]:
        """The peer's messages in ``data``, each checked against the state."""
        if self.state is State.CLOSED:
            if data:
                raise RemoteProtocolError("data after ERROR")
            return []
        peer = Role.CLIENT if self.role is Role.SERVER else Role.SERVER
        messages = self._decoder.feed(data)
        for i, msg in enumerate(messages):
            self._step(msg, peer, RemoteProtocolError)
            if self.state is State.CLOSED and i + 1 < len(messages):
                raise RemoteProtocolError("messages after ERROR")
        return messages

    def send(self, msg: Message) -> bytes:
        """``msg`` as bytes, if this side may send it now."""
        self._step(msg, self.role, LocalProtocolError)
        return encode(msg)
