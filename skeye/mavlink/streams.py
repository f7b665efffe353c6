"""Which telemetry message is due when: the message-interval scheduler, sans-IO.

How this works: every streamed message has a default interval (``DEFAULT_INTERVALS_S``);
MAV_CMD_SET_MESSAGE_INTERVAL changes one (``set_interval``: seconds, ``None`` = stop, ``0`` = back
to the default; a stopped one is in ``stopped``, which also ends what is sent on change) and
``due(now_s)`` returns the message ids whose time has come, each at most once per call, never in
bursts to catch up. Time is an argument. The fastest interval is ``MIN_INTERVAL_S``: faster
requests are refused, not silently slowed.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mav

from skeye.errors import LocalProtocolError

MIN_INTERVAL_S = 0.01  # 100 Hz: the pilot's loop runs at 100 Hz in real time
MAX_INTERVAL_S = 3600.0

DEFAULT_INTERVALS_S: dict[int, float | None] = {
    mav.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    mav.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0,
    mav.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    mav.MAVLINK_MSG_ID_BATTERY_STATUS: 1.0,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    mav.MAVLINK_MSG_ID_ATTITUDE: 0.05,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 0.1,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0.1,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 0.1,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: 0.2,
    mav.MAVLINK_MSG_ID_ALTITUDE: 0.1,
    mav.MAVLINK_MSG_ID_VFR_HUD: 0.25,
    mav.MAVLINK_MSG_ID_HOME_POSITION: 2.0,
    mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: None,  # on request, and when it moves (the vehicle)
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
    mav.MAVLINK_MSG_ID_HIGHRES_IMU: None,  # on request (the companion airframe asks for it)
    mav.MAVLINK_MSG_ID_SCALED_PRESSURE: None,
}
"""Streamed by default at these intervals (s): attitude at 20 Hz, positions at 10 Hz, status at
1 Hz, as a ground station's instruments and a MAVSDK script expect; ``None`` = only on request."""


class MessageScheduler:
    """Per link: the interval of each streamed message and when it is next due."""

    def __init__(self, now_s: float = 0.0) -> None:
        self.intervals_s: dict[int, float | None] = dict(DEFAULT_INTERVALS_S)
        self.stopped: set[int] = set()  # set to None (-1): not even sent when it changes
        self._next_s: dict[int, float] = {m: now_s for m in self.intervals_s}

    def streamable(self, msg_id: int) -> bool:
        return msg_id in self.intervals_s

    def set_interval(self, msg_id: int, interval_s: float | None, now_s: float) -> None:
        """Stream ``msg_id`` every ``interval_s`` (None: stop; 0: its default).

        Raises:
            LocalProtocolError: a message this vehicle does not stream, or an interval out of
                range (the caller answers it with a refusal naming this).
        """
        if msg_id not in self.intervals_s:
            raise LocalProtocolError(f"message {msg_id} is not streamed by this vehicle")
        stop = interval_s is None  # (the default of one sent only on request is None too)
        if interval_s is not None and interval_s == 0:
            interval_s = DEFAULT_INTERVALS_S[msg_id]
        elif interval_s is not None and not (
            math.isfinite(interval_s) and MIN_INTERVAL_S - 1e-9 <= interval_s <= MAX_INTERVAL_S
        ):
            raise LocalProtocolError(
                f"interval {interval_s:g} s out of range ({MIN_INTERVAL_S:g}..{MAX_INTERVAL_S:g})")
        self.intervals_s[msg_id] = interval_s
        self._next_s[msg_id] = now_s
        if stop:
            self.stopped.add(msg_id)
        else:
            self.stopped.discard(msg_id)

    def interval_s(self, msg_id: int) -> float | None:
        return self.intervals_s.get(msg_id)

    def due(self, now_s: float) -> list[int]:
        """The messages to send now (each scheduled one interval on, without catching up)."""
        out = []
        for msg_id, interval in self.intervals_s.items():
            if interval is None or now_s < self._next_s[msg_id]:
                continue
            out.append(msg_id)
            nxt = self._next_s[msg_id] + interval
            self._next_s[msg_id] = nxt if nxt > now_s else now_s + interval
        return out
