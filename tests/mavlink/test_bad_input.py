"""Bad input over MAVLink: every malformed or unknown message, out-of-range command, absurd
mission, second ground station and flood gets its COMMAND_ACK / MISSION_ACK / STATUSTEXT, and
the vehicle keeps flying (hovering where it was, answering the next command)."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as dialect

from tests.mavlink.conftest import (
    GCS,
    MavVehicle,
    command,
    free_udp_port,
    ground_station,
    mav_vehicle,
    scripted_endpoint,
    statustext,
    take_off,
    wait_for,
)

M = mavutil.mavlink


def _airborne(v: MavVehicle):
    conn = v.client()
    wait_for(conn, "GLOBAL_POSITION_INT")
    take_off(conn)
    return conn


def _where(conn) -> tuple[float, float, float]:
    """The vehicle's own position estimate (LOCAL_POSITION_NED), which its hover holds."""
    msg = wait_for(conn, "LOCAL_POSITION_NED")
    return (msg.x, msg.y, msg.z)


def _still_hovering(v: MavVehicle, conn, where: tuple[float, float, float]) -> None:
    """The vehicle holds where it was (its estimate within 0.2 m) and answers a command."""
    hb = wait_for(conn, "HEARTBEAT", lambda m: True)
    assert mavutil.mode_string_v10(hb) == "LOITER"
    assert hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
    assert math.dist(_where(conn), where) < 0.2
    assert command(conn, M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION)[0] == 0
    assert v.mavlink.errors == 0


@pytest.fixture
def flying() -> Iterator[tuple[MavVehicle, object]]:
    with mav_vehicle() as v:
        yield v, _airborne(v)


def test_malformed_and_unknown_messages_are_answered_and_change_nothing(flying):
    v, conn = flying
    where = _where(conn)
    send = conn.write  # raw bytes from the client's own socket: the answers come back there
    unknown = bytes([0xFD, 2, 0, 0, 7, 255, 190]) + (60000).to_bytes(3, "little") + b"ab\0\0"
    send(unknown)
    text = statustext(conn)
    assert "unknown message id 60000" in text
    mav = dialect.MAVLink(None, 255, 190)
    frame = bytearray(mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav))
    frame[-1] ^= 0xFF
    time.sleep(2.1)  # one notice per kind every 2 s
    send(bytes(frame))
    assert "bad MAVLink frame" in statustext(conn)
    send(b"\xfd" + bytes(range(256)) * 3)
    _still_hovering(v, conn, where)
    assert v.mavlink.vehicle.bad_frames >= 3


def test_commands_out_of_range_are_refused_with_their_reason(flying):
    v, conn = flying
    where = _where(conn)
    result, text = command(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 7)
    assert result == M.MAV_RESULT_DENIED and "param1 must be 0 or 1" in text
    result, text = command(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 21196)
    assert result == M.MAV_RESULT_DENIED and "never stops its motors in the air" in text
    result, text = command(conn, M.MAV_CMD_DO_CHANGE_SPEED, 1, 50.0)
    assert result == M.MAV_RESULT_DENIED and "at most 3 m/s" in text
    result, text = command(conn, 31999)
    assert result == M.MAV_RESULT_UNSUPPORTED and "not supported" in text
    result, text = command(conn, M.MAV_CMD_SET_MESSAGE_INTERVAL, 9999, 1000)
    assert result == M.MAV_RESULT_DENIED and "not streamed" in text
    result, text = command(conn, M.MAV_CMD_SET_MESSAGE_INTERVAL,
                           M.MAVLINK_MSG_ID_ATTITUDE, 10)  # 100 kHz
    assert result == M.MAV_RESULT_DENIED and "out of range" in text
    result, text = command(conn, M.MAV_CMD_SET_MESSAGE_INTERVAL,
                           M.MAVLINK_MSG_ID_ATTITUDE, -0.5)  # was taken as 0: the default
    assert result == M.MAV_RESULT_DENIED and "give -1 (stop), 0 (the default rate)" in text
    result, text = command(conn, M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 5)
    assert result == M.MAV_RESULT_DENIED and "ACRO" in text
    result, text = command(conn, M.MAV_CMD_NAV_TAKEOFF, *[0.0] * 6, math.nan)
    assert result == M.MAV_RESULT_TEMPORARILY_REJECTED and "take off" in text
    # 2 km north: outside the flight envelope's 500 m radius, refused by the boards themselves.
    pos = wait_for(conn, "GLOBAL_POSITION_INT")
    conn.mav.command_int_send(1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_DO_REPOSITION,
                              0, 0, -1, 1, 0, math.nan, pos.lat + 180_000, pos.lon, 2.0)
    ack = wait_for(conn, "COMMAND_ACK", lambda m: m.command == M.MAV_CMD_DO_REPOSITION)
    assert ack.result == M.MAV_RESULT_DENIED
    assert "outside the flight envelope" in statustext(conn)
    # The speed limit: a reposition faster than the robot file's 3 m/s is refused, not capped.
    conn.mav.command_int_send(1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_DO_REPOSITION,
                              0, 0, 5.0, 1, 0, math.nan, pos.lat + 100, pos.lon, 2.0)
    ack = wait_for(conn, "COMMAND_ACK", lambda m: m.command == M.MAV_CMD_DO_REPOSITION)
    assert ack.result == M.MAV_RESULT_DENIED
    assert "over this vehicle's limit of 3 m/s" in statustext(conn)
    # Parameters: out of range and unknown names are refused, the value stays.
    conn.mav.param_set_send(1, 1, b"MPC_XY_VEL_MAX", 99.0, M.MAV_PARAM_TYPE_REAL32)
    echo = wait_for(conn, "PARAM_VALUE", lambda m: m.param_id == "MPC_XY_VEL_MAX")
    assert echo.param_value == pytest.approx(3.0)
    assert "must be 0.1..3" in statustext(conn)
    conn.mav.param_set_send(1, 1, b"NO_SUCH_PARAM", 1.0, M.MAV_PARAM_TYPE_REAL32)
    assert "no parameter 'NO_SUCH_PARAM'" in statustext(conn)
    assert v.mavlink.vehicle.acks.get(M.MAV_RESULT_ACCEPTED, 0) >= 2
    _still_hovering(v, conn, where)


def _reposition(conn, speed: float, lat_e7: int, lon_e7: int, alt_m: float,
                reason: bool = True) -> tuple[int, str]:
    """DO_REPOSITION (COMMAND_INT, GLOBAL_INT) as QGroundControl sends it; its COMMAND_ACK's
    result and (``reason``) the STATUSTEXT that follows a refusal (the same reason again
    within 2 s gets none)."""
    conn.mav.command_int_send(1, 1, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_DO_REPOSITION, 0, 0,
                              speed, 1, 0, math.nan, lat_e7, lon_e7, alt_m)
    ack = wait_for(conn, "COMMAND_ACK", lambda m: m.command == M.MAV_CMD_DO_REPOSITION)
    return int(ack.result), "" if ack.result == 0 or not reason else statustext(conn)


def test_a_reposition_with_bad_values_is_refused_naming_the_value():
    """Each bad DO_REPOSITION gets DENIED and a STATUSTEXT naming the field and why, never an
    encoding message of the boards' packets, and no exception in the endpoint: an infinite
    altitude once raised OverflowError (no ACK at all), an infinite speed was flown at cruise,
    100 m/s and latitude 95 came back as "MoveBy.speed=100000 outside 0..65535" and
    "MoveBy.dx=... outside ...". The vehicle is the scripted one (landed, GPS at 49 N 8 E):
    these checks come before the boards' own (which would say "landed")."""
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        with ground_station(server) as conn:
            pos = wait_for(conn, "GLOBAL_POSITION_INT")
            lat, lon = pos.lat, pos.lon
            cases = [
                ((-1.0, lat, lon, math.inf), ["altitude (z) inf"]),
                ((-1.0, lat, lon, -math.inf), ["altitude (z) -inf"]),
                ((math.inf, lat, lon, math.nan), ["ground speed (p1) inf"]),
                ((-math.inf, lat, lon, math.nan), ["ground speed (p1) -inf"]),
                ((100.0, lat + 100, lon, math.nan),
                 ["speed 100 m/s is over this vehicle's limit of 3 m/s"]),
                ((-1.0, 950_000_000, lon, math.nan), ["latitude (x) 95", "-90..90"]),
                ((-1.0, lat, 2_000_000_000, math.nan), ["longitude (y) 200", "-180..180"]),
                ((-1.0, lat + 4_500_000, lon, math.nan), ["outside the flight envelope"]),
                # 10 000 km down gave "MoveBy.dz=... outside": the number is bounded first.
                ((-1.0, lat, lon, -1e7), ["altitude (z) -1e+07 m", "below the lowest land"]),
                ((-1.0, lat, lon, -430.5), ["-430.5 m above mean sea level"]),
            ]
            for (speed, x, y, z), words in cases:
                result, text = _reposition(conn, speed, x, y, z)
                assert result == M.MAV_RESULT_DENIED, (speed, x, y, z, result, text)
                assert "MoveBy" not in text and all(w in text for w in words), (words, text)
            # Cruise (-1, any speed <= 0, NaN as MAVSDK's goto_location sends) still reaches
            # the boards, which refuse a landed vehicle for that reason.
            for speed in (-1.0, 0.0, math.nan):
                result, _ = _reposition(conn, speed, lat + 100, lon, math.nan, reason=False)
                assert result == M.MAV_RESULT_TEMPORARILY_REJECTED, speed
            # Just above the lowest land, but below home: the flight envelope's floor.
            result, text = _reposition(conn, -1.0, lat, lon, -429.5)
            assert result == M.MAV_RESULT_DENIED and "below home" in text, text
            # 1 m above home, the target passes to the boards too.
            result, _ = _reposition(conn, -1.0, lat, lon, pos.alt / 1000.0 + 1.0, reason=False)
            assert result == M.MAV_RESULT_TEMPORARILY_REJECTED
            assert server.errors == 0


def test_a_take_off_altitude_that_is_no_number_or_past_space_is_refused_naming_param7():
    """NAV_TAKEOFF's param7 infinite was refused as "inf m AMSL is not at least 0.1 m above
    the vehicle"; 1e30 reached the boards' packet and came back as its encoder's
    "TakeOff.height=1000000015047466219876688855040000 outside 1..2147483647"."""
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        with ground_station(server) as conn:
            assert command(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)[0] == M.MAV_RESULT_ACCEPTED
            for alt, words in ((math.inf, "(param7) inf m is not a finite number"),
                               (-math.inf, "(param7) -inf m is not a finite number"),
                               (1e30, "(param7) 1e+30 m above mean sea level is over 100000 m")):
                result, text = command(conn, M.MAV_CMD_NAV_TAKEOFF, *[0.0] * 6, alt)
                assert result == M.MAV_RESULT_DENIED and words in text, (alt, text)
            assert server.errors == 0


def _mission_ack(conn, item: dict, count: int = 1) -> tuple[int, str]:
    conn.mav.mission_count_send(1, 1, count, M.MAV_MISSION_TYPE_MISSION)
    msg = wait_for(conn, ["MISSION_REQUEST_INT", "MISSION_ACK"])
    if msg.get_type() == "MISSION_REQUEST_INT":
        fields = dict(seq=0, frame=M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                      command=M.MAV_CMD_NAV_WAYPOINT, current=1, autocontinue=1, param1=0.0,
                      param2=0.5, param3=0.0, param4=math.nan, x=0, y=0, z=2.0)
        fields.update(item)
        conn.mav.mission_item_int_send(1, 1, *fields.values(), M.MAV_MISSION_TYPE_MISSION)
        msg = wait_for(conn, "MISSION_ACK")
    text = "" if msg.type == 0 else statustext(conn)
    return int(msg.type), text


def test_a_mission_with_absurd_items_is_refused_and_the_old_one_kept(flying):
    v, conn = flying
    where = _where(conn)
    pos = wait_for(conn, "GLOBAL_POSITION_INT")
    good = dict(x=pos.lat + 100, y=pos.lon, z=2.0)
    assert _mission_ack(conn, good)[0] == M.MAV_MISSION_ACCEPTED
    cases = [
        (dict(x=pos.lat, y=pos.lon, z=math.nan), M.MAV_MISSION_INVALID_PARAM7, "not a number"),
        (dict(x=2_000_000_000, y=pos.lon), M.MAV_MISSION_INVALID_PARAM5_X, "latitude"),
        (dict(x=pos.lat, y=pos.lon, z=5000.0), M.MAV_MISSION_INVALID_PARAM7, "ceiling"),
        (dict(x=pos.lat, y=pos.lon, z=-1e7), M.MAV_MISSION_INVALID_PARAM7, "lowest land"),
        (dict(x=pos.lat + 90_000, y=pos.lon), M.MAV_MISSION_INVALID_PARAM5_X, "radius"),
        (dict(command=M.MAV_CMD_DO_SET_SERVO), M.MAV_MISSION_UNSUPPORTED, "not supported"),
        (dict(frame=M.MAV_FRAME_LOCAL_NED, x=1, y=1), M.MAV_MISSION_UNSUPPORTED_FRAME, "frame"),
    ]
    for item, code, words in cases:
        time.sleep(0.05)
        result, text = _mission_ack(conn, item)
        assert (result, words in text) == (code, True), (item, result, text)
    result, text = _mission_ack(conn, {}, count=60_000)
    assert result == M.MAV_MISSION_NO_SPACE and "at most 500" in text
    conn.mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
    assert wait_for(conn, "MISSION_COUNT").count == 1
    conn.mav.mission_request_int_send(1, 1, 0, M.MAV_MISSION_TYPE_MISSION)
    kept = wait_for(conn, "MISSION_ITEM_INT")
    assert (kept.x, kept.y) == (good["x"], good["y"])
    _still_hovering(v, conn, where)


def test_a_second_ground_station_is_served_and_both_are_told():
    port = free_udp_port()
    with mav_vehicle(uris=[f"udp://127.0.0.1:{port}"]) as v:
        first = v.keep(mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}",
                                                  source_system=GCS[0], source_component=GCS[1]))
        wait_for(first, "HEARTBEAT")
        second = v.keep(mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}",
                                                   source_system=254, source_component=190))
        second.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        for conn in (first, second):
            note = wait_for(conn, "STATUSTEXT", lambda m: "joined" in m.text)
            assert "254/190 joined; 2 connected" in note.text
        assert command(second, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)[0] == 0
        assert command(first, M.MAV_CMD_COMPONENT_ARM_DISARM, 0)[0] == 0
        # The last command won: both stations hear the vehicle disarmed.
        for conn in (first, second):
            wait_for(conn, "HEARTBEAT", lambda m: not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
        assert not v.pilot.boards.motors_on
        assert len(v.mavlink.transports[0].peers) == 2


def test_each_ground_station_is_told_its_reposition_yaw_is_not_flown():
    """The notice is limited per ground station (one every 2 s), not for all: a second station
    repositioning with a yaw right after the first is told too (it once heard nothing)."""
    port = free_udp_port()
    with mav_vehicle(uris=[f"udp://127.0.0.1:{port}"]) as v:
        first = v.keep(mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}",
                                                  source_system=GCS[0], source_component=GCS[1]))
        second = v.keep(mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}",
                                                   source_system=254, source_component=190))
        for conn in (first, second):
            conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            wait_for(conn, "HEARTBEAT")
        pos = wait_for(first, "GLOBAL_POSITION_INT")
        assert command(first, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)[0] == 0
        assert command(first, M.MAV_CMD_NAV_TAKEOFF, *[0.0] * 6, math.nan)[0] == 0
        wait_for(first, "HEARTBEAT", lambda m: mavutil.mode_string_v10(m) == "LOITER"
                 and m.system_status == M.MAV_STATE_ACTIVE)
        for conn in (first, second):  # back to back: well within the 2 s
            conn.mav.command_int_send(1, 1, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_DO_REPOSITION,
                                      0, 0, -1, 1, 0, 90.0, pos.lat + 50, pos.lon, math.nan)
            ack = wait_for(conn, "COMMAND_ACK", lambda m: m.command == M.MAV_CMD_DO_REPOSITION)
            assert ack.result == M.MAV_RESULT_ACCEPTED
            wait_for(conn, "STATUSTEXT", lambda m: "yaw (p4) 90 deg is not flown" in m.text,
                     timeout_s=10.0)


def test_a_flood_of_10000_messages_leaves_the_vehicle_flying(flying):
    v, conn = flying
    where = _where(conn)
    mav = dialect.MAVLink(None, 255, 190)
    junk = [
        mav.command_long_encode(1, 1, 31999, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav),
        mav.param_request_read_encode(1, 1, b"NOPE", -1).pack(mav),
        mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav),
        b"\xfd\x09garbage!garbage!",
        mav.mission_item_int_encode(1, 1, 7, 6, 16, 0, 1, 0, 0, 0, 0, 1, 1, 1, 0).pack(mav),
    ]
    before = v.mavlink.received
    deadline = time.monotonic() + 300  # a stuck guard: the flood takes seconds
    for k in range(10_000):
        conn.write(junk[k % len(junk)])
        # As fast as the vehicle reads: a burst beyond the kernel's socket buffer would only
        # be dropped there (UDP), never reaching the vehicle.
        while k - (v.mavlink.received - before) > 100:
            assert time.monotonic() < deadline, "the vehicle stopped reading"
            time.sleep(0.001)
    while v.mavlink.received - before < 10_000:
        assert time.monotonic() < deadline, "the vehicle stopped reading"
        time.sleep(0.01)
    _still_hovering(v, conn, where)
    assert v.mavlink.vehicle.bad_frames >= 2000  # the garbage was seen as such


def test_a_silent_ground_station_triggers_the_link_loss_failsafe(flying):
    """The failsafe of the AscTec link, over MAVLink: no message from any ground station for
    COM_DL_LOSS_T and the vehicle hovers in FAILSAFE (MAV_STATE_CRITICAL); messages again stop
    the land countdown, and a mode command takes it back."""
    v, conn = flying
    conn.mav.param_set_send(1, 1, b"COM_DL_LOSS_T", 1.0, M.MAV_PARAM_TYPE_REAL32)
    wait_for(conn, "PARAM_VALUE", lambda m: m.param_id == "COM_DL_LOSS_T")
    assert v.pilot.boards.settings.link_timeout_s == 1.0
    critical = wait_for(conn, "HEARTBEAT", lambda m: m.system_status == M.MAV_STATE_CRITICAL,
                        heartbeat=False)
    assert mavutil.mode_string_v10(critical) == "LOITER"
    assert v.pilot.boards.state.name == "FAILSAFE"
    hold = conn.mode_mapping()["LOITER"]
    assert command(conn, M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                   *hold[1:])[0] == 0
    wait_for(conn, "HEARTBEAT", lambda m: m.system_status == M.MAV_STATE_ACTIVE)
    assert v.pilot.boards.state.name == "HOLDING"
