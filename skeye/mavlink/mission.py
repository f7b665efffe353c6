"""The MAVLink mission protocol, vehicle side, sans-IO: upload, download, clear.

How this works: :class:`MissionProtocol` takes MISSION_* messages and the time and returns the
messages to send. An upload (MISSION_COUNT) is pulled item by item with MISSION_REQUEST_INT,
re-requested after ``item_timeout_s`` (``tick``), given up after ``retries``; the re-requests
and the cancellation are for the uploading station alone (``upload_route``: where its
MISSION_COUNT came from, as the caller gave it), as PX4 and ArduPilot address the partner of a
transfer. One upload at a
time: another peer's MISSION_COUNT meanwhile is refused (MAV_MISSION_ERROR, as PX4 answers
"busy"); the same peer's starts it again. Each item is checked as it arrives
(:func:`basic_problem`, then the vehicle's own ``check``: envelope, supported commands) and the
first bad one ends the upload with MISSION_ACK naming the error class (and ``rejections`` says
why); the stored mission changes only when every item was good. The last item sent again by the
station that uploaded it, while that mission is still the one stored, gets the MISSION_ACK again
(its station did not get the first: a lost ACK), as PX4 answers; any other item nobody asked for
is ignored.
A download (MISSION_REQUEST_LIST) answers MISSION_COUNT and each MISSION_REQUEST_INT with
MISSION_ITEM_INT, each deprecated MISSION_REQUEST with the float MISSION_ITEM its definition asks
for (as PX4 answers). MISSION_CLEAR_ALL clears the mission for the type MISSION or ALL (every
type).
Fence and rally lists are empty and cannot be uploaded (MAV_MISSION_UNSUPPORTED).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mav

from skeye.mavlink.codec import MavCodec, MavMessage

MAX_ITEMS = 500
GLOBAL_FRAMES = (mav.MAV_FRAME_GLOBAL_INT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                 mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT)
RELATIVE_FRAMES = (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT)
INT_FRAME = {mav.MAV_FRAME_GLOBAL: mav.MAV_FRAME_GLOBAL_INT,
             mav.MAV_FRAME_GLOBAL_RELATIVE_ALT: mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT}
FLOAT_FRAME = {i: f for f, i in INT_FRAME.items()}  # a stored item's frame in MISSION_ITEM
NAV_WITH_POSITION = (mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_CMD_NAV_LAND,
                     mav.MAV_CMD_NAV_LOITER_TIME)
DEFAULT_SPEED = (-1.0, -2.0)
"""DO_CHANGE_SPEED's p2 for the cruise speed again: -2 ("return to default vehicle speed", the
command's definition) and -1 (PX4 resets on any speed not above 0)."""
SUPPORTED = (*NAV_WITH_POSITION, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, mav.MAV_CMD_DO_CHANGE_SPEED,
             mav.MAV_CMD_NAV_DELAY)


@dataclass(frozen=True)
class MissionItem:
    """One stored item (MISSION_ITEM_INT's fields; x/y in degrees x 1e7 for global frames)."""

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float

    @property
    def latitude_deg(self) -> float:
        return self.x / 1e7

    @property
    def longitude_deg(self) -> float:
        return self.y / 1e7

    @property
    def relative_alt(self) -> bool:
        return self.frame in RELATIVE_FRAMES

    @classmethod
    def from_message(cls, msg: MavMessage) -> MissionItem:
        """From MISSION_ITEM_INT, or the deprecated float MISSION_ITEM."""
        x, y = msg.x, msg.y
        if msg.get_type() == "MISSION_ITEM":
            frame = int(msg.frame)
            scale = 1e7 if frame in GLOBAL_FRAMES else 1.0
            x = _int32(float(x) * scale)
            y = _int32(float(y) * scale)
            frame = INT_FRAME.get(frame, frame)
        else:
            frame = int(msg.frame)
        return cls(int(msg.seq), frame, int(msg.command), int(msg.current),
                   int(msg.autocontinue), float(msg.param1), float(msg.param2),
                   float(msg.param3), float(msg.param4), int(x), int(y), float(msg.z))

    def float_xy(self) -> tuple[float, float]:
        """x, y as MISSION_ITEM carries them: degrees in a global frame (float32 on the wire:
        about 4e-6 deg, 0.4 m, at 49 deg), else as stored."""
        scale = 1e7 if self.frame in GLOBAL_FRAMES else 1.0
        return self.x / scale, self.y / scale


def _int32(value: float) -> int:
    if not math.isfinite(value) or abs(value) >= 2**31:
        return 2**31 - 1  # out of any range: basic_problem refuses it
    return round(value)


def basic_problem(item: MissionItem) -> tuple[int, str] | None:
    """What is wrong with an item whatever the vehicle: (MAV_MISSION_RESULT, reason) or None."""
    if item.command not in SUPPORTED:
        return (mav.MAV_MISSION_UNSUPPORTED,
                f"item {item.seq}: command {item.command} is not supported by this vehicle")
    if item.command in NAV_WITH_POSITION:
        if item.frame not in GLOBAL_FRAMES:
            return (mav.MAV_MISSION_UNSUPPORTED_FRAME,
                    f"item {item.seq}: frame {item.frame}: give a global frame "
                    "(GLOBAL_INT or GLOBAL_RELATIVE_ALT_INT)")
        if not -90e7 <= item.x <= 90e7:
            return mav.MAV_MISSION_INVALID_PARAM5_X, f"item {item.seq}: latitude out of range"
        if not -180e7 <= item.y <= 180e7:
            return mav.MAV_MISSION_INVALID_PARAM6_Y, f"item {item.seq}: longitude out of range"
        if not math.isfinite(item.z):
            return mav.MAV_MISSION_INVALID_PARAM7, f"item {item.seq}: altitude is not a number"
    for n, p in enumerate((item.param1, item.param2, item.param3), start=1):
        if math.isinf(p):
            return (getattr(mav, f"MAV_MISSION_INVALID_PARAM{n}"),
                    f"item {item.seq}: param{n} is infinite")
    if item.command == mav.MAV_CMD_DO_CHANGE_SPEED and not (
        math.isfinite(item.param2) and (item.param2 in DEFAULT_SPEED or item.param2 > 0)
    ):
        return mav.MAV_MISSION_INVALID_PARAM2, f"item {item.seq}: speed {item.param2} m/s"
    if item.command in (mav.MAV_CMD_NAV_LOITER_TIME, mav.MAV_CMD_NAV_DELAY) and not (
        math.isfinite(item.param1) and 0 <= item.param1 <= 3600
    ):
        return mav.MAV_MISSION_INVALID_PARAM1, f"item {item.seq}: wait {item.param1} s"
    return None


@dataclass
class _Upload:
    peer: tuple[int, int]
    count: int
    items: list[MissionItem]
    requested_s: float
    retries_left: int
    route: Hashable  # where the uploading station is (the caller's link and address)


class MissionProtocol:
    """The stored mission and the transfers in progress (one upload at a time)."""

    def __init__(
        self,
        codec: MavCodec,
        check: Callable[[MissionItem], tuple[int, str] | None] | None = None,
        *,
        max_items: int = MAX_ITEMS,
        item_timeout_s: float = 1.0,
        retries: int = 5,
    ) -> None:
        self.codec = codec
        self.check = check
        self.max_items = max_items
        self.item_timeout_s = item_timeout_s
        self.retries = retries
        self.items: list[MissionItem] = []
        self.version = 0  # bumped by every change of the stored mission
        self.rejections: list[str] = []  # why uploads were refused (newest last)
        self._upload: _Upload | None = None
        # the last upload done: its station, last item and the mission version it stored
        self._done: tuple[tuple[int, int], int, int] | None = None

    def _ack(self, peer: tuple[int, int], result: int, mission_type: int = 0) -> MavMessage:
        return self.codec.mav.mission_ack_encode(peer[0], peer[1], result, mission_type)

    def _request(self, up: _Upload) -> MavMessage:
        return self.codec.mav.mission_request_int_encode(
            up.peer[0], up.peer[1], len(up.items), mav.MAV_MISSION_TYPE_MISSION)

    def _refuse(self, reason: str) -> None:
        self.rejections = [*self.rejections[-19:], reason]

    @property
    def upload_route(self) -> Hashable:
        """Where the station doing an upload is (``route`` of its MISSION_COUNT), or None when
        no upload is under way: ``tick``'s messages are for it alone."""
        return None if self._upload is None else self._upload.route

    def handle(self, msg: MavMessage, now_s: float, route: Hashable = None) -> list[MavMessage]:
        """Answer one MISSION_* message from ``(msg.get_srcSystem(), msg.get_srcComponent())``,
        which came by ``route`` (the caller's link and address: kept for an upload's
        re-requests)."""
        kind = msg.get_type()
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        mission_type = int(getattr(msg, "mission_type", 0))
        if kind == "MISSION_COUNT":
            if mission_type != mav.MAV_MISSION_TYPE_MISSION:
                self._refuse(f"mission type {mission_type} (fence, rally) is not supported")
                return [self._ack(peer, mav.MAV_MISSION_UNSUPPORTED, mission_type)]
            busy = self._upload
            if busy is not None and busy.peer != peer:
                self._refuse(f"an upload from {busy.peer[0]}/{busy.peer[1]} is under way (item "
                             f"{len(busy.items)} of {busy.count}): try again when it ends")
                return [self._ack(peer, mav.MAV_MISSION_ERROR)]
            count = int(msg.count)
            if count > self.max_items:
                self._refuse(f"{count} items: this vehicle stores at most {self.max_items}")
                return [self._ack(peer, mav.MAV_MISSION_NO_SPACE)]
            if count == 0:
                self._store([])
                self._upload = None
                return [self._ack(peer, mav.MAV_MISSION_ACCEPTED)]
            self._upload = _Upload(peer, count, [], now_s, self.retries, route)
            return [self._request(self._upload)]
        if kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            up = self._upload
            if up is None and mission_type == mav.MAV_MISSION_TYPE_MISSION and self._done == (
                    peer, int(msg.seq), self.version):
                # the last item again: the station did not get the MISSION_ACK (PX4 answers so)
                return [self._ack(peer, mav.MAV_MISSION_ACCEPTED)]
            if up is None or peer != up.peer or mission_type != mav.MAV_MISSION_TYPE_MISSION:
                return []  # not asked for: ignored (a late duplicate, another station)
            item = MissionItem.from_message(msg)
            if item.seq != len(up.items):
                return [self._request(up)] if item.seq > len(up.items) else []
            problem = basic_problem(item) or (self.check(item) if self.check else None)
            if problem is not None:
                self._upload = None
                self._refuse(problem[1])
                return [self._ack(peer, problem[0])]
            up.items.append(item)
            up.requested_s = now_s
            up.retries_left = self.retries
            if len(up.items) < up.count:
                return [self._request(up)]
            self._upload = None
            self._store(up.items)
            self._done = (peer, item.seq, self.version)
            return [self._ack(peer, mav.MAV_MISSION_ACCEPTED)]
        if kind == "MISSION_REQUEST_LIST":
            count = len(self.items) if mission_type == mav.MAV_MISSION_TYPE_MISSION else 0
            return [self.codec.mav.mission_count_encode(peer[0], peer[1], count, mission_type)]
        if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            seq = int(msg.seq)
            if mission_type != mav.MAV_MISSION_TYPE_MISSION or not 0 <= seq < len(self.items):
                return [self._ack(peer, mav.MAV_MISSION_INVALID_SEQUENCE, mission_type)]
            it = self.items[seq]
            if kind == "MISSION_REQUEST":  # the deprecated float form asks for MISSION_ITEM
                return [self.codec.mav.mission_item_encode(
                    peer[0], peer[1], it.seq, FLOAT_FRAME.get(it.frame, it.frame), it.command,
                    it.current, it.autocontinue, it.param1, it.param2, it.param3, it.param4,
                    *it.float_xy(), it.z, mav.MAV_MISSION_TYPE_MISSION)]
            return [self.codec.mav.mission_item_int_encode(
                peer[0], peer[1], it.seq, it.frame, it.command, it.current, it.autocontinue,
                it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z,
                mav.MAV_MISSION_TYPE_MISSION)]
        if kind == "MISSION_CLEAR_ALL":
            # ALL (255) clears every type, the mission among them (the fence and rally lists
            # are always empty here)
            if mission_type in (mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_ALL):
                self._store([])
            return [self._ack(peer, mav.MAV_MISSION_ACCEPTED, mission_type)]
        return []  # MISSION_ACK from a downloading client: nothing to do

    def _store(self, items: list[MissionItem]) -> None:
        self.items = list(items)
        self.version += 1

    def tick(self, now_s: float) -> list[MavMessage]:
        """Re-request an item that has not come; give up after the retries (both for the
        uploading station alone: ``upload_route`` before this call says where it is)."""
        up = self._upload
        if up is None or now_s - up.requested_s < self.item_timeout_s:
            return []
        if up.retries_left <= 0:
            self._upload = None
            self._refuse(f"upload from {up.peer[0]}/{up.peer[1]} timed out at item "
                         f"{len(up.items)}")
            return [self._ack(up.peer, mav.MAV_MISSION_OPERATION_CANCELLED)]
        up.retries_left -= 1
        up.requested_s = now_s
        return [self._request(up)]
