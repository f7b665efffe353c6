"""SET_GPS_GLOBAL_ORIGIN from a pymavlink ground station, as a pymavlink script or MAVROS
(``global_position/set_gp_origin``) sends it to a vehicle flying without GPS (indoors, on
optical flow: skeye's ``indoor`` world): it places the local frame on the globe, so
GPS_GLOBAL_ORIGIN, GLOBAL_POSITION_INT, HOME_POSITION and global targets (mission items,
repositions) work from the local position. It is taken where PX4's and ArduPilot's estimators
take it (no GPS anchoring the frame; a valid latitude and longitude, an altitude on Earth) and
refused otherwise, visibly: a STATUSTEXT "SET_GPS_GLOBAL_ORIGIN refused: why" and the
GPS_GLOBAL_ORIGIN still in force (none without one). (Until 2026-11-27 the message was ignored:
an indoor vehicle never had a global position.)
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

from pymavlink import mavutil

from skeye.geo import GeoOrigin
from skeye.pilot.airframe import GpsFix
from skeye.pilot.boards import OnboardBoards
from skeye.pilot.mavlink_server import MavlinkServer
from tests.mavlink.conftest import (
    command,
    ground_station,
    scripted_endpoint,
    statustext,
    wait_for,
)
from tests.pilot.fake_airframe import FakeAirframe

M = mavutil.mavlink
NO_FIX = GpsFix(False, 0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0))  # a receiver indoors
# The origin a ground station gives (PX4 SITL's default home, Zurich): degE7 and mm.
LAT_E7, LON_E7, ALT_MM = 473_977_419, 85_455_939, 488_000


@contextmanager
def _indoor_endpoint() -> Iterator[tuple[MavlinkServer, FakeAirframe, Any]]:
    """The endpoint on a listening UDP link over a scripted airframe without a GPS fix, standing
    3 m north, 4 m west of the local origin and 1.5 m below it; a pymavlink ground station."""
    airframe = FakeAirframe()
    airframe.snap = replace(airframe.snap, gps=NO_FIX, pos_ned_m=(3.0, -4.0, 1.5))
    with MavlinkServer(OnboardBoards(airframe), threading.Lock(), ["udp://127.0.0.1:0"]) as server:
        with ground_station(server) as conn:
            yield server, airframe, conn


def _request(conn: Any, msg_id: int) -> tuple[int, Any]:
    """REQUEST_MESSAGE: its COMMAND_ACK result and the message (None unless accepted)."""
    name = mavutil.mavlink.mavlink_map[msg_id].msgname
    result, _ = command(conn, M.MAV_CMD_REQUEST_MESSAGE, msg_id, timeout_s=10)
    if result != M.MAV_RESULT_ACCEPTED:
        return result, None
    return result, wait_for(conn, name, timeout_s=10)


def _origin_of(msg: Any) -> tuple[int, int, int]:
    return int(msg.latitude), int(msg.longitude), int(msg.altitude)


def test_an_origin_given_without_gps_places_the_local_frame_on_the_globe():
    with _indoor_endpoint() as (server, _, conn):
        wait_for(conn, "HEARTBEAT")
        assert _request(conn, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)[0] == \
            M.MAV_RESULT_TEMPORARILY_REJECTED  # no GPS, no origin given: none yet
        conn.mav.set_gps_global_origin_send(1, LAT_E7, LON_E7, ALT_MM, 0)
        told = wait_for(conn, "GPS_GLOBAL_ORIGIN", timeout_s=10)  # the answer, unasked
        assert _origin_of(told) == (LAT_E7, LON_E7, ALT_MM)
        # Global positions are the given origin plus the local position: to the rounding of
        # degE7 (1 unit, about 1.1 cm) and of mm.
        origin = GeoOrigin(LAT_E7 / 1e7, LON_E7 / 1e7, ALT_MM / 1e3)
        lat, lon, alt = origin.to_geodetic(3.0, -4.0, 1.5)
        pos = wait_for(conn, "GLOBAL_POSITION_INT", timeout_s=10)
        assert abs(pos.lat - lat * 1e7) <= 1 and abs(pos.lon - lon * 1e7) <= 1
        assert abs(pos.alt - alt * 1e3) <= 1
        _, home = _request(conn, M.MAVLINK_MSG_ID_HOME_POSITION)  # home: where it stands
        assert abs(home.latitude - lat * 1e7) <= 1 and abs(home.longitude - lon * 1e7) <= 1
        assert abs(home.altitude - alt * 1e3) <= 1
        # A global mission item is placed through it (without an origin: "no GPS position").
        north = round((origin.to_geodetic(20.0, 0.0, 0.0)[0]) * 1e7)
        conn.mav.mission_count_send(1, 1, 1, M.MAV_MISSION_TYPE_MISSION)
        assert wait_for(conn, "MISSION_REQUEST_INT", timeout_s=10).seq == 0
        conn.mav.mission_item_int_send(1, 1, 0, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_NAV_WAYPOINT,
                                       1, 1, 0, 0.5, 0, 0, north, LON_E7, 490.0,
                                       M.MAV_MISSION_TYPE_MISSION)
        assert wait_for(conn, "MISSION_ACK", timeout_s=10).type == M.MAV_MISSION_ACCEPTED
        assert server.errors == 0


def test_an_origin_out_of_range_or_for_another_system_changes_nothing_a_later_one_does():
    with _indoor_endpoint() as (server, _, conn):
        wait_for(conn, "HEARTBEAT")
        conn.mav.set_gps_global_origin_send(1, LAT_E7, LON_E7, ALT_MM, 0)
        assert _origin_of(wait_for(conn, "GPS_GLOBAL_ORIGIN", timeout_s=10)) == \
            (LAT_E7, LON_E7, ALT_MM)
        for lat, lon, alt, why in (
            (910_000_000, LON_E7, ALT_MM, "latitude 91 deg is out of range -90..90"),
            (LAT_E7, -1_810_000_000, ALT_MM, "longitude -181 deg is out of range -180..180"),
            (LAT_E7, LON_E7, -500_000, "altitude -500 m above mean sea level is outside "
                                        "-430..100000 m"),
        ):
            conn.mav.set_gps_global_origin_send(1, lat, lon, alt, 0)
            assert why in statustext(conn, timeout_s=10)
            kept = wait_for(conn, "GPS_GLOBAL_ORIGIN", timeout_s=10)  # the one in force
            assert _origin_of(kept) == (LAT_E7, LON_E7, ALT_MM)
        conn.mav.set_gps_global_origin_send(7, 0, 0, 0, 0)  # another vehicle's: not ours
        _, now = _request(conn, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
        assert _origin_of(now) == (LAT_E7, LON_E7, ALT_MM)
        conn.mav.set_gps_global_origin_send(1, LAT_E7 + 100, LON_E7, ALT_MM - 2_000, 0)
        replaced = wait_for(conn, "GPS_GLOBAL_ORIGIN", timeout_s=10)  # a later one replaces it
        assert _origin_of(replaced) == (LAT_E7 + 100, LON_E7, ALT_MM - 2_000)
        assert server.errors == 0


def test_with_gps_the_fixes_place_the_local_frame_and_an_origin_given_is_refused():
    with scripted_endpoint("udp://127.0.0.1:0") as server:  # (a fix at 49 N 8 E, 100 m)
        with ground_station(server) as conn:
            wait_for(conn, "HEARTBEAT")
            conn.mav.set_gps_global_origin_send(1, LAT_E7, LON_E7, ALT_MM, 0)
            assert "the GPS places this vehicle's local frame" in statustext(conn, timeout_s=10)
            kept = wait_for(conn, "GPS_GLOBAL_ORIGIN", timeout_s=10)
            assert _origin_of(kept) == (490_000_000, 80_000_000, 100_000)
        assert server.errors == 0


def test_a_gps_fix_after_an_origin_given_takes_over():
    with _indoor_endpoint() as (server, airframe, conn):
        wait_for(conn, "HEARTBEAT")
        conn.mav.set_gps_global_origin_send(1, LAT_E7, LON_E7, ALT_MM, 0)
        assert _origin_of(wait_for(conn, "GPS_GLOBAL_ORIGIN", timeout_s=10))[0] == LAT_E7
        # Out of the door: a fix at 49 N 8 E, 100 m; where it stands (3, -4, 1.5) is that
        # fix, so the local origin is 3 m south, 4 m east of it and 1.5 m above.
        airframe.snap = replace(airframe.snap, time_s=1.0,
                                gps=GpsFix(True, 9, 49.0, 8.0, 100.0, (0.0, 0.0, 0.0)))
        with server.lock:
            server.vehicle.boards.tick(1.0)
        moved = wait_for(conn, "GPS_GLOBAL_ORIGIN", timeout_s=10)  # told as it moved
        lat, lon, alt = GeoOrigin(49.0, 8.0, 100.0).to_geodetic(-3.0, 4.0, -1.5)
        assert abs(moved.latitude - lat * 1e7) <= 1 and abs(moved.longitude - lon * 1e7) <= 1
        assert abs(moved.altitude - alt * 1e3) <= 1
        assert server.errors == 0
