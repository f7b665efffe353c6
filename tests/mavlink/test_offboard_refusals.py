"""Offboard setpoints the vehicle cannot fly are refused in the user's terms: the message's
field, its value in metres (m/s, rad/s) and the limit it breaks, for every setpoint kind it
flies (position and velocity; SET_POSITION_TARGET_LOCAL_NED and _GLOBAL_INT). A local target
10 000 km down was once refused as "MoveBy.dz=10000002500 outside -2147483648..2147483647",
the overflow of an internal wire field, and a velocity of 40 m/s as "Velocity.vx=40000 outside
-32768..32767"; local targets were not checked against the ground as global ones are.

Against the endpoint on a scripted airframe (no simulator), a pymavlink ground station on
loopback UDP."""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from pymavlink import mavutil

from skeye.pilot.airframe import GpsFix
from skeye.pilot.boards import BoardSettings, OnboardBoards
from skeye.pilot.mavlink_server import MavlinkServer
from tests.mavlink.conftest import command, ground_station, statustext, wait_for
from tests.pilot.fake_airframe import FakeAirframe

M = mavutil.mavlink
NO_FIX = GpsFix(False, 0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0))  # a receiver indoors
POSITION_ONLY = 0b110111111000  # velocity, acceleration, yaw, yaw rate ignored
VELOCITY_ONLY = 0b010111000111  # position, acceleration, yaw ignored; the yaw rate used
OFFBOARD = (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 6)  # PX4's main mode OFFBOARD


@contextmanager
def _flying(gps: bool = True, settings: BoardSettings | None = None,
            ) -> Iterator[tuple[MavlinkServer, Any]]:
    """The endpoint over a scripted airframe hovering 2 m up at the local origin (with its GPS
    fix at 49 N 8 E, 100 m, or indoors without one), and a pymavlink ground station."""
    airframe = FakeAirframe()
    if not gps:
        airframe.snap = replace(airframe.snap, gps=NO_FIX)
    boards = OnboardBoards(airframe, settings)
    with MavlinkServer(boards, threading.Lock(), ["udp://127.0.0.1:0"]) as server:
        with ground_station(server) as conn:
            wait_for(conn, "HEARTBEAT", timeout_s=10)
            assert command(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)[0] == M.MAV_RESULT_ACCEPTED
            assert command(conn, M.MAV_CMD_NAV_TAKEOFF, *[0.0] * 6,
                           math.nan)[0] == M.MAV_RESULT_ACCEPTED
            with server.lock:
                airframe.finish(landed=False, pos_ned_m=(0.0, 0.0, -2.0), time_s=1.0)
                boards.tick(1.0)
            yield server, conn


def _local(conn: Any, mask: int, x: float = 0.0, y: float = 0.0, z: float = -2.0,
           vx: float = 0.0, vy: float = 0.0, vz: float = 0.0, yaw_rate: float = 0.0,
           frame: int = M.MAV_FRAME_LOCAL_NED) -> None:
    conn.mav.set_position_target_local_ned_send(0, 1, 1, frame, mask, x, y, z, vx, vy, vz,
                                                0, 0, 0, 0, yaw_rate)


def _offboard(conn: Any) -> None:
    """Into Offboard on a setpoint that holds where the vehicle is."""
    _local(conn, POSITION_ONLY)
    assert command(conn, M.MAV_CMD_DO_SET_MODE, *OFFBOARD)[0] == M.MAV_RESULT_ACCEPTED


def _refusal(conn: Any) -> str:
    """The next "offboard setpoint refused" STATUSTEXT's text."""
    while True:
        text = statustext(conn, timeout_s=10)
        if text.startswith("offboard setpoint refused: "):
            return text.removeprefix("offboard setpoint refused: ")


def test_local_position_setpoints_out_of_reach_are_refused_naming_the_field():
    with _flying() as (server, conn):
        _offboard(conn)
        # 10 000 km down, in LOCAL_NED and as an offset: below the lowest land on Earth
        # (the ground station's origin at 100 m above mean sea level)
        for frame, z_m in ((M.MAV_FRAME_LOCAL_NED, 1e7), (M.MAV_FRAME_LOCAL_OFFSET_NED, 2e7)):
            _local(conn, POSITION_ONLY, z=z_m, frame=frame)
            text = _refusal(conn)
            assert text.startswith(f"position setpoint: z {z_m:g} m puts the target "), text
            assert "below the lowest land on Earth (-430 m)" in text, text
        _local(conn, POSITION_ONLY, z=math.nan)
        assert _refusal(conn) == "position setpoint: z nan m is not a finite number"
        assert server.errors == 0


def test_without_an_origin_a_local_target_beyond_the_local_frame_is_refused():
    """Indoors (no GPS, no origin given) the ground's height above the sea is not known: a
    target deeper than a local frame reaches (100 km) is refused as that."""
    with _flying(gps=False) as (server, conn):
        _offboard(conn)
        _local(conn, POSITION_ONLY, z=1e7)
        assert _refusal(conn) == ("position setpoint: z 1e+07 m puts the target 1e+07 m below "
                                  "the local origin, beyond the 100 km a local position reaches")
        assert server.errors == 0


def test_velocity_setpoints_over_the_vehicles_limits_are_refused_naming_the_field():
    with _flying() as (server, conn):
        _offboard(conn)
        _local(conn, VELOCITY_ONLY, vx=40.0)
        assert _refusal(conn) == ("velocity setpoint: vx 40, vy 0 m/s is 40 m/s forward and "
                                  "0 m/s right of the heading, over this vehicle's limit of "
                                  "3 m/s on each (MPC_XY_VEL_MAX)")
        # Within the limit on each axis (3.5 m/s diagonally, as a policy's actions may ask):
        # flown (the refusal after it shows it was taken in turn)
        _local(conn, VELOCITY_ONLY, vx=2.5, vy=2.5)
        _local(conn, VELOCITY_ONLY, vz=-40.0)
        assert _refusal(conn) == ("velocity setpoint: vz -40 m/s is over this vehicle's "
                                  "climb and descent limit of 1.5 m/s")
        name, args = server.vehicle.boards.airframe.calls[-1]
        assert name == "set_velocity" and args[:3] == (2.5, 2.5, 0.0), (name, args)
        # Over the vehicle's yaw rate limit (the hummingbird's 1.745 rad/s) but within what a
        # VELOCITY carries: it reached the simulator, whose refusal was its own ("set_velocity:
        # yaw_rate_rad_s=3 exceeds the limit 1.745"), and this scripted airframe flew it
        for yaw_rate in (3.0, -40.0):
            _local(conn, VELOCITY_ONLY, yaw_rate=yaw_rate)
            assert _refusal(conn) == (f"velocity setpoint: yaw_rate {yaw_rate:g} rad/s is over "
                                      "this vehicle's limit of 1.745 rad/s")
        _local(conn, VELOCITY_ONLY, yaw_rate=-1.745)  # at the limit: flown
        _local(conn, VELOCITY_ONLY, vz=-41.0)  # a refusal after it: the yaw was taken in turn
        assert _refusal(conn).startswith("velocity setpoint: vz -41 m/s ")
        name, args = server.vehicle.boards.airframe.calls[-1]
        assert name == "set_velocity" and args[3] == pytest.approx(-1.745), (name, args)
        conn.mav.set_position_target_global_int_send(
            0, 1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, VELOCITY_ONLY, 0, 0, 0.0,
            0.0, -50.0, 0.0, 0, 0, 0, 0, 0)
        assert _refusal(conn) == ("velocity setpoint: vx 0, vy -50 m/s is 0 m/s forward and "
                                  "-50 m/s right of the heading, over this vehicle's limit of "
                                  "3 m/s on each (MPC_XY_VEL_MAX)")
        assert server.errors == 0


def test_global_position_setpoints_below_the_ground_are_refused_naming_the_field():
    with _flying() as (server, conn):
        _offboard(conn)
        conn.mav.set_position_target_global_int_send(
            0, 1, 1, M.MAV_FRAME_GLOBAL_INT, POSITION_ONLY, 490_000_000, 80_000_000, -1e7,
            0, 0, 0, 0, 0, 0, 0, 0)
        text = _refusal(conn)
        assert text.startswith("altitude (alt) -1e+07 m puts the target "), text
        assert "below the lowest land on Earth (-430 m)" in text, text
        assert server.errors == 0


def test_offboard_is_refused_with_the_reason_when_its_latest_setpoint_is():
    """DO_SET_MODE Offboard whose latest setpoint cannot be flown was ACCEPTED without a word
    (the setpoint's refusal was dropped), the mode Offboard with the vehicle holding; now it is
    refused with the setpoint's reason and the mode stays Hold, as PX4 refuses a mode whose
    requirements (for Offboard a valid setpoint stream) are not met."""
    with _flying() as (server, conn):
        hold = wait_for(conn, "HEARTBEAT", lambda h: mavutil.mode_string_v10(h) == "LOITER")
        for base_mode, send in (
                (OFFBOARD[0], lambda: _local(conn, POSITION_ONLY, z=1e7)),
                (OFFBOARD[0] | M.MAV_MODE_FLAG_SAFETY_ARMED,  # (another command: not a repeat)
                 lambda: _local(conn, VELOCITY_ONLY, vx=40.0))):
            send()
            result, text = command(conn, M.MAV_CMD_DO_SET_MODE, base_mode, OFFBOARD[1])
            assert result == M.MAV_RESULT_DENIED, (result, text)
            assert text.startswith("DO_SET_MODE: the latest offboard setpoint is refused: "
                                   f"{'position' if base_mode == OFFBOARD[0] else 'velocity'} "
                                   "setpoint: "), text
            after = wait_for(conn, "HEARTBEAT")
            assert after.custom_mode == hold.custom_mode, mavutil.mode_string_v10(after)
        assert server.vehicle.boards.airframe.names()[-1] == "take_off"  # nothing flown
        assert server.errors == 0


def test_a_limit_sent_as_a_float32_is_at_the_limit_not_over_it() -> None:
    """vx, vy, vz were compared with the limit + 1e-9: a robot file's MaxSpeed of 2.2 m/s,
    sent by a client as MAVLink's float32 (2.2000000477), would have been refused."""
    from skeye.pilot.mavlink_vehicle import _over

    for limit in (2.2, 1.745, 3.0, 0.1):
        sent = float(np.float32(limit))
        assert not _over(sent, limit) and not _over(-sent, limit)
        assert _over(limit * 1.001, limit) and _over(-limit * 1.001, limit)


def test_a_speed_limit_sent_as_a_float32_is_flown_at_the_limit() -> None:
    """DO_CHANGE_SPEED compared its speed with the limit + 1e-9 and DO_REPOSITION's went to the
    boards as it came: with a robot file's MaxSpeed of 2.2 m/s, the limit itself, as MAVLink's
    float32 carries it (2.2000000477), was refused by both. Now it is flown at 2.2 m/s."""
    with _flying(settings=BoardSettings(max_speed_m_s=2.2)) as (server, conn):
        airframe = server.vehicle.boards.airframe
        result, text = command(conn, M.MAV_CMD_DO_CHANGE_SPEED, 1, 2.2)
        assert result == M.MAV_RESULT_ACCEPTED, text
        assert server.vehicle.cruise_m_s == 2.2
        result, text = command(conn, M.MAV_CMD_DO_CHANGE_SPEED, 1, 2.21)  # over it: refused
        assert result == M.MAV_RESULT_DENIED and "at most 2.2 m/s" in text
        assert server.vehicle.cruise_m_s == 2.2
        for speed in (-1.0, 2.2):  # the cruise speed, then the limit given to the command
            conn.mav.command_int_send(1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                      M.MAV_CMD_DO_REPOSITION, 0, 0, speed, 1, 0, math.nan,
                                      490_000_900, 80_000_000, 2.0)  # 10 m north
            ack = wait_for(conn, "COMMAND_ACK", lambda m: m.command == M.MAV_CMD_DO_REPOSITION)
            assert ack.result == M.MAV_RESULT_ACCEPTED, (speed, ack, statustext(conn))
            with server.lock:
                name, args = airframe.calls[-1]
            assert name == "fly_to" and args[-1] == pytest.approx(2.2, abs=1e-3), (speed, args)
        assert server.errors == 0


def test_a_setpoint_in_a_frame_not_flown_is_refused_naming_the_frame() -> None:
    """A setpoint's frame that is none of those the vehicle flies was flown as another: a
    LOCAL_ENU velocity 0.5 m/s east went north, a GLOBAL_TERRAIN_ALT_INT altitude was taken as
    above mean sea level (a probe of 2026-11-28 with pymavlink). PX4 drops such a setpoint
    ("invalid coordinate frame"); here it is refused naming the frame, and nothing is flown."""
    with _flying() as (server, conn):
        airframe = server.vehicle.boards.airframe
        _offboard(conn)
        with server.lock:
            flown = len(airframe.calls)
        _local(conn, VELOCITY_ONLY, vx=0.5, frame=M.MAV_FRAME_LOCAL_ENU)
        assert _refusal(conn) == ("coordinate_frame 4 (LOCAL_ENU) is not flown: give LOCAL_NED, "
                                  "LOCAL_OFFSET_NED, BODY_NED, BODY_OFFSET_NED or BODY_FRD")
        conn.mav.set_position_target_global_int_send(
            0, 1, 1, M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, POSITION_ONLY, 490_000_000, 80_000_000,
            2.0, 0, 0, 0, 0, 0, 0, 0, 0)
        assert _refusal(conn) == ("coordinate_frame 11 (GLOBAL_TERRAIN_ALT_INT) is not flown: "
                                  "give GLOBAL_INT or GLOBAL_RELATIVE_ALT_INT")
        _local(conn, VELOCITY_ONLY, vx=0.5)  # in a frame flown: flown
        _local(conn, VELOCITY_ONLY, vz=-40.0)  # a refusal after it: the one before was taken
        assert _refusal(conn).startswith("velocity setpoint: vz -40 m/s ")
        with server.lock:
            calls = airframe.calls[flown:]
        assert calls == [("set_velocity", (0.5, 0.0, 0.0, 0.0, 1.0))], calls
        assert server.errors == 0


def test_a_velocity_axis_ignored_in_the_type_mask_is_not_flown() -> None:
    """A velocity setpoint with vz ignored in type_mask (bit 32) was flown with whatever vz
    held: NaN refused the whole setpoint ("vz nan m/s is not a finite number"), 1 m/s descended
    (a probe of 2026-11-28 with pymavlink). An ignored axis is now not commanded (0), as a
    position axis ignored keeps the vehicle's own coordinate."""
    with _flying() as (server, conn):
        airframe = server.vehicle.boards.airframe
        _offboard(conn)
        with server.lock:
            flown = len(airframe.calls)
        _local(conn, VELOCITY_ONLY | 0b100000, vx=0.5, vz=math.nan)
        _local(conn, VELOCITY_ONLY | 0b11000, vx=-40.0, vy=math.nan, vz=1.0)
        _local(conn, VELOCITY_ONLY, vz=-40.0)  # a refusal after them: both were taken
        assert _refusal(conn).startswith("velocity setpoint: vz -40 m/s ")
        with server.lock:
            calls = airframe.calls[flown:]
        assert calls == [("set_velocity", (0.5, 0.0, 0.0, 0.0, 1.0)),
                         ("set_velocity", (0.0, 0.0, -1.0, 0.0, 1.0))], calls
        assert server.errors == 0


def test_change_speed_minus_two_returns_to_the_cruise_speed() -> None:
    """DO_CHANGE_SPEED's p2 -2 is "return to default vehicle speed" (the command's definition):
    it was refused ("speed -2 m/s: must be above 0 ...", a probe of 2026-11-28 with pymavlink),
    as was a mission's DO_CHANGE_SPEED item of -2 (``test_mission_protocol.py``)."""
    with _flying() as (server, conn):
        assert command(conn, M.MAV_CMD_DO_CHANGE_SPEED, 1, 2.0)[0] == M.MAV_RESULT_ACCEPTED
        assert server.vehicle.cruise_m_s == 2.0
        result, text = command(conn, M.MAV_CMD_DO_CHANGE_SPEED, 1, -2.0, -1)
        assert result == M.MAV_RESULT_ACCEPTED, text
        assert server.vehicle.cruise_m_s is None  # MPC_XY_CRUISE's again
        assert server.errors == 0


def test_a_reposition_to_int32_max_latitude_and_longitude_changes_only_the_altitude() -> None:
    """MAV_CMD's definition: "NaN and INT32_MAX may be used in float/integer params
    (respectively) to indicate optional/default values (e.g. to use the component's current yaw
    or latitude rather than a specific value)". DO_REPOSITION with x, y INT32_MAX was refused
    ("latitude (x) 214.748 deg is out of range -90..90", a probe of 2026-11-28 with pymavlink);
    it is an altitude change where the vehicle is."""
    with _flying() as (server, conn):
        airframe = server.vehicle.boards.airframe
        int32_max = 2**31 - 1
        conn.mav.command_int_send(1, 1, M.MAV_FRAME_GLOBAL, M.MAV_CMD_DO_REPOSITION, 0, 0,
                                  -1, 1, 0, math.nan, int32_max, int32_max, 103.0)
        ack = wait_for(conn, "COMMAND_ACK", lambda m: m.command == M.MAV_CMD_DO_REPOSITION)
        assert ack.result == M.MAV_RESULT_ACCEPTED, statustext(conn)
        with server.lock:
            name, args = airframe.calls[-1]
        # from 2 m over the origin (100 m above mean sea level) to 103 m: 3 m up, in place
        assert name == "fly_to" and args[:3] == pytest.approx((0.0, 0.0, 3.0), abs=1e-3), args
        assert server.errors == 0


def test_a_reposition_sent_as_command_long_is_flown() -> None:
    """DO_REPOSITION as COMMAND_LONG (p5, p6 latitude and longitude in degrees, NaN for here;
    p7 above mean sea level), as QGroundControl's PX4 plugin sends its altitude change, was
    refused ("DO_REPOSITION is a COMMAND_INT", a probe of 2026-11-28 with pymavlink); PX4 flies
    either form."""
    with _flying() as (server, conn):
        airframe = server.vehicle.boards.airframe
        result, text = command(conn, M.MAV_CMD_DO_REPOSITION, -1, 1, 0, math.nan, math.nan,
                               math.nan, 103.0)
        assert result == M.MAV_RESULT_ACCEPTED, text
        with server.lock:
            name, args = airframe.calls[-1]
        assert name == "fly_to" and args[:3] == pytest.approx((0.0, 0.0, 3.0), abs=1e-3), args
        # 10 m north (1e-7 deg of latitude is 1.1 cm), at 102 m; degrees as float32 are held
        # to 2**-18 deg at 49 N, about 0.4 m
        result, text = command(conn, M.MAV_CMD_DO_REPOSITION, -1, 1, 0, math.nan, 49.00009,
                               8.0, 102.0)
        assert result == M.MAV_RESULT_ACCEPTED, text
        with server.lock:
            name, args = airframe.calls[-1]
        assert name == "fly_to" and args[:3] == pytest.approx((10.0, 0.0, 2.0), abs=0.45), args
        result, text = command(conn, M.MAV_CMD_DO_REPOSITION, -1, 1, 0, math.nan, 95.0, 8.0,
                               102.0)
        assert (result, text) == (M.MAV_RESULT_DENIED, "DO_REPOSITION: latitude (p5) 95 deg is "
                                  "out of range -90..90")
        assert server.errors == 0
