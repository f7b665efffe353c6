"""The parameter list is for the system it is asked of: a PARAM_REQUEST_LIST for another system
(a second vehicle on the same link) was answered with this vehicle's whole list (a probe of
2026-11-27 with pymavlink); PX4 answers only its own system's, as for PARAM_REQUEST_READ and
PARAM_SET."""

from __future__ import annotations

import math

from pymavlink import mavutil

from tests.mavlink.conftest import ground_station, scripted_endpoint, statustext, wait_for

M = mavutil.mavlink


def test_a_parameter_list_asked_of_another_system_is_not_answered():
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        with ground_station(server) as conn:
            wait_for(conn, "HEARTBEAT")
            count = len(server.vehicle.params.specs)
            conn.mav.param_request_list_send(2, 1)  # another vehicle's
            conn.mav.param_request_list_send(1, 50)  # another component's
            # then this one's last parameter: the first PARAM_VALUE back must answer it (the
            # vehicle answers in the order asked; a list would have started at index 0)
            conn.mav.param_request_read_send(1, 1, b"", count - 1)
            first = wait_for(conn, "PARAM_VALUE", timeout_s=10)
            assert (first.param_index, first.param_count) == (count - 1, count)
            conn.mav.param_request_list_send(1, 0)  # this vehicle's: every one, in order
            indexes = [wait_for(conn, "PARAM_VALUE", timeout_s=10).param_index
                       for _ in range(count)]
            assert indexes == list(range(count))
            assert server.errors == 0


def test_a_speed_limit_set_below_the_cruise_speed_brings_the_cruise_speed_down():
    """MPC_XY_VEL_MAX set to 0.5 m/s under MPC_XY_CRUISE's 1 m/s was ACCEPTED and the cruise
    speed stayed 1 m/s: every move naming no speed was then refused ("speed 1 m/s is over this
    vehicle's limit of 0.5 m/s"), and MPC_XY_CRUISE could be set over the limit too (a probe of
    2026-11-28 with pymavlink). Now the cruise speed comes down to the limit, as PX4 constrains
    it, every ground station hears its new value, and one above the limit is refused."""
    from tests.mavlink.test_offboard_refusals import _flying

    with _flying() as (server, conn):
        conn.mav.param_set_send(1, 1, b"MPC_XY_VEL_MAX", 0.5, M.MAV_PARAM_TYPE_REAL32)
        values = {}
        while len(values) < 2:
            value = wait_for(conn, "PARAM_VALUE", timeout_s=10)
            values[value.param_id] = value.param_value
        assert values == {"MPC_XY_VEL_MAX": 0.5, "MPC_XY_CRUISE": 0.5}
        assert statustext(conn, timeout_s=10) == (
            "MPC_XY_CRUISE constrained to 0.5 by MPC_XY_VEL_MAX")
        # a reposition at the cruise speed (p1 -1): flown at the limit
        conn.mav.command_int_send(1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                  M.MAV_CMD_DO_REPOSITION, 0, 0, -1, 1, 0, math.nan,
                                  490_000_900, 80_000_000, 2.0)
        ack = wait_for(conn, "COMMAND_ACK", lambda m: m.command == M.MAV_CMD_DO_REPOSITION)
        assert ack.result == M.MAV_RESULT_ACCEPTED
        with server.lock:
            name, args = server.vehicle.boards.airframe.calls[-1]
        assert name == "fly_to" and args[-1] == 0.5, (name, args)
        conn.mav.param_set_send(1, 1, b"MPC_XY_CRUISE", 0.8, M.MAV_PARAM_TYPE_REAL32)
        value = wait_for(conn, "PARAM_VALUE", timeout_s=10)
        assert (value.param_id, value.param_value) == ("MPC_XY_CRUISE", 0.5)
        assert statustext(conn, timeout_s=10) == (
            "MPC_XY_CRUISE: must be at most MPC_XY_VEL_MAX, 0.5 m/s, not 0.8")
        assert server.errors == 0
