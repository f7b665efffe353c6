"""A mission changed while it runs, and a second ground station uploading at the same time, as a
pymavlink script or QGroundControl does it (a probe of 2026-11-27 found each one wrong):

- MISSION_CLEAR_ALL during a mission raised IndexError in the endpoint's tick, which stopped its
  thread: no telemetry and no answers any more; now the mission stops, the vehicle holds and
  every link is told;
- DO_SET_MISSION_CURRENT during a mission stopped it ("another command took over") instead of
  going on from the item asked for, as PX4 does;
- a command refused during a mission (a reposition too fast, a take-off in the air) stopped the
  mission silently (the mode went to Hold while the vehicle flew on to its waypoint); a refused
  command changes nothing;
- a second ground station's MISSION_COUNT during an upload took the upload over silently: the
  first one's items were ignored and it got no MISSION_ACK; now the second is refused
  (MAV_MISSION_ERROR with a STATUSTEXT), as PX4 refuses it ("busy").
"""

from __future__ import annotations

import math

from pymavlink import mavutil

from skeye.wire.packets import NavState
from tests.mavlink.conftest import (
    GCS,
    MavVehicle,
    command,
    mav_vehicle,
    scripted_endpoint,
    statustext,
    take_off,
    two_ground_stations,
    upload_mission,
    wait_for,
)

M = mavutil.mavlink
NORTH_E7 = 900  # 1e-4 deg: about 10 m north


def _on_the_first_leg(v: MavVehicle):
    """In the air, a 3-waypoint mission started (10 m north, 10 m north and 5 m east, back
    where it took off), flying its first leg; the client and the start's GLOBAL_POSITION_INT."""
    conn = v.client()
    wait_for(conn, "GLOBAL_POSITION_INT")
    take_off(conn)
    start = wait_for(conn, "GLOBAL_POSITION_INT")
    items = [(start.lat + NORTH_E7, start.lon, 2.5), (start.lat + NORTH_E7, start.lon + 700, 2.5),
             (start.lat, start.lon, 2.5)]
    assert upload_mission(conn, items) == M.MAV_MISSION_ACCEPTED
    assert command(conn, M.MAV_CMD_MISSION_START, 0, 0)[0] == 0
    wait_for(conn, "HEARTBEAT", lambda m: mavutil.mode_string_v10(m) == "MISSION"
             and v.pilot.boards.state is NavState.FLYING)
    return conn, start


def _mission_end(conn) -> tuple[str, list[int]]:
    """The STATUSTEXT that ends the mission ("mission complete" or "mission stopped: ...") and
    the items reached before it."""
    reached = []
    while True:
        msg = wait_for(conn, ["STATUSTEXT", "MISSION_ITEM_REACHED"])
        if msg.get_type() == "MISSION_ITEM_REACHED":
            reached.append(int(msg.seq))
        elif msg.text.startswith("mission"):
            return str(msg.text), reached


def test_clearing_the_mission_in_flight_stops_it_and_the_vehicle_holds():
    with mav_vehicle() as v:
        conn, _ = _on_the_first_leg(v)
        conn.mav.mission_clear_all_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
        assert wait_for(conn, "MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
        assert statustext(conn) == "mission stopped: the mission was cleared"
        wait_for(conn, "HEARTBEAT", lambda m: mavutil.mode_string_v10(m) == "LOITER")
        # It holds short of the first waypoint (10 m north), not flying on to it.
        still = wait_for(conn, "LOCAL_POSITION_NED",
                         lambda m: math.hypot(m.vx, m.vy) < 0.05
                         and v.pilot.boards.state is NavState.HOLDING)
        assert still.x < 6.0
        assert wait_for(conn, "MISSION_CURRENT").mission_state == M.MISSION_STATE_NO_MISSION
        assert command(conn, M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION)[0] == 0
        v.mavlink.check()  # the endpoint's thread is alive
        assert v.mavlink.errors == 0


def test_setting_the_current_item_in_flight_goes_on_from_that_item():
    with mav_vehicle() as v:
        conn, _ = _on_the_first_leg(v)
        assert command(conn, M.MAV_CMD_DO_SET_MISSION_CURRENT, 2)[0] == 0
        # Straight back to item 2 (where it took off: a short way), items 0 and 1 skipped.
        assert _mission_end(conn) == ("mission complete", [2])


def test_a_command_refused_during_a_mission_leaves_the_mission_running():
    with mav_vehicle() as v:
        conn, start = _on_the_first_leg(v)
        conn.mav.command_int_send(1, 1, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_DO_REPOSITION, 0, 0,
                                  100.0, 1, 0, math.nan, start.lat, start.lon, math.nan)
        ack = wait_for(conn, "COMMAND_ACK", lambda m: m.command == M.MAV_CMD_DO_REPOSITION)
        assert ack.result == M.MAV_RESULT_DENIED
        result, text = command(conn, M.MAV_CMD_NAV_TAKEOFF, *[0.0] * 6, math.nan)
        assert result == M.MAV_RESULT_TEMPORARILY_REJECTED, text
        hb = wait_for(conn, "HEARTBEAT")
        assert mavutil.mode_string_v10(hb) == "MISSION"
        assert _mission_end(conn) == ("mission complete", [0, 1, 2])


def test_a_second_upload_during_an_upload_is_refused_and_the_first_completes():
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        with two_ground_stations(server) as (first, second):
            first.mav.mission_count_send(1, 1, 2, M.MAV_MISSION_TYPE_MISSION)
            assert wait_for(first, "MISSION_REQUEST_INT").seq == 0
            second.mav.mission_count_send(1, 1, 1, M.MAV_MISSION_TYPE_MISSION)
            answer = wait_for(second, ["MISSION_REQUEST_INT", "MISSION_ACK"],
                              lambda m: m.target_system == 254)
            assert answer.get_type() == "MISSION_ACK", answer  # (was: the upload taken over)
            assert answer.type == M.MAV_MISSION_ERROR
            assert "an upload from 255/190 is under way" in statustext(second)
            for seq in (0, 1):  # items "here" (0/0), 2 m up
                first.mav.mission_item_int_send(
                    1, 1, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_WAYPOINT, 0,
                    1, 0, 0.5, 0, math.nan, 0, 0, 2.0, M.MAV_MISSION_TYPE_MISSION)
                answer = wait_for(first, ["MISSION_REQUEST_INT", "MISSION_ACK"],
                                  lambda m: m.target_system == GCS[0])
            assert (answer.get_type(), answer.type) == ("MISSION_ACK", M.MAV_MISSION_ACCEPTED)
            assert len(server.vehicle.mission.items) == 2
            # Once it is over, the second station's upload is served.
            second.mav.mission_count_send(1, 1, 1, M.MAV_MISSION_TYPE_MISSION)
            assert wait_for(second, ["MISSION_REQUEST_INT", "MISSION_ACK"],
                            lambda m: m.target_system == 254).get_type() == "MISSION_REQUEST_INT"
            assert server.errors == 0


def test_a_re_requested_mission_item_goes_only_to_the_uploading_station():
    """An item not sent within 1 s is asked for again: of the station doing the upload only,
    as PX4 and ArduPilot address the partner of a transfer. (Until 2026-11-27 the re-request
    went to every ground station on every link.)"""
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        with two_ground_stations(server) as (first, second):
            for conn in (first, second):
                wait_for(conn, "HEARTBEAT")  # (its own heartbeat makes it a ground station)
            first.mav.mission_count_send(1, 1, 1, M.MAV_MISSION_TYPE_MISSION)
            assert wait_for(first, "MISSION_REQUEST_INT").seq == 0
            again = wait_for(first, "MISSION_REQUEST_INT", timeout_s=10)  # (no item: asked again)
            assert (again.seq, again.target_system) == (0, GCS[0])
            # What the vehicle sent the second station before the re-request is in its socket
            # once an answer sent after it has come.
            second.mav.param_request_read_send(1, 1, b"COM_OF_LOSS_T", -1)
            seen: list[str] = []
            wait_for(second, ["MISSION_REQUEST_INT", "PARAM_VALUE"],
                     lambda m: seen.append(m.get_type()) or m.get_type() == "PARAM_VALUE",
                     timeout_s=10)
            assert seen == ["PARAM_VALUE"]
            assert server.errors == 0
