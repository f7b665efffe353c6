"""The simulator dies under a flying pilot: the pilot says so, keeps its ground link, and the
failsafe applies; commands are refused (code 4) while polls are still answered."""

from __future__ import annotations

from contextlib import ExitStack

import pytest

from skeye.control.connection import connect
from skeye.errors import CommandRejected
from skeye.link.vehicle import Vehicle
from skeye.pilot.boards import BoardSettings
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.wire.packets import PD, HealthStatus, NavState, PollMask, SkeyeMask
from tests.ground.conftest import wait_until
from tests.sim.conftest import running_sim


def _lost_in_the_air(stack: ExitStack, land_timeout_s: float) -> tuple[PilotServer, Vehicle]:
    """A pilot hovering on a lockstep simulator with a ground station connected (streaming
    NAV_STATUS); then the simulator goes away (its engine too), and the pilot is in FAILSAFE."""
    server = stack.enter_context(running_sim(mode="lockstep", seed=4))
    sim = stack.enter_context(connect(f"127.0.0.1:{server.port}", timeout_s=5.0))
    robot = sim.spawn("hummingbird", start="Pad1")
    pilot = stack.enter_context(
        PilotServer(SimAirframe(sim, robot), port=0, lockstep=True, lockstep_rate=0.0,
                    tick_s=0.05, settings=BoardSettings(land_timeout_s=land_timeout_s))
    )
    vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=5.0))
    vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.02)
    vehicle.take_off(1.0)
    vehicle.wait_state(NavState.HOLDING, timeout_s=30)
    server.close()
    server.runner.close()
    vehicle.wait_state(NavState.FAILSAFE, timeout_s=10)
    return pilot, vehicle


def test_simulator_killed_under_the_pilot():
    with ExitStack() as stack:
        pilot, vehicle = _lost_in_the_air(stack, land_timeout_s=60.0)
        assert pilot.vehicle_lost is not None and "simulator" in pilot.vehicle_lost
        assert pilot.loop_error is None
        # The ground link is kept: polls are answered, commands refused with the reason.
        assert PD.LL_STATUS in vehicle.poll(int(PollMask.LL_STATUS))
        with pytest.raises(CommandRejected) as info:
            vehicle.move_by(forward_m=1.0)
        assert info.value.code == 4
        # the reason the pilot logged (which way it learnt of the loss first varies: "simulator
        # lost: the simulator at ... closed" from the airframe, or the connection's own words)
        assert f"the vehicle is lost: {pilot.vehicle_lost}" in str(info.value), info.value
        assert PD.LL_STATUS in vehicle.poll(int(PollMask.LL_STATUS))


def test_a_lost_vehicle_is_landed_after_the_land_timeout_with_the_ground_station_connected():
    """The heartbeat of a connected ground station stopped the land countdown of a vehicle
    lost below: FAILSAFE for good, the land timeout never came. Now LANDING after it, and the
    landing that cannot reach the dead simulator is a warning, not a fault of the loop."""
    with ExitStack() as stack:
        pilot, vehicle = _lost_in_the_air(stack, land_timeout_s=1.0)  # (its heartbeat polls)
        vehicle.wait_state(NavState.LANDING, timeout_s=30)
        assert pilot.loop_faults == 0 and pilot.loop_error is None


def test_the_pilot_reattaches_when_its_simulator_comes_back():
    """Recovery (issue 31): the simulator at the same address again, the pilot spawns its robot
    there and says so; the vehicle is LANDED and flies. Before, a pilot that lost its
    simulator stayed lost until restarted."""
    with ExitStack() as stack:
        first = stack.enter_context(running_sim(mode="lockstep", seed=4))
        address = f"127.0.0.1:{first.port}"

        def attach():
            sim = connect(address, timeout_s=5.0)
            try:
                return sim, sim.spawn("hummingbird", start="Pad1")
            except BaseException:
                sim.close()
                raise

        sim, robot = attach()
        airframe = SimAirframe(sim, robot, attach=attach)
        pilot = stack.enter_context(
            PilotServer(airframe, port=0, lockstep=True, lockstep_rate=0.0, tick_s=0.05,
                        settings=BoardSettings(land_timeout_s=60.0), reattach_s=0.2))
        stack.callback(lambda: airframe.connection.close())
        vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=5.0))
        vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.02)
        vehicle.take_off(1.0)
        vehicle.wait_state(NavState.HOLDING, timeout_s=30)

        first.close()  # the simulator goes away (its engine too)
        first.runner.close()
        vehicle.wait_state(NavState.FAILSAFE, timeout_s=10)
        wait_until(lambda: vehicle.health is not None
                   and vehicle.health.status is HealthStatus.LOST, 10, "HEALTH LOST")
        assert "simulator" in vehicle.health.reason

        # A new simulator at the same address: the pilot finds it by itself.
        again = stack.enter_context(running_sim(mode="lockstep", seed=5, port=first.port))
        assert again.port == first.port
        vehicle.wait_state(NavState.LANDED, timeout_s=30)
        wait_until(lambda: vehicle.health is not None
                   and vehicle.health.status is HealthStatus.OK, 10, "HEALTH OK")
        assert "respawned" in vehicle.health.reason
        assert pilot.reattached == 1 and pilot.vehicle_lost is None and pilot.loop_error is None
        vehicle.take_off(1.0)
        vehicle.wait_state(NavState.HOLDING, timeout_s=30)
