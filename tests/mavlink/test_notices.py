"""The vehicle's refusal notices (STATUSTEXT) are limited per ground station, not for all: with
two stations, each is told why its own message was refused, even when the other's was refused
for the same reason a moment before (the offboard setpoint's notice was once limited for all
stations together, so the second heard nothing for 2 s)."""

from __future__ import annotations

import math
from collections.abc import Hashable
from typing import Any

from pymavlink import mavutil

from skeye.mavlink.codec import MavCodec, MavParser
from skeye.pilot.boards import OnboardBoards
from skeye.pilot.mavlink_vehicle import MavlinkVehicle
from tests.pilot.fake_airframe import FakeAirframe

M = mavutil.mavlink
A: Hashable = ("127.0.0.1", 1)
B: Hashable = ("127.0.0.1", 2)


class Stations:
    """Two ground stations (255/190 and 254/190) on one link of a vehicle core."""

    def __init__(self, vehicle: MavlinkVehicle) -> None:
        self.vehicle = vehicle
        self.codecs = {A: MavCodec(255, 190), B: MavCodec(254, 190)}
        self.parsers = {A: MavParser(), B: MavParser()}

    def send(self, peer: Hashable, msg: Any, now_s: float) -> list[Any]:
        out = []
        for decoded in self.parsers[peer].feed(self.codecs[peer].encode(msg), datagram=True):
            out += self.vehicle.handle(0, peer, decoded, now_s)
        return out

    def command(self, peer: Hashable, command: int, *params: float, now_s: float) -> int:
        msg = self.codecs[peer].mav.command_long_encode(1, 1, command, 0,
                                                        *(list(params) + [0.0] * 7)[:7])
        acks = [o.msg.result for o in self.send(peer, msg, now_s)
                if o.msg.get_type() == "COMMAND_ACK"]
        assert len(acks) == 1, acks
        return acks[0]

    def setpoint(self, peer: Hashable, north_m: float, now_s: float) -> list[Any]:
        msg = self.codecs[peer].mav.set_position_target_local_ned_encode(
            0, 1, 1, M.MAV_FRAME_LOCAL_NED, 0b110111111000, north_m, 0.0, -2.0,
            0, 0, 0, 0, 0, 0, 0, 0)
        return self.send(peer, msg, now_s)


def test_each_station_is_told_its_offboard_setpoint_is_refused():
    airframe = FakeAirframe()
    boards = OnboardBoards(airframe)
    vehicle = MavlinkVehicle(boards)
    vehicle.add_link(0.0)
    gcs = Stations(vehicle)
    assert gcs.command(A, M.MAV_CMD_COMPONENT_ARM_DISARM, 1, now_s=1.0) == M.MAV_RESULT_ACCEPTED
    assert gcs.command(A, M.MAV_CMD_NAV_TAKEOFF, *[0.0] * 6, math.nan,
                       now_s=1.0) == M.MAV_RESULT_ACCEPTED
    airframe.finish(landed=False, pos_ned_m=(0.0, 0.0, -2.0))
    boards.tick(1.5)
    vehicle.tick(1.5)
    gcs.setpoint(A, 0.0, 2.0)
    assert gcs.command(A, M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 6,
                       now_s=2.1) == M.MAV_RESULT_ACCEPTED  # PX4's OFFBOARD
    for peer, now_s in ((A, 2.5), (B, 2.6)):  # the same refusal, 0.1 s apart
        told = [o for o in gcs.setpoint(peer, math.nan, now_s) if o.msg.get_type() == "STATUSTEXT"]
        assert told and all(o.peer == peer for o in told), (peer, told)
        assert told[0].msg.text.startswith("offboard setpoint refused: position setpoint")


def _offboard(peer: Hashable = A) -> tuple[FakeAirframe, Stations]:
    """A vehicle core flying 2 m up at (1, 2) north/east, in Offboard."""
    airframe = FakeAirframe()
    boards = OnboardBoards(airframe)
    vehicle = MavlinkVehicle(boards)
    vehicle.add_link(0.0)
    gcs = Stations(vehicle)
    assert gcs.command(peer, M.MAV_CMD_COMPONENT_ARM_DISARM, 1, now_s=1.0) == 0
    assert gcs.command(peer, M.MAV_CMD_NAV_TAKEOFF, *[0.0] * 6, math.nan, now_s=1.0) == 0
    airframe.finish(landed=False, pos_ned_m=(1.0, 2.0, -2.0))
    boards.tick(1.5)
    vehicle.tick(1.5)
    gcs.setpoint(peer, 1.0, 2.0)
    assert gcs.command(peer, M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 6,
                       now_s=2.1) == M.MAV_RESULT_ACCEPTED  # PX4's OFFBOARD
    return airframe, gcs


def test_a_position_axis_ignored_in_the_type_mask_keeps_the_vehicles_own():
    """x and y given, z ignored (its field 0, as a client that does not use it sends it): the
    target was z = 0, the ground, so the vehicle descended into it; now it keeps its height.
    So with y ignored in an offset frame (no sideways step)."""
    airframe, gcs = _offboard()
    xy_only = 0b110111111100  # velocity, acceleration, yaw and z ignored
    for frame, x, y, expected in ((M.MAV_FRAME_LOCAL_NED, 5.0, 3.0, (5.0, 3.0, 2.0)),
                                  (M.MAV_FRAME_LOCAL_OFFSET_NED, 1.0, 0.0, (2.0, 2.0, 2.0))):
        mask = xy_only | (0b010 if frame == M.MAV_FRAME_LOCAL_OFFSET_NED else 0)
        msg = gcs.codecs[A].mav.set_position_target_local_ned_encode(
            0, 1, 1, frame, mask, x, 99.0 if mask & 0b010 else y, 0.0, 0, 0, 0, 0, 0, 0, 0, 0)
        gcs.send(A, msg, 2.5)
        name, args = airframe.calls[-1]
        assert name == "fly_to" and args[:3] == expected, airframe.calls[-3:]


def test_a_waypoint_here_flies_to_its_altitude():
    """A NAV_WAYPOINT at 0/0 ("here") flew to where the vehicle was, its altitude ignored (and
    the envelope's ceiling was not checked for it): now it climbs to its z, above home."""
    airframe, gcs = _offboard()
    vehicle = gcs.vehicle
    mav = gcs.codecs[A].mav
    for z_m, accepted in ((5.0, True), (1e4, False)):  # 10 km: over the envelope's ceiling
        out = gcs.send(A, mav.mission_count_encode(1, 1, 1, M.MAV_MISSION_TYPE_MISSION), 3.0)
        assert [o.msg.get_type() for o in out] == ["MISSION_REQUEST_INT"], out
        item = mav.mission_item_int_encode(
            1, 1, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_WAYPOINT, 0, 1,
            0, 0.5, 0, math.nan, 0, 0, z_m, M.MAV_MISSION_TYPE_MISSION)
        ack = next(o.msg for o in gcs.send(A, item, 3.1) if o.msg.get_type() == "MISSION_ACK")
        assert (ack.type == M.MAV_MISSION_ACCEPTED) == accepted, ack
    assert gcs.command(A, M.MAV_CMD_MISSION_START, 0, 0, now_s=3.2) == 0
    vehicle.tick(3.3)
    name, args = airframe.calls[-1]
    assert name == "fly_to" and args[:3] == (1.0, 2.0, 5.0), airframe.calls[-3:]


def test_a_global_setpoint_with_its_altitude_ignored_keeps_the_vehicles_height() -> None:
    """SET_POSITION_TARGET_GLOBAL_INT with alt ignored (its field 0, mean sea level) flies to
    the latitude and longitude at the vehicle's own height."""
    airframe, gcs = _offboard()
    origin = gcs.vehicle.origin()
    assert origin is not None  # the scripted airframe has a GPS fix
    for frame in (M.MAV_FRAME_GLOBAL_INT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
        msg = gcs.codecs[A].mav.set_position_target_global_int_encode(
            0, 1, 1, frame, 0b110111111000 | 0b100, round(origin.latitude_deg * 1e7),
            round(origin.longitude_deg * 1e7), 0.0, 0, 0, 0, 0, 0, 0, 0, 0)
        gcs.send(A, msg, 2.5)
        name, args = airframe.calls[-1]
        assert name == "fly_to" and args[2] == 2.0, airframe.calls[-3:]  # 2 m up, as it was
        assert abs(args[0]) < 0.02 and abs(args[1]) < 0.02  # the origin, to the degE7 rounding
