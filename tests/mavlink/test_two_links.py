"""One vehicle, two links: the AscTec packet port and MAVLink command the same boards; the last
command wins, and a MAVLink mission that another command interrupts stops and says so."""

from __future__ import annotations

import math

from pymavlink import mavutil

from skeye.link.vehicle import Vehicle
from skeye.wire.packets import NavState
from tests.mavlink.conftest import command, mav_vehicle, statustext, take_off, wait_for

M = mavutil.mavlink


def test_an_asctec_hold_stops_a_mavlink_mission():
    with mav_vehicle(rate=2.0) as v, Vehicle.open(v.pilot.address, timeout_s=10.0) as asctec:
        conn = v.client()
        wait_for(conn, "GLOBAL_POSITION_INT")
        take_off(conn)
        pos = wait_for(conn, "GLOBAL_POSITION_INT")
        conn.mav.mission_count_send(1, 1, 1, M.MAV_MISSION_TYPE_MISSION)
        wait_for(conn, "MISSION_REQUEST_INT")
        conn.mav.mission_item_int_send(1, 1, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                       M.MAV_CMD_NAV_WAYPOINT, 1, 1, 0, 0.5, 0, math.nan,
                                       pos.lat + 900, pos.lon, 2.5, M.MAV_MISSION_TYPE_MISSION)
        assert wait_for(conn, "MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
        assert command(conn, M.MAV_CMD_MISSION_START, 0, 0)[0] == 0
        wait_for(conn, "HEARTBEAT", lambda m: mavutil.mode_string_v10(m) == "MISSION")
        wait_for(conn, "HEARTBEAT", lambda m: v.pilot.boards.state is NavState.FLYING)
        asctec.hold()  # the other link's command: the last one wins
        text = statustext(conn)
        while "mission stopped" not in text:
            text = statustext(conn)
        assert "another command took over" in text
        hb = wait_for(conn, "HEARTBEAT", lambda m: mavutil.mode_string_v10(m) == "LOITER")
        assert hb.system_status == M.MAV_STATE_ACTIVE
        assert v.pilot.boards.state is NavState.HOLDING
        mission = wait_for(conn, "MISSION_CURRENT")
        assert mission.mission_state == M.MISSION_STATE_PAUSED
