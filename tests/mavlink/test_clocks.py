"""The vehicle's clock as MAVLink clients read it: TIMESYNC and PING answered as PX4 does.

A ground station (MAVROS, MAVSDK) sends TIMESYNC with ``tc1 = 0`` and its own time in ``ts1``;
the vehicle answers with ``tc1`` its own time in nanoseconds, the clock of every
``time_boot_ms`` and ``time_usec`` it sends (PX4: ``hrt_absolute_time() * 1000``, its boot
time, which in SITL lockstep is sim time). The client takes the offset between its clock and
that one to convert the telemetry's stamps; an answer on another clock puts every converted stamp
off by the difference. The vehicle here runs in lockstep, so the checks compare stamps only
(sim time), never the wall clock."""

from __future__ import annotations

from dataclasses import replace

from pymavlink import mavutil

from tests.mavlink.conftest import (
    GCS,
    command,
    ground_station,
    mav_vehicle,
    scripted_endpoint,
    wait_for,
)

M = mavutil.mavlink


def test_timesync_answers_on_the_clock_of_the_telemetry_stamps():
    with mav_vehicle() as v:
        conn = v.client()
        for ts1 in (111_111, 222_222, 333_333):
            before = wait_for(conn, "ATTITUDE")
            conn.mav.timesync_send(0, ts1)
            answer = wait_for(conn, "TIMESYNC", lambda m, t=ts1: m.ts1 == t)
            after = wait_for(conn, "ATTITUDE")
            # The answer's instant lies between the two ATTITUDEs' (time_boot_ms is cut to whole
            # milliseconds, hence the + 1 ms); both are sim time, the vehicle's boot clock.
            assert before.time_boot_ms * 1_000_000 <= answer.tc1 \
                < (after.time_boot_ms + 1) * 1_000_000, \
                (before.time_boot_ms, answer.tc1, after.time_boot_ms)


def test_ping_is_answered_with_the_senders_time_as_mavsdk_measures_the_round_trip():
    """MAVSDK's ``Ping`` (and QGroundControl's link check) take the round trip as their clock now
    minus the answer's ``time_usec``: the answer carries the request's stamp back unchanged,
    with its ``seq``, addressed to the sender, as PX4 and MAVSDK answer a PING."""
    with mav_vehicle() as v:
        conn = v.client()
        wait_for(conn, "HEARTBEAT")
        for seq, stamp_us in ((1, 5_000_000), (2, 1_764_300_000_000_000)):  # boot, Unix time
            conn.mav.ping_send(stamp_us, seq, 0, 0)
            answer = wait_for(conn, "PING", lambda m, s=seq: m.seq == s)
            assert (answer.time_usec, answer.target_system, answer.target_component) \
                == (stamp_us, *GCS)


def test_one_instant_has_one_stamp_on_every_message_and_on_the_asctec_link():
    """Sim time comes as text (``{Time 1.001000}``); 1.001 in binary is a hair under it, and
    1.001 * 1000 is 1000.9999999999999. Each message's stamp is the nearest count of its unit,
    as the AscTec link's NAV_STATUS ``time`` is: cut short instead, on a 1 ms simulator one
    reading in 135 read a millisecond early (one in 67 a microsecond), and the links disagreed."""
    with scripted_endpoint("udp://127.0.0.1:0") as server:
        airframe = server.vehicle.boards.airframe
        with server.lock:
            airframe.snap = replace(airframe.snap, time_s=float("1.001000"))
        with ground_station(server) as conn:
            wanted = ["ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "SYSTEM_TIME",
                      "HIGHRES_IMU", "GPS_RAW_INT", "ALTITUDE"]
            assert command(conn, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_HIGHRES_IMU,
                           100_000) == (0, "")  # on request only: 10 Hz
            stamps: dict[str, object] = {}
            while len(stamps) < len(wanted):
                msg = wait_for(conn, [k for k in wanted if k not in stamps], timeout_s=10.0)
                stamps[msg.get_type()] = msg
            ms = {k: m.time_boot_ms for k, m in stamps.items() if hasattr(m, "time_boot_ms")}
            us = {k: m.time_usec for k, m in stamps.items() if hasattr(m, "time_usec")}
            with server.lock:
                nav_status = server.vehicle.boards.nav_status()
            assert nav_status is not None
            assert ms == dict.fromkeys(ms, 1001) and nav_status.time == 1001, (ms, nav_status)
            assert us == dict.fromkeys(us, 1_001_000), us
