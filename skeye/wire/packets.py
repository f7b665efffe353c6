"""Sans-IO codec of the vehicle packet protocol (docs/protocols/packets.md): bytes <-> messages.

How this works: ``encode(msg)`` looks the message's class up in ``LAYOUTS`` (packet_defs) and
packs its fields in the table's order, little-endian, then frames the payload the way that
class travels: vehicle frames ``>*>`` len PD payload crc ``<#<``, acks ``>a`` PD ``a<``, AscTec
commands prefix + payload (their checksum computed here), skeye commands like vehicle frames
but opening with ``>*>s``. Nothing else in skeye packs protocol bytes.

Two stream parsers do the reverse without I/O: ``feed(data)`` appends to a buffer and returns
every event now complete, in order. ``VehicleStreamParser`` is what ground control receives
(vehicle frames and acks); ``CommandStreamParser`` is what the vehicle receives (AscTec
commands and skeye frames). Invariants:

- Any byte string, cut anywhere into chunks, gives the same events; nothing raises.
- Bytes before a start marker are garbage: skipped and counted in ``garbage_bytes``.
- A bad frame gives an error event and is counted in ``errors[ErrorKind]``. Resynchronisation:
  when the frame's end is confirmed (its stop string is present, or a command's checksum
  matched) the parser skips the whole frame; when it is not (bad stop string, length field over
  1024, bad command checksum, unknown command letters) it resumes at the byte after the bad
  start marker, so a real frame hidden behind a corrupt length or a dropped byte is still found.
  A length field that disagrees with its PD's structure (every vehicle structure and every
  skeye command has a fixed size; RESULT at least its fixed part) is such a bad frame at once,
  on both sides: it is not waited for. The vehicle side answers it BAD_LENGTH
  (``CommandError(..., intact=False)``: its CRC never came, so it is no packet for the link
  timeout).
- The buffer never holds more than one maximal frame (1035 bytes) plus the unparsed chunk.
  ``discard()`` drops an unfinished frame whose sender is gone (a new connection on the line).

Error events: ground side gets ``FrameError(reason, kind)``. The vehicle side gets
``CommandError(pd, code, reason)`` whenever it can name the command, so it can answer a RESULT
with that code: command checksum or skeye CRC wrong -> BAD_CHECKSUM, skeye payload length not
that of its PD -> BAD_LENGTH, a field out of range -> BAD_VALUE. An unknown skeye PD is answered
BAD_VALUE too (the descriptor is a value the vehicle does not accept; there is nothing wrong
with the frame's length or checksum, and REFUSED means "valid but not now"). Errors that leave
no command to name (bad stop string, over-long length, unknown ``>*>`` command letters) are
``FrameError`` on the vehicle side as well.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum
from typing import Any

from skeye.errors import LocalProtocolError
from skeye.wire.crc import command_checksum, crc16
from skeye.wire.packet_defs import (
    ACK_PDS,
    ASCTEC_BY_PREFIX,
    GPS_FIX_VALID,
    LAYOUTS,
    MAX_PAYLOAD,
    PD,
    POLL_MASK_ALL,
    POLL_PDS,
    SKEYE_BY_PD,
    VEHICLE_BY_PD,
    Ack,
    Clock,
    ComeHome,
    ControllerOutput,
    CtrlBits,
    CtrlInput,
    CurrentWay,
    EndFlight,
    FrameKind,
    GotoGps,
    GpsData,
    GpsDataAdvanced,
    Health,
    HealthStatus,
    Hold,
    ImuCalcData,
    ImuRawData,
    Land,
    Launch,
    Layout,
    LlStatus,
    Message,
    MoveBy,
    MoveFrame,
    NavigationStatus,
    NavState,
    NavStatus,
    PadAction,
    PadMode,
    PadReport,
    Poll,
    PollMask,
    RcData,
    Reset,
    Result,
    ResultCode,
    SkeyeMask,
    Stream,
    TakeOff,
    Truth,
    VehicleInfo,
    Velocity,
    Waypoint,
    WaypointGoto,
    WaypointProps,
)

__all__ = [
    "ACK_PDS",
    "GPS_FIX_VALID",
    "MAX_PAYLOAD",
    "PD",
    "POLL_MASK_ALL",
    "POLL_PDS",
    "Ack",
    "Clock",
    "ComeHome",
    "CommandError",
    "CommandEvent",
    "CommandStreamParser",
    "ControllerOutput",
    "CtrlBits",
    "CtrlInput",
    "CurrentWay",
    "EndFlight",
    "ErrorKind",
    "FrameError",
    "GotoGps",
    "GpsData",
    "GpsDataAdvanced",
    "Health",
    "HealthStatus",
    "Hold",
    "ImuCalcData",
    "ImuRawData",
    "Land",
    "Launch",
    "LlStatus",
    "Message",
    "MoveBy",
    "MoveFrame",
    "NavState",
    "NavStatus",
    "NavigationStatus",
    "PadAction",
    "PadMode",
    "PadReport",
    "Poll",
    "PollMask",
    "RcData",
    "Reset",
    "Result",
    "ResultCode",
    "SkeyeMask",
    "Stream",
    "TakeOff",
    "Truth",
    "VehicleEvent",
    "VehicleInfo",
    "VehicleStreamParser",
    "Velocity",
    "Waypoint",
    "WaypointGoto",
    "WaypointProps",
    "arrived_intact",
    "encode",
]

START = b">*>"
SKEYE_START = b">*>s"
STOP = b"<#<"
ACK_START = b">a"
ACK_STOP = b"a<"
_FRAME_OVERHEAD = 3 + 2  # crc + stop after the payload


class ErrorKind(Enum):
    """What was wrong with a rejected frame; the key of ``parser.errors``."""

    BAD_CRC = "bad CRC"
    BAD_CHECKSUM = "bad command checksum"
    BAD_STOP = "bad stop string"
    TOO_LONG = "length over 1024"
    UNKNOWN_PD = "unknown descriptor or command"
    BAD_LENGTH = "payload length does not match descriptor"
    BAD_VALUE = "field value out of range"


@dataclass(frozen=True)
class FrameError:
    """A rejected frame (or command bytes that name no command)."""

    reason: str
    kind: ErrorKind


@dataclass(frozen=True)
class CommandError:
    """A rejected command the vehicle can name; answer it with ``self.result()``."""

    pd: int
    code: ResultCode
    reason: str
    intact: bool = True  # False: judged before its CRC came (a length that disagrees with its PD)

    def result(self) -> Result:
        """The RESULT packet that answers this error."""
        reason = self.reason.encode("utf-8")[: Result.MAX_REASON_BYTES]
        return Result(self.pd, self.code, reason.decode("utf-8", errors="ignore"))


VehicleEvent = Message | FrameError
CommandEvent = Message | CommandError | FrameError


def arrived_intact(event: CommandEvent) -> bool:
    """Did this event's bytes pass their CRC or checksum (or have none to fail)?

    Only such an event shows that a ground station is on the line: a frame whose CRC or
    command checksum failed, and bytes too broken to name a command, may be line noise, so the
    vehicle's link timeout does not count them as packets (docs/protocols/packets.md, "Flight
    states"). A rejected command whose bytes arrived intact (a wrong length, a value out of
    range, an unknown skeye PD) was sent by a station and counts; a length field that
    disagrees with its PD is answered before the frame's CRC has come, so it does not.
    """
    if isinstance(event, FrameError):
        return False
    if isinstance(event, CommandError):
        return event.intact and event.code is not ResultCode.BAD_CHECKSUM
    return True


# --- encoding -------------------------------------------------------------------------------


def _payload(layout: Layout, msg: Message) -> bytes:
    values: list[Any] = []
    for f in layout.fields:
        if f.computed:
            values.append(command_checksum(*(getattr(msg, n) for n in layout.checksum)))
        elif f.count > 1:
            values.extend(getattr(msg, f.name))
        else:
            values.append(getattr(msg, f.name))
    data = layout.packer.pack(*values)
    if layout.tail is not None:
        data += getattr(msg, layout.tail).encode("utf-8")
    return data


def _frame(start: bytes, pd: int, payload: bytes) -> bytes:
    return b"".join(
        (
            start,
            len(payload).to_bytes(2, "little"),
            bytes((pd,)),
            payload,
            crc16(payload).to_bytes(2, "little"),
            STOP,
        )
    )


def encode(msg: Message) -> bytes:
    """The complete wire bytes of ``msg`` in the direction its type travels."""
    layout = LAYOUTS.get(type(msg))
    if layout is None:
        raise LocalProtocolError(f"{type(msg).__name__} is not a vehicle packet message")
    payload = _payload(layout, msg)
    if layout.kind is FrameKind.ACK:
        return ACK_START + payload + ACK_STOP
    if layout.kind is FrameKind.ASCTEC:
        return layout.prefix + payload
    assert layout.pd is not None  # vehicle and skeye frames always have one (packet_defs)
    return _frame(SKEYE_START if layout.kind is FrameKind.SKEYE else START, layout.pd, payload)


# --- decoding -------------------------------------------------------------------------------


class _Reject(Exception):
    """Internal: a payload that cannot become its message."""

    def __init__(self, kind: ErrorKind, reason: str) -> None:
        super().__init__(reason)
        self.kind = kind
        self.reason = reason


def _decode(cls: type[Message], payload: bytes) -> Message:
    """Payload -> message, or ``_Reject`` naming what is wrong (never anything else)."""
    layout = LAYOUTS[cls]
    size = layout.size
    if len(payload) != size and not (layout.tail is not None and len(payload) >= size):
        raise _Reject(
            ErrorKind.BAD_LENGTH, f"{cls.__name__} payload is {len(payload)} bytes, not {size}"
        )
    values = iter(layout.packer.unpack_from(payload))
    kwargs: dict[str, Any] = {}
    received_checksum = None
    for f in layout.fields:
        if f.computed:
            received_checksum = next(values)
        elif f.count > 1:
            kwargs[f.name] = tuple(next(values) for _ in range(f.count))
        else:
            kwargs[f.name] = next(values)
    if layout.checksum:
        expected = command_checksum(*(kwargs[n] for n in layout.checksum))
        if received_checksum != expected:
            raise _Reject(
                ErrorKind.BAD_CHECKSUM,
                f"{cls.__name__} checksum 0x{received_checksum:04x}, expected 0x{expected:04x}",
            )
    if layout.tail is not None:
        try:
            kwargs[layout.tail] = payload[size:].decode("utf-8")
        except UnicodeDecodeError as exc:
            raise _Reject(ErrorKind.BAD_VALUE, f"{cls.__name__}.{layout.tail}: {exc}") from None
    try:
        return cls(**kwargs)
    except LocalProtocolError as exc:
        raise _Reject(ErrorKind.BAD_VALUE, str(exc)) from None


_RESULT_CODE = {
    ErrorKind.BAD_CRC: ResultCode.BAD_CHECKSUM,
    ErrorKind.BAD_CHECKSUM: ResultCode.BAD_CHECKSUM,
    ErrorKind.BAD_LENGTH: ResultCode.BAD_LENGTH,
    ErrorKind.BAD_VALUE: ResultCode.BAD_VALUE,
    ErrorKind.UNKNOWN_PD: ResultCode.BAD_VALUE,
}


@dataclass(frozen=True)
class _Framed:
    """A ``>*>``-framed payload whose stop string and CRC were checked."""

    pd: int
    payload: bytes
    size: int  # bytes of the whole frame


@dataclass(frozen=True)
class _BadFrame:
    kind: ErrorKind
    reason: str
    consumed: int
    pd: int | None


def _split_frame(buf: bytearray, start_len: int) -> _Framed | _BadFrame | None:
    """Cut one frame off ``buf`` (which starts with a start marker of ``start_len`` bytes).

    Returns None while the frame is incomplete.
    """
    if len(buf) < start_len + 2:
        return None
    length = buf[start_len] | buf[start_len + 1] << 8
    if length > MAX_PAYLOAD:
        return _BadFrame(ErrorKind.TOO_LONG, f"length field {length} > {MAX_PAYLOAD}", 1, None)
    body = start_len + 3
    total = body + length + _FRAME_OVERHEAD
    if len(buf) < total:
        return None
    pd = buf[start_len + 2]
    if buf[total - 3 : total] != STOP:
        stop = bytes(buf[total - 3 : total])
        return _BadFrame(ErrorKind.BAD_STOP, f"stop string {stop!r} after PD 0x{pd:02x}", 1, pd)
    payload = bytes(buf[body : body + length])
    crc = buf[total - 5] | buf[total - 4] << 8
    if crc != crc16(payload):
        reason = f"PD 0x{pd:02x}: CRC 0x{crc:04x}, computed 0x{crc16(payload):04x}"
        return _BadFrame(ErrorKind.BAD_CRC, reason, total, pd)
    return _Framed(pd, payload, total)


class _StreamParser:
    """Buffer, counters and the feed loop shared by both directions."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.errors: Counter[ErrorKind] = Counter()
        self.garbage_bytes = 0
        self.messages = 0

    @property
    def buffered(self) -> int:
        """Bytes held while waiting for the rest of a frame."""
        return len(self._buf)

    def discard(self) -> int:
        """Drop the bytes held for an unfinished frame (its sender is gone: a new one's bytes
        are not its rest); they count as garbage. How many."""
        dropped = len(self._buf)
        self._buf.clear()
        self.garbage_bytes += dropped
        return dropped

    def _length_misfit(self, start: int, by_pd: Mapping[int, type[Any]]
                       ) -> tuple[type[Any], int, int] | None:
        """(structure, length field, its payload size) when the frame at the buffer's head,
        its start marker ``start`` bytes long, has a length field that disagrees with the
        structure its PD names in ``by_pd`` (each has a fixed size; RESULT at least its fixed
        part): a corrupted length would otherwise hold every later byte as the frame's rest,
        up to 1024 bytes. None while the PD has not come, for an unknown PD (its length cannot
        be checked), for a length too long for any frame (said as such, TOO_LONG) and for one
        that fits."""
        buf = self._buf
        if len(buf) < start + 3:
            return None
        cls = by_pd.get(buf[start + 2])
        if cls is None:
            return None
        layout = LAYOUTS[cls]
        length = buf[start] | buf[start + 1] << 8
        if (length > MAX_PAYLOAD or length == layout.size
                or (layout.tail is not None and layout.size <= length)):
            return None
        return cls, length, layout.size

    def feed(self, data: bytes) -> list[Any]:
        """Add received bytes; return every message or error event now complete, in order.

        Raises:
            LocalProtocolError: ``data`` is not bytes (the only error ``feed`` raises).
        """
        if not isinstance(data, bytes | bytearray | memoryview):
            raise LocalProtocolError(f"feed takes bytes, got {type(data).__name__}")
        self._buf += data
        events: list[Any] = []
        while self._buf:
            step = self._step()
            if step is None:
                break
            consumed, event = step
            del self._buf[:consumed]
            if event is None:
                self.garbage_bytes += consumed
                continue
            if isinstance(event, Message):
                self.messages += 1
            events.append(event)
        return events

    def _skip_to_marker(self) -> tuple[int, None] | None:
        """Garbage before the next '>' (consumed), or None if the buffer starts with '>'."""
        i = self._buf.find(b">")
        if i == 0:
            return None
        return (len(self._buf) if i < 0 else i), None

    def _error(self, kind: ErrorKind, reason: str, consumed: int) -> tuple[int, FrameError]:
        self.errors[kind] += 1
        return consumed, FrameError(reason, kind)

    def _step(self) -> tuple[int, Any] | None:
        raise NotImplementedError


class VehicleStreamParser(_StreamParser):
    """What ground control receives: vehicle frames and acks -> messages or ``FrameError``."""

    def feed(self, data: bytes) -> list[VehicleEvent]:
        """Add received bytes; return every message or ``FrameError`` now complete."""
        return super().feed(data)

    def _step(self) -> tuple[int, Any] | None:
        skip = self._skip_to_marker()
        if skip is not None:
            return skip
        buf = self._buf
        if len(buf) < 2:
            return None
        if buf[1] == ACK_START[1]:
            if len(buf) < 5:
                return None
            if buf[3:5] != ACK_STOP:
                return self._error(ErrorKind.BAD_STOP, f"ack ends {bytes(buf[3:5])!r}", 1)
            if buf[2] not in ACK_PDS:
                return self._error(ErrorKind.UNKNOWN_PD, f"ack of unknown PD 0x{buf[2]:02x}", 5)
            return 5, Ack(PD(buf[2]))
        if not START.startswith(bytes(buf[:3])):
            return 1, None  # a lone '>'
        if len(buf) < 3:
            return None
        wrong = self._wrong_length()
        if wrong is not None:
            return wrong
        framed = _split_frame(buf, len(START))
        if framed is None:
            return None
        if isinstance(framed, _BadFrame):
            return self._error(framed.kind, framed.reason, framed.consumed)
        cls = VEHICLE_BY_PD.get(framed.pd)
        if cls is None:
            return self._error(ErrorKind.UNKNOWN_PD, f"unknown PD 0x{framed.pd:02x}", framed.size)
        try:
            return framed.size, _decode(cls, framed.payload)
        except _Reject as rej:
            return self._error(rej.kind, rej.reason, framed.size)


    def _wrong_length(self) -> tuple[int, FrameError] | None:
        """A bad frame, at once, when the length field disagrees with the structure its PD
        names (:meth:`_StreamParser._length_misfit`), on a line where the answers behind it
        only come once its claimed bytes are read. The parser resumes at the byte after the
        start marker."""
        misfit = self._length_misfit(len(START), VEHICLE_BY_PD)
        if misfit is None:
            return None
        cls, length, size = misfit
        return self._error(ErrorKind.BAD_LENGTH, f"{cls.__name__}: length field {length}, "
                           f"its structure is {size} bytes", 1)


class CommandStreamParser(_StreamParser):
    """What the vehicle receives: AscTec commands and skeye frames -> messages or errors."""

    def feed(self, data: bytes) -> list[CommandEvent]:
        """Add received bytes; return every message, ``CommandError`` or ``FrameError``."""
        return super().feed(data)

    def _command_error(
        self, kind: ErrorKind, pd: int, reason: str, consumed: int
    ) -> tuple[int, CommandError]:
        self.errors[kind] += 1
        return consumed, CommandError(pd, _RESULT_CODE[kind], reason)

    def _step(self) -> tuple[int, Any] | None:
        skip = self._skip_to_marker()
        if skip is not None:
            return skip
        buf = self._buf
        if not START.startswith(bytes(buf[:3])):
            return 1, None  # a lone '>'
        if len(buf) < 4:
            return None
        if buf[3] == SKEYE_START[3]:
            return self._skeye_frame()
        head = bytes(buf[:5])
        incomplete = False
        for prefix, cls in ASCTEC_BY_PREFIX.items():
            if head.startswith(prefix):
                return self._asctec_command(prefix, cls)
            incomplete = incomplete or prefix.startswith(head)
        if incomplete:
            return None
        # Name only the bytes that decided it, so the reason does not depend on chunking.
        if not any(p.startswith(head[:4]) for p in ASCTEC_BY_PREFIX):
            head = head[:4]
        return self._error(ErrorKind.UNKNOWN_PD, f"unknown command {head!r}", 1)

    def _asctec_command(self, prefix: bytes, cls: type[Message]) -> tuple[int, Any] | None:
        layout = LAYOUTS[cls]
        total = len(prefix) + layout.size
        if len(self._buf) < total:
            return None
        try:
            return total, _decode(cls, bytes(self._buf[len(prefix) : total]))
        except _Reject as rej:
            assert layout.pd is not None  # only CTRL_INPUT and WAYPOINT can be rejected
            # A wrong checksum leaves the command's end unconfirmed: rescan from the next byte.
            consumed = 1 if rej.kind is ErrorKind.BAD_CHECKSUM else total
            return self._command_error(rej.kind, layout.pd, rej.reason, consumed)

    def _skeye_frame(self) -> tuple[int, Any] | None:
        wrong = self._wrong_length()
        if wrong is not None:
            return wrong
        framed = _split_frame(self._buf, len(SKEYE_START))
        if framed is None:
            return None
        if isinstance(framed, _BadFrame):
            if framed.kind is ErrorKind.BAD_CRC and framed.pd is not None:
                return self._command_error(framed.kind, framed.pd, framed.reason, framed.consumed)
            return self._error(framed.kind, framed.reason, framed.consumed)
        cls = SKEYE_BY_PD.get(framed.pd)
        if cls is None:
            reason = f"unknown skeye command PD 0x{framed.pd:02x}"
            return self._command_error(ErrorKind.UNKNOWN_PD, framed.pd, reason, framed.size)
        try:
            return framed.size, _decode(cls, framed.payload)
        except _Reject as rej:
            return self._command_error(rej.kind, framed.pd, rej.reason, framed.size)

    def _wrong_length(self) -> tuple[int, CommandError] | None:
        """RESULT BAD_LENGTH, at once, when a skeye frame's length field disagrees with the
        payload its PD names (:meth:`_StreamParser._length_misfit`), as the ground side does
        with the vehicle's structures: every later command (sticks, polls) would otherwise
        wait as the frame's rest. The parser resumes at the byte after the start marker."""
        misfit = self._length_misfit(len(SKEYE_START), SKEYE_BY_PD)
        if misfit is None:
            return None
        cls, length, size = misfit
        self.errors[ErrorKind.BAD_LENGTH] += 1
        reason = f"{cls.__name__}: length field {length}, its payload is {size} bytes"
        pd = self._buf[len(SKEYE_START) + 2]
        return 1, CommandError(pd, ResultCode.BAD_LENGTH, reason, intact=False)
