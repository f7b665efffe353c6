"""The mission protocol's corners as ground stations drive them (a probe of 2026-11-27 with
pymavlink, against the MAVLink mission protocol and PX4's mavlink_mission.cpp, found each one
wrong):

- MISSION_CLEAR_ALL with mission_type ALL (255, "used to clear all mission types") was
  acknowledged ACCEPTED and cleared nothing: the mission stayed stored;
- a download item by item with the deprecated MISSION_REQUEST was answered with
  MISSION_ITEM_INT; the message's definition asks for MISSION_ITEM, and PX4 answers with it;
- the last item of an upload sent again (the ground station's answer when the final MISSION_ACK
  is lost) was ignored, so the station timed out although the vehicle had stored the mission;
  PX4 sends the MISSION_ACK again.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import pytest
from pymavlink import mavutil

from tests.mavlink.conftest import GCS, command, scripted_endpoint, wait_for

M = mavutil.mavlink
LAT_E7, LON_E7 = 490_001_000, 80_002_000  # near the scripted fix at 49 N 8 E


def _client(server) -> Any:
    port = int(server.addresses[0].rsplit(":", 1)[1])
    return mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=GCS[0],
                                      source_component=GCS[1])


@pytest.fixture
def vehicle() -> Iterator[tuple[Any, Any]]:
    """The scripted vehicle and a pymavlink ground station that has heard it, holding a
    mission of two waypoints."""
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        conn = _client(server)
        try:
            wait_for(conn, "HEARTBEAT")
            _upload(conn, 2)
            assert _count(conn) == 2
            yield server, conn
            assert server.errors == 0
        finally:
            conn.close()


def _item(conn: Any, seq: int) -> None:
    conn.mav.mission_item_int_send(
        1, 1, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_WAYPOINT, 0, 1,
        0, 0.5, 0, math.nan, LAT_E7 + 100 * seq, LON_E7, 5.0 + seq, M.MAV_MISSION_TYPE_MISSION)


def _upload(conn: Any, count: int) -> None:
    """``count`` waypoints, pulled by the vehicle; returns once it acknowledged them."""
    conn.mav.mission_count_send(1, 1, count, M.MAV_MISSION_TYPE_MISSION)
    while True:
        msg = wait_for(conn, ["MISSION_REQUEST_INT", "MISSION_ACK"], timeout_s=10)
        if msg.get_type() == "MISSION_ACK":
            assert msg.type == M.MAV_MISSION_ACCEPTED
            return
        _item(conn, msg.seq)


def _count(conn: Any) -> int:
    conn.mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
    return int(wait_for(conn, "MISSION_COUNT", timeout_s=10).count)


def test_clear_all_of_every_mission_type_clears_the_mission(vehicle: tuple[Any, Any]) -> None:
    _, conn = vehicle
    conn.mav.mission_clear_all_send(1, 1, M.MAV_MISSION_TYPE_ALL)
    ack = wait_for(conn, "MISSION_ACK", timeout_s=10)
    assert (ack.type, ack.mission_type) == (M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_TYPE_ALL)
    assert _count(conn) == 0


def test_a_download_by_mission_request_gets_mission_items(vehicle: tuple[Any, Any]) -> None:
    _, conn = vehicle
    for seq in range(2):
        conn.mav.mission_request_send(1, 1, seq, M.MAV_MISSION_TYPE_MISSION)
        item = wait_for(conn, ["MISSION_ITEM", "MISSION_ITEM_INT"], timeout_s=10)
        assert item.get_type() == "MISSION_ITEM"
        assert item.seq == seq
        assert item.frame == M.MAV_FRAME_GLOBAL_RELATIVE_ALT
        assert item.command == M.MAV_CMD_NAV_WAYPOINT
        # degrees as float32: 49 deg is held to 2**-18 deg (4e-6), about 0.4 m
        assert abs(item.x - (LAT_E7 + 100 * seq) / 1e7) <= 2.0**-18
        assert abs(item.y - LON_E7 / 1e7) <= 2.0**-18
        assert item.z == 5.0 + seq
    conn.mav.mission_request_int_send(1, 1, 1, M.MAV_MISSION_TYPE_MISSION)
    item = wait_for(conn, ["MISSION_ITEM", "MISSION_ITEM_INT"], timeout_s=10)
    assert item.get_type() == "MISSION_ITEM_INT"
    assert (item.x, item.y) == (LAT_E7 + 100, LON_E7)
    conn.mav.mission_ack_send(1, 1, M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_TYPE_MISSION)


def test_the_last_item_sent_again_after_a_lost_ack_is_acknowledged_again(
        vehicle: tuple[Any, Any]) -> None:
    server, conn = vehicle
    _upload(conn, 3)  # (its MISSION_ACK "lost": the station sends item 2 again)
    stored = server.vehicle.mission.version
    _item(conn, 2)
    ack = wait_for(conn, "MISSION_ACK", timeout_s=5)
    assert (ack.type, ack.mission_type) == (M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_TYPE_MISSION)
    assert (ack.target_system, ack.target_component) == GCS
    assert _count(conn) == 3  # stored once, not changed by the repeat
    assert server.vehicle.mission.version == stored
    # an item no upload asked for is still not acknowledged: the next answer is the count
    _item(conn, 1)
    conn.mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
    answer = wait_for(conn, ["MISSION_ACK", "MISSION_COUNT"], timeout_s=10)
    assert (answer.get_type(), answer.count) == ("MISSION_COUNT", 3)


def test_a_take_off_item_here_in_the_amsl_frame_climbs_to_that_altitude(
        vehicle: tuple[Any, Any]) -> None:
    """A NAV_TAKEOFF at 0/0 ("here") in GLOBAL_INT: z is above mean sea level, as for any
    item in that frame. Until 2026-11-28 it was flown as a height above the ground: z 103 m
    AMSL, 3 m over the vehicle standing at 100 m, climbed 103 m (a probe with pymavlink)."""
    server, conn = vehicle
    airframe = server.vehicle.boards.airframe
    conn.mav.mission_count_send(1, 1, 1, M.MAV_MISSION_TYPE_MISSION)
    assert wait_for(conn, "MISSION_REQUEST_INT", timeout_s=10).seq == 0
    conn.mav.mission_item_int_send(
        1, 1, 0, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_NAV_TAKEOFF, 0, 1, 0, 0, 0, math.nan,
        0, 0, 103.0, M.MAV_MISSION_TYPE_MISSION)
    assert wait_for(conn, "MISSION_ACK", timeout_s=10).type == M.MAV_MISSION_ACCEPTED
    assert command(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)[0] == M.MAV_RESULT_ACCEPTED
    assert command(conn, M.MAV_CMD_MISSION_START, 0, 0)[0] == M.MAV_RESULT_ACCEPTED
    wait_for(conn, "HEARTBEAT", lambda h: h.system_status == M.MAV_STATE_ACTIVE, timeout_s=10)
    with server.lock:
        take_offs = [args for name, args in airframe.calls if name == "take_off"]
    assert len(take_offs) == 1
    assert take_offs[0][0] == pytest.approx(3.0, abs=1e-3)  # the scripted fix: 100 m AMSL


def test_a_change_speed_item_of_minus_two_is_taken(vehicle: tuple[Any, Any]) -> None:
    """A DO_CHANGE_SPEED item with p2 -2 ("return to default vehicle speed") was refused with
    INVALID_PARAM2 ("item 0: speed -2.0 m/s"), the whole mission with it."""
    _, conn = vehicle
    conn.mav.mission_count_send(1, 1, 1, M.MAV_MISSION_TYPE_MISSION)
    assert wait_for(conn, "MISSION_REQUEST_INT", timeout_s=10).seq == 0
    conn.mav.mission_item_int_send(
        1, 1, 0, M.MAV_FRAME_MISSION, M.MAV_CMD_DO_CHANGE_SPEED, 0, 1, 1, -2, -1, 0, 0, 0, 0,
        M.MAV_MISSION_TYPE_MISSION)
    assert wait_for(conn, "MISSION_ACK", timeout_s=10).type == M.MAV_MISSION_ACCEPTED
    assert _count(conn) == 1
