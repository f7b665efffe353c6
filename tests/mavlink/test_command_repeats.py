"""A command sent again within a second (a ground station resending because an answer was lost):
an action is not run twice and gets its first COMMAND_ACK again, however its unused parameters
are filled (MAVSDK sends NaN for each, and NaN != NaN once made every resend look new: a take-off
resent was refused "not landed" after the first was accepted); a request for a message is
answered again, message and all (the second REQUEST_MESSAGE once got only its COMMAND_ACK).
A repeat after the vehicle's mode, arming or flight state moved on is a new command: arm,
disarm, arm within a second once left the vehicle disarmed with the last arm ACCEPTED; so is
A after B (A, B, A); a running mission's own progress is no change."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from pymavlink import mavutil

from skeye.mavlink.modes import Program, Px4Mode
from skeye.pilot import mavlink_vehicle
from skeye.pilot.mavlink_server import MavlinkServer
from skeye.wire.packets import NavState
from tests.mavlink.conftest import GCS, scripted_endpoint, wait_for

M = mavutil.mavlink


def _client(server):
    port = int(server.addresses[0].rsplit(":", 1)[1])
    return mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=GCS[0],
                                      source_component=GCS[1])


def _ack(conn, cmd: int) -> int:
    return int(wait_for(conn, "COMMAND_ACK", lambda m: m.command == cmd, timeout_s=10).result)


def _send(conn, cmd: int, *params: float, confirmation: int = 0) -> int:
    """COMMAND_LONG (parameters as given, the rest NaN as MAVSDK leaves them); its ACK's result."""
    conn.mav.command_long_send(1, 1, cmd, confirmation,
                               *params, *([math.nan] * (7 - len(params))))
    return _ack(conn, cmd)


@contextmanager
def _station() -> Iterator[tuple[MavlinkServer, Any]]:
    """The scripted endpoint and a ground station's client of it, heard from once."""
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        conn = _client(server)
        try:
            wait_for(conn, "HEARTBEAT")
            yield server, conn
        finally:
            conn.close()


def _take_off(server: MavlinkServer, conn) -> None:
    """Arm, take off, and the scripted climb ends at 2.5 m: the vehicle hovers (HOLDING)."""
    assert _send(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == M.MAV_RESULT_ACCEPTED
    assert _send(conn, M.MAV_CMD_NAV_TAKEOFF) == M.MAV_RESULT_ACCEPTED
    boards = server.vehicle.boards
    with server.lock:
        boards.airframe.finish(landed=False, pos_ned_m=(0.0, 0.0, -2.5), time_s=1.0)
        boards.tick(1.0)
    assert boards.state is NavState.HOLDING


@pytest.fixture
def wide_window(monkeypatch: pytest.MonkeyPatch) -> None:
    """The resend window at a minute instead of 1 s of wall time: what these tests send "within
    the window" stays within it on a machine as busy as it may be."""
    monkeypatch.setattr(mavlink_vehicle, "DUPLICATE_WINDOW_S", 60.0)


def test_a_take_off_resent_with_nan_parameters_gets_the_same_ack_and_runs_once():
    with _station() as (server, conn):
        # As MAVSDK's action.arm() and action.takeoff() send them: unset parameters NaN.
        assert _send(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == M.MAV_RESULT_ACCEPTED
        for confirmation in (0, 1):  # the resend, as MAVSDK numbers it
            assert (_send(conn, M.MAV_CMD_NAV_TAKEOFF, confirmation=confirmation)
                    == M.MAV_RESULT_ACCEPTED)
        calls = [c for c in server.vehicle.boards.airframe.calls if c[0] == "take_off"]
        assert len(calls) == 1
        assert server.errors == 0


def test_a_command_repeated_after_the_vehicle_changed_is_run_again(wide_window: None):
    with _station() as (server, conn):
        for arm in (1.0, 0.0, 1.0):  # well within the second a resend is looked for
            assert _send(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, arm) == M.MAV_RESULT_ACCEPTED
            assert server.vehicle.armed == bool(arm)
        assert server.errors == 0


def test_a_take_off_repeated_once_its_climb_ended_is_refused_as_in_the_air(wide_window: None):
    """The same NAV_TAKEOFF again, after the first one's climb ended in a hover: the flight
    state moved on (TAKING_OFF -> HOLDING), so it is a new command, refused in the air (CI's
    failure of test_commands_out_of_range_are_refused_with_their_reason: a fast lockstep
    climb within the resend window, and the repeat got the first take-off's ACCEPTED)."""
    with _station() as (server, conn):
        _take_off(server, conn)
        assert _send(conn, M.MAV_CMD_NAV_TAKEOFF) == M.MAV_RESULT_TEMPORARILY_REJECTED
        assert [c[0] for c in server.vehicle.boards.airframe.calls].count("take_off") == 1
        assert server.errors == 0


def test_a_request_for_a_message_repeated_at_once_is_answered_each_time():
    with _station() as (_server, conn):
        for _ in range(2):  # AUTOPILOT_VERSION and MESSAGE_INTERVAL are never streamed
            assert (_send(conn, M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                          0, 0, 0, 0, 0, 0) == M.MAV_RESULT_ACCEPTED)
            wait_for(conn, "AUTOPILOT_VERSION", timeout_s=10)
        for _ in range(2):
            assert (_send(conn, M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE,
                          0, 0, 0, 0, 0, 0) == M.MAV_RESULT_ACCEPTED)
            reply = wait_for(conn, "MESSAGE_INTERVAL", timeout_s=10)
            assert (reply.message_id, reply.interval_us) == (M.MAVLINK_MSG_ID_ATTITUDE, 50_000)


def _upload_take_off_mission(conn) -> None:
    """A take-off to 2.5 m where the vehicle stands, then a waypoint 10 m north of it."""
    items = [(M.MAV_CMD_NAV_TAKEOFF, 0, 0), (M.MAV_CMD_NAV_WAYPOINT, 490000900, 80000000)]
    conn.mav.mission_count_send(1, 1, len(items), M.MAV_MISSION_TYPE_MISSION)
    while True:
        msg = wait_for(conn, ["MISSION_REQUEST_INT", "MISSION_ACK"], timeout_s=10)
        if msg.get_type() == "MISSION_ACK":
            assert msg.type == M.MAV_MISSION_ACCEPTED
            return
        cmd, lat, lon = items[msg.seq]
        conn.mav.mission_item_int_send(
            1, 1, msg.seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd, int(msg.seq == 0), 1,
            0, 0.5, 0, math.nan, lat, lon, 2.5, M.MAV_MISSION_TYPE_MISSION)


@pytest.mark.parametrize("start", ["MISSION_START", "DO_SET_MODE"])
def test_a_mission_start_resent_after_its_take_off_began_is_not_run_again(start: str,
                                                                          wide_window: None):
    """MAVSDK resends a command whose ACK it did not get within 0.5 s, unchanged. A mission
    started on the ground takes off at the endpoint's next tick, so the resend finds the
    flight state moved on (LANDED -> TAKING_OFF) by the mission itself: it is the same
    command, and was run again (the mission restarted at its take-off item in the air, which
    the climb refused as busy: "mission stopped"). MAVSDK's start_mission sends DO_SET_MODE
    (Mission); MISSION_START is the command's own way."""
    with _station() as (server, conn):
        assert _send(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == M.MAV_RESULT_ACCEPTED
        _upload_take_off_mission(conn)
        if start == "MISSION_START":
            cmd, params = M.MAV_CMD_MISSION_START, (0.0, 1.0)
        else:
            main, sub = Px4Mode.MISSION.value
            cmd = M.MAV_CMD_DO_SET_MODE
            params = (float(M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(main), float(sub))
        boards = server.vehicle.boards
        assert _send(conn, cmd, *params) == M.MAV_RESULT_ACCEPTED
        wait_for(conn, ["ATTITUDE", "HEARTBEAT", "SYS_STATUS", "LOCAL_POSITION_NED"],
                 lambda m: boards.state is NavState.TAKING_OFF, timeout_s=10)
        # MAVSDK's resend, 0.5 s after the first (here within the widened window): the very
        # same message again
        assert _send(conn, cmd, *params) == M.MAV_RESULT_ACCEPTED
        # The endpoint's next tick (it runs the programs before its streams: an ATTITUDE
        # after the ACK comes from a tick after the resend), still mid-climb
        msg = wait_for(conn, ["ATTITUDE", "STATUSTEXT"], timeout_s=10)
        assert msg.get_type() == "ATTITUDE", msg.to_dict()
        assert server.vehicle.program is Program.MISSION
        with server.lock:  # the climb ends: the mission goes on to its waypoint
            boards.airframe.finish(landed=False, pos_ned_m=(0.0, 0.0, -2.5), time_s=1.0)
            boards.tick(1.0)
        msg = wait_for(conn, ["MISSION_ITEM_REACHED", "STATUSTEXT"],
                       lambda m: m.get_type() != "STATUSTEXT" or m.text.startswith("mission"),
                       timeout_s=10)
        assert msg.get_type() == "MISSION_ITEM_REACHED" and msg.seq == 0, msg.to_dict()
        assert [c[0] for c in boards.airframe.calls].count("take_off") == 1
        assert server.vehicle.program is Program.MISSION
        assert server.errors == 0


def test_a_command_repeated_after_another_of_its_kind_is_run_again(wide_window: None):
    """A, B, A within a second: the second A is no retransmission of the first (a ground
    station retransmits only the command it is waiting on, and MAVSDK sends no second command
    of an id while one is waiting), yet neither changes the mode, the arming or the flight
    state: it got the first A's ACK and was not run, and B stayed (a speed, a message's
    interval; a reposition's target the same way)."""
    with _station() as (server, conn):
        for speed in (2.0, 1.0, 2.0):
            assert (_send(conn, M.MAV_CMD_DO_CHANGE_SPEED, 1.0, speed, -1.0)
                    == M.MAV_RESULT_ACCEPTED)
            assert server.vehicle.cruise_m_s == speed
        for interval_us in (100_000.0, 500_000.0, 100_000.0):
            assert (_send(conn, M.MAV_CMD_SET_MESSAGE_INTERVAL, float(M.MAVLINK_MSG_ID_ATTITUDE),
                          interval_us) == M.MAV_RESULT_ACCEPTED)
            scheduler = server.vehicle.links[0].scheduler
            assert scheduler.interval_s(M.MAVLINK_MSG_ID_ATTITUDE) == interval_us / 1e6
        # In the air, a reposition (COMMAND_INT) to A, to B, to A: it flies to A.
        _take_off(server, conn)
        for lat_e7 in (490000900, 490001800, 490000900):
            conn.mav.command_int_send(1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                      M.MAV_CMD_DO_REPOSITION, 0, 0, -1.0, 0.0, 0.0,
                                      math.nan, lat_e7, 80000000, 2.0)
            assert _ack(conn, M.MAV_CMD_DO_REPOSITION) == M.MAV_RESULT_ACCEPTED
        airframe = server.vehicle.boards.airframe
        moves = [c[1] for c in airframe.calls if c[0] in ("fly_to", "fly_to_gps")]
        assert len(moves) == 3 and moves[0] == moves[2] != moves[1], moves
        assert server.errors == 0
