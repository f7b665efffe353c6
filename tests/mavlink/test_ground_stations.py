"""Several ground stations on one vehicle: a parameter one of them sets is sent to all (as PX4
sends a changed parameter on every link), so QGroundControl's parameter list on another station
does not keep the old value; a refused value goes back to the sender only. (Until 2026-11-27 the
PARAM_VALUE of a value set went to the sender alone.)"""

from __future__ import annotations

from pymavlink import mavutil

from tests.mavlink.conftest import scripted_endpoint, statustext, two_ground_stations, wait_for

M = mavutil.mavlink


def test_a_parameter_set_by_one_ground_station_is_sent_to_the_others():
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        with two_ground_stations(server) as (first, second):
            for conn in (first, second):
                wait_for(conn, "HEARTBEAT")  # (its own heartbeat makes it a ground station)
            first.mav.param_set_send(1, 1, b"MIS_TAKEOFF_ALT", 4.0, M.MAV_PARAM_TYPE_REAL32)
            for conn in (first, second):
                value = wait_for(conn, "PARAM_VALUE", timeout_s=10)
                assert (value.param_id, value.param_value) == ("MIS_TAKEOFF_ALT", 4.0)
            first.mav.param_set_send(1, 1, b"MIS_TAKEOFF_ALT", 500.0, M.MAV_PARAM_TYPE_REAL32)
            assert wait_for(first, "PARAM_VALUE", timeout_s=10).param_value == 4.0
            assert "MIS_TAKEOFF_ALT must be 0.5..80 m" in statustext(first)
            # The second station hears no PARAM_VALUE for the refusal (a read shows the next).
            second.mav.param_request_read_send(1, 1, b"COM_OF_LOSS_T", -1)
            assert wait_for(second, "PARAM_VALUE", timeout_s=10).param_id == "COM_OF_LOSS_T"
            assert server.errors == 0
