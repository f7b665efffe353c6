"""SET_MESSAGE_INTERVAL -1 stops a message: its stream, and also what the vehicle sends when
the message's content changes (MISSION_CURRENT as a mission goes on, GPS_GLOBAL_ORIGIN as the
origin moves: ``tests/mavlink/test_origin_time.py``), as PX4 takes the stream away."""

from __future__ import annotations

import math

from pymavlink import mavutil

from tests.mavlink.conftest import command, mav_vehicle, wait_for

M = mavutil.mavlink


def test_a_stopped_mission_current_is_not_sent_as_the_mission_goes_on():
    with mav_vehicle(estimator="truth") as v:
        conn = v.client()
        wait_for(conn, "GLOBAL_POSITION_INT")
        assert command(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)[0] == 0
        assert command(conn, M.MAV_CMD_NAV_TAKEOFF, *[0.0] * 6, math.nan)[0] == 0
        wait_for(conn, "HEARTBEAT", lambda m: mavutil.mode_string_v10(m) == "LOITER")
        pos = wait_for(conn, "GLOBAL_POSITION_INT")
        conn.mav.mission_count_send(1, 1, 2, M.MAV_MISSION_TYPE_MISSION)
        for seq in range(2):  # two waypoints 0.5 m apart, north
            assert wait_for(conn, "MISSION_REQUEST_INT").seq == seq
            conn.mav.mission_item_int_send(
                1, 1, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_WAYPOINT,
                int(seq == 0), 1, 0, 0.5, 0, math.nan, pos.lat + 45 * (seq + 1), pos.lon,
                pos.relative_alt / 1e3, M.MAV_MISSION_TYPE_MISSION)
        assert wait_for(conn, "MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
        assert command(conn, M.MAV_CMD_SET_MESSAGE_INTERVAL,
                       M.MAVLINK_MSG_ID_MISSION_CURRENT, -1) == (0, "")
        assert command(conn, M.MAV_CMD_MISSION_START, 0, 0)[0] == 0
        seen = []
        while True:  # in order: every message the vehicle sent until the mission's end
            msg = wait_for(conn, ["MISSION_ITEM_REACHED", "MISSION_CURRENT", "STATUSTEXT"],
                           timeout_s=120)
            seen.append(msg.get_type())
            if msg.get_type() == "STATUSTEXT" and msg.text == "mission complete":
                break
        assert seen.count("MISSION_ITEM_REACHED") == 2
        assert "MISSION_CURRENT" not in seen, seen
