"""The parameter list is for the system it is asked of: a PARAM_REQUEST_LIST for another system
(a second vehicle on the same link) was answered with this vehicle's whole list (a probe of
2026-11-27 with pymavlink); PX4 answers only its own system's, as for PARAM_REQUEST_READ and
PARAM_SET."""

from __future__ import annotations

from pymavlink import mavutil

from tests.mavlink.conftest import GCS, scripted_endpoint, wait_for

M = mavutil.mavlink


def test_a_parameter_list_asked_of_another_system_is_not_answered():
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        port = int(server.addresses[0].rsplit(":", 1)[1])
        conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=GCS[0],
                                          source_component=GCS[1])
        try:
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
        finally:
            conn.close()
