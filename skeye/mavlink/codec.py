"""MAVLink 2 frames to messages and back, through pymavlink's common dialect.

How this works: :class:`MavCodec` owns one pymavlink ``MAVLink`` object per direction it is
used for: ``encode`` packs a message with this system's ids and its own sequence numbers;
:class:`MavParser` is one peer's receive state (a frame may arrive cut anywhere), whose
``feed`` returns decoded messages and :class:`BadFrame` items, never raising: pymavlink's
robust parsing turns a bad CRC, an unknown message id or garbage into ``MAVLink_bad_data``,
which becomes a ``BadFrame`` with its reason. The dialect module is ``dialect`` (message
classes, enums and ``MAVLINK_MSG_ID_*``).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as dialect

from skeye.errors import LocalProtocolError

MavMessage = Any  # a pymavlink MAVLink_message (the dialect's classes are not typed)

GCS_COMPONENTS = range(190, 200)  # MAV_COMP_ID_MISSIONPLANNER .. (QGC 190, MAVSDK 190)
MAX_STATUSTEXT = 50  # STATUSTEXT's text field, bytes
MAX_STATUSTEXT_CHUNKS = 8  # the most chunks one long STATUSTEXT is sent in


@dataclass(frozen=True)
class BadFrame:
    """Bytes that were not a message of the dialect: a bad CRC, an unknown id, garbage."""

    reason: str
    size: int
    msg_id: int | None = None  # when the header named one


class MavParser:
    """One peer's receive side: bytes in, messages (or ``BadFrame``) out; never raises."""

    def __init__(self) -> None:
        self._reset()
        self.bad = 0  # bad frames seen

    def _reset(self) -> None:
        self._mav = dialect.MAVLink(None, srcSystem=0, srcComponent=0)
        self._mav.robust_parsing = True

    def feed(self, data: bytes, *, datagram: bool = False) -> list[MavMessage | BadFrame]:
        """Messages in ``data``. ``datagram``: ``data`` is one UDP datagram, which holds whole
        frames only: a frame left unfinished at its end is bad, and the next datagram starts
        afresh (else a garbage length could swallow the next datagram's real frames)."""
        out = self._feed(data)
        if datagram and self._mav.buf_len() > 0:
            self.bad += 1
            out.append(BadFrame("a frame cut short at the datagram's end", self._mav.buf_len()))
            self._reset()
        return out

    def _feed(self, data: bytes) -> list[MavMessage | BadFrame]:
        out: list[MavMessage | BadFrame] = []
        try:
            msgs = self._mav.parse_buffer(data) or []
        except Exception as exc:  # pymavlink raises a few plain errors even when robust
            self._reset()
            self.bad += 1
            return [BadFrame(f"unreadable frame: {exc}", len(data))]
        for msg in msgs:
            if isinstance(msg, dialect.MAVLink_unknown):  # a frame of another dialect
                self.bad += 1
                msg_id = int(msg.get_type().rsplit("_", 1)[-1])  # "UNKNOWN_60000"
                out.append(BadFrame(f"unknown MAVLink message ID {msg_id}",
                                    len(msg.get_msgbuf()), msg_id))
            elif msg.get_type() == "BAD_DATA":
                self.bad += 1
                reason = str(getattr(msg, "reason", "bad data"))
                out.append(BadFrame(reason, len(msg.get_msgbuf()), _msg_id_in(reason)))
            else:
                out.append(msg)
        return out


def _msg_id_in(reason: str) -> int | None:
    """The message id an 'unknown MAVLink message ID 12345' reason names."""
    if "unknown MAVLink message ID" not in reason:
        return None
    digits = "".join(c for c in reason.rsplit("ID", 1)[-1] if c.isdigit())
    return int(digits) if digits else None


class MavCodec:
    """Encode messages as this system/component (sequence numbers kept here)."""

    def __init__(self, system_id: int = 1, component_id: int = 1) -> None:
        if not (1 <= system_id <= 255 and 0 <= component_id <= 255):
            raise LocalProtocolError(f"MAVLink ids out of range: {system_id}/{component_id}")
        self.system_id = system_id
        self.component_id = component_id
        self._mav = dialect.MAVLink(None, srcSystem=system_id, srcComponent=component_id)

    @property
    def mav(self) -> Any:
        """The pymavlink object whose ``*_encode`` methods build messages."""
        return self._mav

    def encode(self, msg: MavMessage) -> bytes:
        """One MAVLink 2 frame."""
        return bytes(msg.pack(self._mav))


def statustext(codec: MavCodec, severity: int, text: str) -> list[MavMessage]:
    """STATUSTEXT message(s): text over 50 bytes goes in chunks with one id (MAVLink 2).

    A receiver knows the last chunk by the NUL in it (a text shorter than 50 bytes); a text
    that is a whole number of chunks long gets an empty chunk after it to say so. At most
    ``MAX_STATUSTEXT_CHUNKS`` chunks go, so a longer text is cut first (at a character) to
    the most they carry with the last one short: 7 * 50 + 49 = 399 bytes."""
    data = text.encode("utf-8", "replace")
    if len(data) <= MAX_STATUSTEXT:
        return [codec.mav.statustext_encode(severity, data)]
    ident = (zlib.crc32(data) & 0xFFFE) + 1
    most = MAX_STATUSTEXT_CHUNKS * MAX_STATUSTEXT - 1
    if len(data) > most:  # a character cut in two is left out whole
        data = data[:most].decode("utf-8", "ignore").encode("utf-8")
    chunks = [data[i:i + MAX_STATUSTEXT] for i in range(0, len(data), MAX_STATUSTEXT)]
    if len(data) % MAX_STATUSTEXT == 0:
        chunks.append(b"")  # at most 7 full chunks here: the empty one is the 8th at most
    return [codec.mav.statustext_encode(severity, chunk, ident, n)
            for n, chunk in enumerate(chunks)]
