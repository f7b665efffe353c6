"""AscTec single-waypoint flight as a ground station sequences it (docs/protocols/packets.md,
CURRENT_WAY and WAYPOINT): a real pilot on a real lockstep simulator, the clock in the test's
hands (``ground_clock``), the waypoint uploaded (``>*>ws``) and flown (``>*>wg``) over the
packet protocol, CURRENT_WAY polled after every grant of sim time.

The semantics are the AscTec SDK's (``sdkio.h``, ``WP_NAVSTAT_*``): 0x01 once the vehicle has
entered the radius ``pos_acc`` of the waypoint, 0x02 once it is within it and ``time`` (the
time to stay) is over, 0x08 when the waypoint flight was aborted; the SDK's
``gps_waypoints.c`` example sends the next waypoint on 0x02 and gives up on 0x08.
"""

from __future__ import annotations

from contextlib import ExitStack

from skeye.wire.packet_units import WaypointSi, waypoint_from_si
from skeye.wire.packets import (
    PD,
    Ack,
    CurrentWay,
    NavigationStatus,
    NavState,
    PollMask,
    WaypointProps,
)
from tests.pilot.test_takeover import TAKEOVER, Flight, _fly, _hold_at
from tests.sim.conftest import running_sim

REACHED = int(NavigationStatus.REACHED)
WAITED = int(NavigationStatus.REACHED_AND_WAITED)
ABORTED = int(NavigationStatus.ABORTED)
STEP_S = 0.1  # sim time granted between two polls
TICK_S = 0.05  # the pilot's tick (``_fly``): the boards look at the vehicle this often


def _current_way(flight: Flight) -> CurrentWay:
    way = flight.vehicle.poll(int(PollMask.CURRENT_WAY))[PD.CURRENT_WAY]
    assert isinstance(way, CurrentWay)
    return way


def _go(flight: Flight, east_m: float, height_m: float, pos_acc_m: float, stay_s: float,
        speed_percent: int = 50) -> None:
    """Upload a waypoint ``east_m`` east of home at ``height_m`` and fly to it."""
    wp = waypoint_from_si(WaypointSi(
        properties=int(WaypointProps.HEIGHT_ENABLED), max_speed_percent=speed_percent,
        hold_time_s=stay_s, position_accuracy_m=pos_acc_m, x=east_m, y=0.0, yaw_rad=0.0,
        height_m=height_m))
    assert isinstance(flight.vehicle.upload_waypoint(wp), Ack)
    assert isinstance(flight.vehicle.waypoint_goto(), Ack)


def test_a_waypoint_is_reached_at_pos_acc_and_waited_for_its_time() -> None:
    # pos_acc 0.8 m, time 0.5 s: 0x01 comes as the vehicle enters 0.8 m of the waypoint (still
    # flying, metres short of the motion's own 5 cm arrival), 0x02 once it has stayed 0.5 s
    # of sim time within that radius, not before. Before: pos_acc and time were stored, not
    # flown: 0x01 came at the motion's arrival and 0x02 never.
    pos_acc_m, stay_s = 0.8, 0.5
    with ExitStack() as stack_:
        server = stack_.enter_context(running_sim(mode="lockstep", seed=31))
        flight = _fly(stack_, server.port)
        _hold_at(flight, 1.0)
        _go(flight, 2.0, 1.0, pos_acc_m, stay_s)
        reached_s = waited_s = None
        way = _current_way(flight)
        assert way.navigation_status & (REACHED | WAITED | ABORTED) == 0, way
        while waited_s is None:
            ns = flight.run_for(STEP_S)
            way = _current_way(flight)
            now = flight.now()
            if reached_s is None and way.navigation_status & REACHED:
                reached_s = now
                # entered the radius this step: within it, by at most a step's flight more
                assert way.distance_to_wp <= round(pos_acc_m * 10), way
                assert way.distance_to_wp >= round(pos_acc_m * 10) // 2, way
                assert ns.state is NavState.FLYING, ns  # the motion goes on to the point
            if way.navigation_status & WAITED:
                assert way.navigation_status & REACHED, way  # 0x02 implies 0x01
                waited_s = now
            assert now < 20.0 + (reached_s or 0.0), f"no 0x02 within 20 s of sim time: {way}"
        assert reached_s is not None
        # The dwell on the vehicle's clock, as the polls see it: each bit is set at a tick
        # (every TICK_S), the pilot stops at the first tick at or past a grant, so polls come
        # STEP_S to STEP_S + TICK_S apart and see a bit that late at most; 0x02 comes at the
        # first tick once the time to stay is over.
        assert stay_s - (STEP_S + TICK_S) <= waited_s - reached_s, (reached_s, waited_s)
        assert waited_s - reached_s <= stay_s + TICK_S + (STEP_S + TICK_S), (reached_s, waited_s)
        assert way.navigation_status & ABORTED == 0, way
        assert way.distance_to_wp <= round(pos_acc_m * 10), way


def test_sticks_abort_a_waypoint_flight_and_say_so() -> None:
    # The SDK's WP_NAVSTAT_PILOT_ABORT: "waypoint navigation aborted by safety pilot (any
    # stick was moved)". Sticks take over a waypoint flight under way: CURRENT_WAY reads 0x08
    # and neither 0x01 nor 0x02 (a station waiting for 0x02 learns it never comes), no
    # current waypoint (distance 0); the next >*>wg clears it. Before: 0x08 was never set.
    with ExitStack() as stack_:
        server = stack_.enter_context(running_sim(mode="lockstep", seed=32))
        flight = _fly(stack_, server.port)
        _hold_at(flight, 1.0)
        _go(flight, 3.0, 1.0, pos_acc_m=0.5, stay_s=1.0)
        flight.run_until(lambda ns: ns.state is NavState.FLYING and abs(ns.vy) > 300, 10.0)
        way = _current_way(flight)
        assert way.navigation_status & (REACHED | WAITED | ABORTED) == 0, way
        assert way.distance_to_wp > 10, way  # still more than a metre to go
        assert isinstance(flight.vehicle.command(TAKEOVER), Ack)
        ns = flight.run_for(STEP_S)
        assert ns.state is NavState.MANUAL, ns
        way = _current_way(flight)
        assert way.navigation_status & (REACHED | WAITED | ABORTED) == ABORTED, way
        assert way.distance_to_wp == 0, way
        _go(flight, 3.0, 1.0, pos_acc_m=0.5, stay_s=1.0)  # a new waypoint flight
        way = _current_way(flight)
        assert way.navigation_status & (REACHED | WAITED | ABORTED) == 0, way


def test_an_automatic_goto_waypoint_is_flown_on_upload() -> None:
    # WPPROP_AUTOMATICGOTO (0x10): "if set, vehicle will not wait for a goto command, but goto
    # this waypoint directly" (AscTec's LL/HL communication header; the older SDK's sdk.c
    # example uploads its waypoints so). Before: stored, and the vehicle hovered on.
    with ExitStack() as stack_:
        server = stack_.enter_context(running_sim(mode="lockstep", seed=33))
        flight = _fly(stack_, server.port)
        _hold_at(flight, 1.0)
        wp = waypoint_from_si(WaypointSi(
            properties=int(WaypointProps.HEIGHT_ENABLED | WaypointProps.AUTOMATIC_GOTO),
            max_speed_percent=50, hold_time_s=0.0, position_accuracy_m=0.5, x=2.0, y=0.0,
            yaw_rad=0.0, height_m=1.0))
        assert isinstance(flight.vehicle.upload_waypoint(wp), Ack)  # and no >*>wg
        ns = flight.run_for(0.5)
        assert ns.state is NavState.FLYING, ns
        way = _current_way(flight)
        assert 10 <= way.distance_to_wp <= 20, way  # on its way: 2 m at the upload
        assert way.navigation_status & (REACHED | WAITED | ABORTED) == 0, way
