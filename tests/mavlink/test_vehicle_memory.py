"""The vehicle's two memories of ground stations, the answers kept for the repeat rule and the
times of the rate-limited notices, are bounded without forgetting a live station: each forgets
what can no longer matter, oldest first. Both were once cleared whole when full, so a take-off
resent just after other stations had filled the memory was run again, and a refusal's notice
was repeated inside its rate limit."""

from __future__ import annotations

import math
from collections.abc import Hashable
from typing import Any

from pymavlink import mavutil

from skeye.mavlink.codec import MavCodec, MavParser
from skeye.pilot import mavlink_vehicle
from skeye.pilot.boards import OnboardBoards
from skeye.pilot.mavlink_vehicle import COMMANDS_KEPT, NOTICES_KEPT, MavlinkVehicle
from tests.pilot.fake_airframe import FakeAirframe

M = mavutil.mavlink
A: Hashable = ("127.0.0.1", 1)
UNSUPPORTED = M.MAV_CMD_USER_1  # a command id the vehicle does not run: answered, and noticed


class Stations:
    """Ground stations on one link of a vehicle core, one codec and parser per peer."""

    def __init__(self) -> None:
        self.airframe = FakeAirframe()
        self.vehicle = MavlinkVehicle(OnboardBoards(self.airframe))
        self.vehicle.add_link(0.0)
        self._codecs: dict[Hashable, tuple[MavCodec, MavParser]] = {}

    def command(self, peer: Hashable, command: int, *params: float,
                now_s: float) -> tuple[int, list[str]]:
        """COMMAND_LONG from ``peer``: its ACK's result and the STATUSTEXTs sent with it."""
        if peer not in self._codecs:
            self._codecs[peer] = (MavCodec(255, 190), MavParser())
        codec, parser = self._codecs[peer]
        msg = codec.mav.command_long_encode(1, 1, command, 0, *(list(params) + [0.0] * 7)[:7])
        out: list[Any] = []
        for decoded in parser.feed(codec.encode(msg), datagram=True):
            out += self.vehicle.handle(0, peer, decoded, now_s)
        acks = [o.msg.result for o in out if o.msg.get_type() == "COMMAND_ACK"]
        assert len(acks) == 1, out
        return acks[0], [o.msg.text for o in out if o.msg.get_type() == "STATUSTEXT"]


def _other(i: int) -> Hashable:
    return ("127.0.0.1", 10_000 + i)


def test_a_resent_take_off_is_answered_again_after_stale_commands_filled_the_memory():
    assert UNSUPPORTED not in mavlink_vehicle.COMMANDS
    gcs = Stations()
    for i in range(COMMANDS_KEPT - 2):  # stations long gone, each answered once at t = 1 s
        assert gcs.command(_other(i), UNSUPPORTED, now_s=1.0)[0] == M.MAV_RESULT_UNSUPPORTED
    assert gcs.command(A, M.MAV_CMD_COMPONENT_ARM_DISARM, 1, now_s=10.0)[0] == 0
    take_off = (M.MAV_CMD_NAV_TAKEOFF, *[0.0] * 6, math.nan)
    assert gcs.command(A, *take_off, now_s=10.0)[0] == M.MAV_RESULT_ACCEPTED
    # Two more stations' commands: over the memory's size (where it was cleared whole)
    for i in (COMMANDS_KEPT, COMMANDS_KEPT + 1):
        gcs.command(_other(i), UNSUPPORTED, now_s=10.1)
    # A's take-off again within the resend window, its ACK lost: the same answer, run once
    assert gcs.command(A, *take_off, now_s=10.2)[0] == M.MAV_RESULT_ACCEPTED
    assert gcs.airframe.names().count("take_off") == 1, gcs.airframe.calls


def test_a_flood_of_stations_within_the_windows_keeps_both_memories_bounded():
    gcs = Stations()
    for i in range(3 * COMMANDS_KEPT):  # within the 1 s resend window
        gcs.command(_other(i), UNSUPPORTED, now_s=1.0 + i * 1e-4)
    assert len(gcs.vehicle._recent) == COMMANDS_KEPT
    for i in range(3 * NOTICES_KEPT):  # within the notices' 2 s, each a refusal told once
        assert gcs.command(_other(i), UNSUPPORTED, now_s=5.0)[1]
    assert len(gcs.vehicle._notices) == NOTICES_KEPT


def test_a_refusals_notice_stays_limited_after_stale_notices_filled_the_memory():
    gcs = Stations()
    for i in range(NOTICES_KEPT - 1):  # stations long gone, each told once at t = 1 s
        assert gcs.command(_other(i), UNSUPPORTED, now_s=1.0)[1]
    told = gcs.command(A, UNSUPPORTED, now_s=10.0)[1]
    assert told and "not supported" in told[0], told
    for i in (NOTICES_KEPT, NOTICES_KEPT + 1):  # over the memory's size
        gcs.command(_other(i), UNSUPPORTED, now_s=10.5)
    # A's same refusal again 1.5 s later (a new command: past the 1 s resend window), within
    # the notices' 2 s: answered, and not told again
    assert mavlink_vehicle.DUPLICATE_WINDOW_S < 1.5 < mavlink_vehicle.NOTICE_EVERY_S
    assert gcs.command(A, UNSUPPORTED, now_s=11.5) == (M.MAV_RESULT_UNSUPPORTED, [])
