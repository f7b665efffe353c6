"""The SET_MODE message (what QGroundControl sent before it used MAV_CMD_DO_SET_MODE, and a
pymavlink script's ``mav.set_mode_send``): run as DO_SET_MODE with its base mode and PX4's
custom mode, and answered with DO_SET_MODE's COMMAND_ACK, as PX4 runs it. Until 2026-11-28 it
was ignored without a word: the mode stayed, and no ACK or STATUSTEXT said why (a probe with
pymavlink)."""

from __future__ import annotations

from pymavlink import mavutil

from tests.mavlink.conftest import (
    GCS,
    command,
    ground_station,
    scripted_endpoint,
    statustext,
    wait_for,
)

M = mavutil.mavlink
CUSTOM = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


def _px4(main: int, sub: int = 0) -> int:
    return (main << 16) | (sub << 24)


def test_set_mode_changes_the_mode_and_is_acknowledged():
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        with ground_station(server) as conn:
            wait_for(conn, "HEARTBEAT", timeout_s=10)
            assert command(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)[0] == M.MAV_RESULT_ACCEPTED
            conn.mav.set_mode_send(2, CUSTOM, _px4(4, 2))  # another system's: not for us
            conn.mav.set_mode_send(1, CUSTOM, _px4(4, 2))  # AUTO.TAKEOFF
            ack = wait_for(conn, "COMMAND_ACK", timeout_s=10)
            assert (ack.command, ack.result) == (M.MAV_CMD_DO_SET_MODE, M.MAV_RESULT_ACCEPTED)
            assert (ack.target_system, ack.target_component) == GCS
            wait_for(conn, "HEARTBEAT",
                     lambda h: mavutil.mode_string_v10(h) == "TAKEOFF", timeout_s=10)
            conn.mav.set_mode_send(1, CUSTOM, _px4(7))  # STABILIZED: refused, with the reason
            ack = wait_for(conn, "COMMAND_ACK", timeout_s=10)
            assert (ack.command, ack.result) == (M.MAV_CMD_DO_SET_MODE, M.MAV_RESULT_DENIED)
            assert "mode STABILIZED is not flown" in statustext(conn, timeout_s=10)
            conn.mav.set_mode_send(1, CUSTOM, _px4(4, 99))  # no PX4 mode at all
            ack = wait_for(conn, "COMMAND_ACK", timeout_s=10)
            assert (ack.command, ack.result) == (M.MAV_CMD_DO_SET_MODE, M.MAV_RESULT_DENIED)
            assert "custom mode 4/99 (main/sub) is no PX4 mode" in statustext(conn, timeout_s=10)
            assert server.errors == 0
