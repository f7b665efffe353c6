"""A command sent again within a second (a ground station resending because an answer was lost):
an action is not run twice and gets its first COMMAND_ACK again, however its unused parameters
are filled (MAVSDK sends NaN for each, and NaN != NaN once made every resend look new: a take-off
resent was refused "not landed" after the first was accepted); a request for a message is
answered again, message and all (the second REQUEST_MESSAGE once got only its COMMAND_ACK).
A repeat after the vehicle's mode, arming or flight state moved on is a new command: arm,
disarm, arm within a second once left the vehicle disarmed with the last arm ACCEPTED."""

from __future__ import annotations

import math

from pymavlink import mavutil

from tests.mavlink.conftest import GCS, scripted_endpoint, wait_for

M = mavutil.mavlink
NAN6 = (math.nan,) * 6


def _client(server):
    port = int(server.addresses[0].rsplit(":", 1)[1])
    return mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=GCS[0],
                                      source_component=GCS[1])


def _ack(conn, cmd: int) -> int:
    return int(wait_for(conn, "COMMAND_ACK", lambda m: m.command == cmd, timeout_s=10).result)


def test_a_take_off_resent_with_nan_parameters_gets_the_same_ack_and_runs_once():
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        conn = _client(server)
        try:
            wait_for(conn, "HEARTBEAT")
            # As MAVSDK's action.arm() and action.takeoff() send them: unset parameters NaN.
            conn.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, *NAN6)
            assert _ack(conn, M.MAV_CMD_COMPONENT_ARM_DISARM) == M.MAV_RESULT_ACCEPTED
            for confirmation in (0, 1):  # the resend, as MAVSDK numbers it
                conn.mav.command_long_send(1, 1, M.MAV_CMD_NAV_TAKEOFF, confirmation,
                                           math.nan, *NAN6)
                assert _ack(conn, M.MAV_CMD_NAV_TAKEOFF) == M.MAV_RESULT_ACCEPTED
            calls = [c for c in server.vehicle.boards.airframe.calls if c[0] == "take_off"]
            assert len(calls) == 1
            assert server.errors == 0
        finally:
            conn.close()


def test_a_command_repeated_after_the_vehicle_changed_is_run_again():
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        conn = _client(server)
        try:
            wait_for(conn, "HEARTBEAT")
            for arm in (1.0, 0.0, 1.0):  # well within the second a resend is looked for
                conn.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, arm, *NAN6)
                assert _ack(conn, M.MAV_CMD_COMPONENT_ARM_DISARM) == M.MAV_RESULT_ACCEPTED
                assert server.vehicle.armed == bool(arm)
            assert server.errors == 0
        finally:
            conn.close()


def test_a_request_for_a_message_repeated_at_once_is_answered_each_time():
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        conn = _client(server)
        try:
            wait_for(conn, "HEARTBEAT")
            for _ in range(2):  # AUTOPILOT_VERSION and MESSAGE_INTERVAL are never streamed
                conn.mav.command_long_send(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0,
                                           M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
                assert _ack(conn, M.MAV_CMD_REQUEST_MESSAGE) == M.MAV_RESULT_ACCEPTED
                wait_for(conn, "AUTOPILOT_VERSION", timeout_s=10)
            for _ in range(2):
                conn.mav.command_long_send(1, 1, M.MAV_CMD_GET_MESSAGE_INTERVAL, 0,
                                           M.MAVLINK_MSG_ID_ATTITUDE, 0, 0, 0, 0, 0, 0)
                assert _ack(conn, M.MAV_CMD_GET_MESSAGE_INTERVAL) == M.MAV_RESULT_ACCEPTED
                reply = wait_for(conn, "MESSAGE_INTERVAL", timeout_s=10)
                assert (reply.message_id, reply.interval_us) == (M.MAVLINK_MSG_ID_ATTITUDE,
                                                                 50_000)
        finally:
            conn.close()
