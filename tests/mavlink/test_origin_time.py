"""GPS_GLOBAL_ORIGIN and SYSTEM_TIME, as PX4 sends them.

GPS_GLOBAL_ORIGIN is the geodetic position of LOCAL_POSITION_NED's origin: sent when first known
and when it moves, and on MAV_CMD_REQUEST_MESSAGE; the origin plus a LOCAL_POSITION_NED is that
moment's GLOBAL_POSITION_INT. SYSTEM_TIME's ``time_boot_ms`` is the other messages' clock (sim
time); its ``time_unix_usec`` is the host's wall clock, also in lockstep where the two differ."""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

from pymavlink import mavutil

from skeye.geo import GeoOrigin
from skeye.mavlink.codec import MavCodec, MavParser
from skeye.pilot.airframe import GpsFix
from skeye.pilot.boards import OnboardBoards
from skeye.pilot.mavlink_vehicle import MavlinkVehicle
from tests.mavlink.conftest import command, mav_vehicle, wait_for
from tests.pilot.fake_airframe import FakeAirframe

M = mavutil.mavlink


def _origins(vehicle: MavlinkVehicle, now_s: float) -> list[tuple[int, int, int]]:
    return [(o.msg.latitude, o.msg.longitude, o.msg.altitude) for o in vehicle.tick(now_s)
            if o.msg.get_type() == "GPS_GLOBAL_ORIGIN"]


def test_the_origin_is_sent_once_when_known_and_again_only_when_it_moves():
    airframe = FakeAirframe()
    fix = airframe.snap.gps
    airframe.snap = replace(airframe.snap, gps=GpsFix(False, 0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0)))
    boards = OnboardBoards(airframe)
    vehicle = MavlinkVehicle(boards)
    vehicle.add_link(0.0)
    assert _origins(vehicle, 0.0) == []  # no GPS fix: no origin
    airframe.snap = replace(airframe.snap, gps=fix, time_s=1.0)
    boards.tick(1.0)
    assert _origins(vehicle, 1.0) == [(490_000_000, 80_000_000, 100_000)]
    assert _origins(vehicle, 2.0) == _origins(vehicle, 3.0) == []  # unchanged: not again
    moved = replace(fix, latitude_deg=49.000001, altitude_m=101.0)  # a second fix, 11 cm on
    airframe.snap = replace(airframe.snap, gps=moved, time_s=4.0)
    boards.tick(4.0)
    assert _origins(vehicle, 4.0) == [(490_000_005, 80_000_000, 100_500)]  # the mean of two


def _geodetic_error_m(origin: Any, local: Any, glob: Any) -> tuple[float, float]:
    """(horizontal, vertical) distance between origin + local and the global position, m."""
    geo = GeoOrigin(origin.latitude / 1e7, origin.longitude / 1e7, origin.altitude / 1e3)
    lat, lon, alt = geo.to_geodetic(local.x, local.y, local.z)
    north_m = (glob.lat / 1e7 - lat) * 111_200.0
    east_m = (glob.lon / 1e7 - lon) * 111_200.0 * math.cos(math.radians(lat))
    return math.hypot(north_m, east_m), abs(glob.alt / 1e3 - alt)


def test_origin_plus_local_position_is_the_global_position():
    with mav_vehicle(start="Field1") as v:  # 3 m north of the world's origin
        conn = v.client()
        told = wait_for(conn, "GPS_GLOBAL_ORIGIN")  # unasked, once a fix gives it
        assert abs(told.latitude / 1e7 - 50.8123) < 1e-3  # the pad world's origin (GPS: metres)
        assert command(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == (0, "")
        assert command(conn, M.MAV_CMD_NAV_TAKEOFF, *[0.0] * 6, math.nan) == (0, "")
        wait_for(conn, "HEARTBEAT", lambda m: mavutil.mode_string_v10(m) == "LOITER")

        # As a MAVSDK script converts: the origin asked for, the next position. A few cm: the
        # rounding (degE7, mm) and the origin moving with the fixes that come in between.
        for _ in range(3):
            assert command(conn, M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN) \
                == (0, "")
            origin = wait_for(conn, "GPS_GLOBAL_ORIGIN")
            local = wait_for(conn, "LOCAL_POSITION_NED")
            glob = wait_for(conn, "GLOBAL_POSITION_INT",
                            lambda m, t=local.time_boot_ms: m.time_boot_ms == t)
            assert local.x > 2.0 and local.z < -2.0  # away from the origin on every axis
            horizontal_m, vertical_m = _geodetic_error_m(origin, local, glob)
            assert horizontal_m < 0.08 and vertical_m < 0.08, (horizontal_m, vertical_m)

        # Of one instant (all three streamed every 10 ms, from the same estimate): the rounding
        # alone (1e-7 deg is 1.1 cm north, 0.7 cm east here; 1 mm).
        for msg_id in (M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                       M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT):
            assert command(conn, M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 10_000) == (0, "")
        seen: dict[str, dict[int, Any]] = {"GPS_GLOBAL_ORIGIN": {}, "LOCAL_POSITION_NED": {},
                                           "GLOBAL_POSITION_INT": {}}
        matched = 0
        deadline = time.monotonic() + 120.0  # a stuck guard: five instants come in a second
        while matched < 5:
            assert time.monotonic() < deadline, f"{matched} of 5 instants with all three"
            msg = wait_for(conn, list(seen))
            ms = (msg.time_usec // 1000 if msg.get_type() == "GPS_GLOBAL_ORIGIN"
                  else msg.time_boot_ms)
            seen[msg.get_type()][ms] = msg
            if all(ms in by_time for by_time in seen.values()):
                horizontal_m, vertical_m = _geodetic_error_m(
                    *(seen[k].pop(ms) for k in seen))
                assert horizontal_m < 0.02 and vertical_m < 0.002, (horizontal_m, vertical_m)
                matched += 1


def test_system_time_is_boot_time_and_the_host_wall_clock_in_lockstep():
    with mav_vehicle(rate=4.0) as v:  # sim time runs 4 times as fast as the wall clock
        conn = v.client()
        before = first = None  # the first SYSTEM_TIME, and the ATTITUDE sent last before it
        while first is None:
            msg = wait_for(conn, ["ATTITUDE", "SYSTEM_TIME"])
            if msg.get_type() == "ATTITUDE":
                before = msg
            elif before is not None:
                first = msg
        first_wall = time.time()
        after = wait_for(conn, "ATTITUDE")
        # One clock (sim time): between the ATTITUDEs sent before and after it. (Not "within
        # 200 ms of the next": the two streams' phases part after one late tick, and 50 ms of
        # wall time between them is 200 ms of sim time at 4x.) The wall-clock bounds below
        # leave a busy machine's delivery delays room; sim time would be off by seconds.
        assert before.time_boot_ms <= first.time_boot_ms <= after.time_boot_ms
        assert abs(first.time_unix_usec / 1e6 - first_wall) < 1.0
        later = wait_for(conn, "SYSTEM_TIME", lambda m: m.time_boot_ms >= first.time_boot_ms
                         + 8000)
        later_wall = time.time()
        assert abs(later.time_unix_usec / 1e6 - later_wall) < 1.0
        unix_s = (later.time_unix_usec - first.time_unix_usec) / 1e6
        assert abs(unix_s - (later_wall - first_wall)) < 1.0  # not the 8 s of sim time


def test_an_interval_of_minus_one_stops_the_origin_sent_on_change():
    """SET_MESSAGE_INTERVAL -1 stops GPS_GLOBAL_ORIGIN on that link also when it moves (as
    PX4 takes the stream away); 0 (the default) brings the on-change sending back."""
    airframe = FakeAirframe()
    boards = OnboardBoards(airframe)
    vehicle = MavlinkVehicle(boards)
    vehicle.add_link(0.0)
    assert len(_origins(vehicle, 0.0)) == 1

    gcs, parser = MavCodec(255, 190), MavParser()

    def set_interval(interval_us: float, now_s: float) -> None:
        msg = gcs.mav.command_long_encode(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                          M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, interval_us,
                                          0, 0, 0, 0, 0)
        (decoded,) = parser.feed(gcs.encode(msg), datagram=True)
        acks = [o.msg.result for o in vehicle.handle(0, ("127.0.0.1", 1), decoded, now_s)
                if o.msg.get_type() == "COMMAND_ACK"]
        assert acks == [M.MAV_RESULT_ACCEPTED]

    set_interval(-1, 1.0)
    fix = airframe.snap.gps
    for k, now_s in enumerate((2.0, 4.0), start=1):
        moved = replace(fix, latitude_deg=49.0 + k * 1e-5)
        airframe.snap = replace(airframe.snap, gps=moved, time_s=now_s)
        boards.tick(now_s)
        assert _origins(vehicle, now_s) == []  # moved, but stopped
    set_interval(0, 5.0)
    airframe.snap = replace(airframe.snap, gps=replace(fix, latitude_deg=49.0001), time_s=6.0)
    boards.tick(6.0)
    assert len(_origins(vehicle, 6.0)) == 1


def test_a_respawned_vehicle_places_its_origin_anew_altitude_included():
    """After a respawn (here onto a world elsewhere on the globe) the origin is the new fixes'
    alone: latitude, longitude and altitude alike (the altitude once kept the old mean)."""
    airframe = FakeAirframe()
    boards = OnboardBoards(airframe)
    vehicle = MavlinkVehicle(boards)
    vehicle.add_link(0.0)
    assert _origins(vehicle, 0.0) == [(490_000_000, 80_000_000, 100_000)]
    elsewhere = replace(airframe.snap.gps, latitude_deg=50.0, longitude_deg=9.0, altitude_m=300.0)
    airframe.snap = replace(airframe.snap, gps=elsewhere, time_s=1.0)
    boards.respawned("a new world")
    boards.tick(1.0)
    assert _origins(vehicle, 1.0) == [(500_000_000, 90_000_000, 300_000)]
