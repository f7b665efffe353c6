"""The pilot server over real loopback TCP, on a scripted airframe: one client, link loss."""

from __future__ import annotations

import socket
import time

import pytest

from skeye.errors import CommandRejected
from skeye.link.transport import LinkClosed
from skeye.link.vehicle import Vehicle
from skeye.pilot.boards import BoardSettings
from skeye.pilot.server import PilotServer
from skeye.wire.packets import (
    PD,
    LlStatus,
    NavState,
    PollMask,
    Result,
    ResultCode,
    SkeyeMask,
    VehicleStreamParser,
)
from tests.pilot.fake_airframe import FakeAirframe


def test_second_client_is_turned_away_and_first_is_untouched():
    air = FakeAirframe()
    with PilotServer(air, port=0) as pilot, Vehicle.open(pilot.address) as first:
        first.poll(int(PollMask.LL_STATUS))
        second = socket.create_connection(("127.0.0.1", pilot.port), timeout=2.0)
        data = b""
        while True:  # read until the pilot closes it
            chunk = second.recv(4096)
            if not chunk:
                break
            data += chunk
        second.close()
        (answer,) = VehicleStreamParser().feed(data)
        assert isinstance(answer, Result)
        assert answer.code is ResultCode.BUSY and "one ground station" in answer.reason
        assert pilot.turned_away == 1
        assert PD.LL_STATUS in first.poll(int(PollMask.LL_STATUS))
        with Vehicle.open(pilot.address) as third:  # a Vehicle raises the refusal
            with pytest.raises((CommandRejected, LinkClosed)) as info:
                third.poll(1, timeout_s=2.0)
            if isinstance(info.value, CommandRejected):
                assert info.value.code == 5
    # The first client left: a new one is served.
    with PilotServer(air, port=0) as pilot:
        with Vehicle.open(pilot.address) as a:
            a.poll(1)
        deadline = time.monotonic() + 2
        while pilot.client is not None and time.monotonic() < deadline:
            time.sleep(0.01)
        with Vehicle.open(pilot.address) as b:
            assert PD.LL_STATUS in b.poll(1)


def test_a_station_that_reconnects_at_once_is_served_not_turned_away():
    """Closing and reconnecting at once races the pilot's reader noticing the hang-up; the new
    connection waits for that (HANDOVER_GRACE_S) instead of being refused as busy."""
    air = FakeAirframe()
    with PilotServer(air, port=0) as pilot:
        for _ in range(20):
            with Vehicle.open(pilot.address, timeout_s=30.0) as v:  # an event wait
                assert PD.LL_STATUS in v.poll(int(PollMask.LL_STATUS))
        assert pilot.turned_away == 0


def test_connections_that_come_and_go_leave_no_thread_behind():
    """Every connection gets a reader thread; one that has ended is forgotten at the next
    connection. The server kept every reader it ever started (its session, link and outbox
    with it): 1000 connections held about 5 MB for good."""
    air = FakeAirframe()
    with PilotServer(air, port=0) as pilot:
        for _ in range(60):
            with Vehicle.open(pilot.address, timeout_s=30.0) as v:  # an event wait
                assert PD.LL_STATUS in v.poll(int(PollMask.LL_STATUS))
        for _ in range(60):
            socket.create_connection(("127.0.0.1", pilot.port), timeout=5.0).close()
        with Vehicle.open(pilot.address, timeout_s=30.0) as v:  # the last one is served
            assert PD.LL_STATUS in v.poll(int(PollMask.LL_STATUS))
            # the loop, the accept thread, this reader, and readers still ending
            assert pilot.threads < 20, pilot.threads


def test_link_loss_over_tcp_holds_then_lands_and_the_pilot_serves_again():
    air = FakeAirframe()
    settings = BoardSettings(link_timeout_s=1.0, land_timeout_s=1.0)  # >> a busy host's stalls
    with PilotServer(air, port=0, settings=settings) as pilot:
        with Vehicle.open(pilot.address, keepalive_s=None) as v:  # goes quiet after take-off
            v.take_off(1.0)
            air.finish(landed=False, armed=True)
            v.stream(0, int(SkeyeMask.NAV_STATUS), 0.02)  # streaming is not a packet from us
            v.wait_state(NavState.HOLDING, timeout_s=30)
            t0 = time.monotonic()
            v.wait_state(NavState.FAILSAFE, timeout_s=30)
            assert time.monotonic() - t0 >= 0.2
            assert air.names()[-1] == "hover"
            v.wait_state(NavState.LANDING, timeout_s=30)
            assert air.names()[-1] == "land"
        air.finish(landed=True, armed=False)
        with Vehicle.open(pilot.address) as v:
            v.stream(0, int(SkeyeMask.NAV_STATUS), 0.02)
            v.wait_state(NavState.LANDED, timeout_s=30)  # the boards saw the touchdown
            ll = v.poll(1)[PD.LL_STATUS]
            assert isinstance(ll, LlStatus) and ll.flying == 0
            deadline = time.monotonic() + 30.0
            while pilot.boards.state is not NavState.LANDED and time.monotonic() < deadline:
                time.sleep(0.01)  # the loop notices the touchdown on its next tick
            assert pilot.boards.state is NavState.LANDED


def test_a_station_heard_once_in_failsafe_then_lost_again_still_gets_the_landing():
    """The ground station goes quiet: FAILSAFE; it sends one poll (the countdown stops) and goes
    quiet again: the vehicle lands after the land timeout. It hovered in FAILSAFE for good."""
    air = FakeAirframe()
    settings = BoardSettings(link_timeout_s=1.0, land_timeout_s=2.0)  # >> a busy host's stalls
    with PilotServer(air, port=0, settings=settings) as pilot:
        with Vehicle.open(pilot.address, keepalive_s=None) as v:  # goes quiet after take-off
            v.take_off(1.0)
            air.finish(landed=False, armed=True)
            v.stream(0, int(SkeyeMask.NAV_STATUS), 0.02)
            v.wait_state(NavState.HOLDING, timeout_s=30)
            v.wait_state(NavState.FAILSAFE, timeout_s=30)
            assert PD.LL_STATUS in v.poll(int(PollMask.LL_STATUS))  # heard once, then quiet
            assert pilot.boards.state is NavState.FAILSAFE
            v.wait_state(NavState.LANDING, timeout_s=30)
            assert air.names()[-1] == "land"


def test_garbage_over_tcp_is_counted_and_serving_goes_on():
    air = FakeAirframe()
    with PilotServer(air, port=0) as pilot, Vehicle.open(pilot.address) as v:
        v.send_raw(b"\x00\xff>*>zz>>>*>s\x05\x00garbage" * 20)
        r = v.wait_result(0)
        assert r.code is ResultCode.BAD_VALUE
        assert PD.LL_STATUS in v.poll(1)
        assert sum(pilot.boards.errors.values()) >= 20


def test_a_quiet_ground_station_keeps_the_link_alive_with_its_heartbeat():
    air = FakeAirframe()
    settings = BoardSettings(link_timeout_s=1.0, land_timeout_s=1.0)  # 10 heartbeats
    with PilotServer(air, port=0, settings=settings) as pilot:
        with Vehicle.open(pilot.address, keepalive_s=0.1) as v:
            v.take_off(1.0)
            air.finish(landed=False, armed=True)
            v.stream(0, int(SkeyeMask.NAV_STATUS), 0.02)
            v.wait_state(NavState.HOLDING, timeout_s=30)
            time.sleep(3.0)  # well past the link timeout, sending no command
            assert pilot.boards.state is NavState.HOLDING


def test_pad_mode_max_speed_is_checked_against_the_vehicles_limit():
    """Issue 31: PAD_MODE's max speed was stored whatever it was; now over the vehicle's limit
    (its robot file's max_speed_m_s, here 3 m/s) it is refused with code 3 naming the limit, as
    MOVE_BY's speed is."""
    air = FakeAirframe()
    with PilotServer(air, port=0, settings=BoardSettings(max_speed_m_s=3.0)) as pilot, \
            Vehicle.open(pilot.address) as v:
        with pytest.raises(CommandRejected) as info:
            v.pad_mode("hold", 0.05, 5.0)
        assert info.value.code == 3 and "limit of 3 m/s" in info.value.reason
        assert pilot.boards.pad.settings.max_speed_m_s == 0.0  # nothing stored
        v.pad_mode("hold", 0.05, 0.5)
        assert pilot.boards.pad.settings.max_speed_m_s == pytest.approx(0.5)
