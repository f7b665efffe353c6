"""Commands in awkward moments, flown on a real lockstep simulator with the clock in the test's
hands (``ground_clock``, as tests/pilot/test_takeover.py): sim time moves only when granted,
and the pilot's wall clock (its link timeouts') is injected, so "the ground station took 5 s
to grant more time" is a jump of that clock, not a sleep."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import ExitStack

import pytest

from skeye.pilot.boards import BoardSettings
from skeye.wire.packets import NavState
from tests.pilot.test_takeover import _fly, _hold_at
from tests.sim.conftest import running_sim


class JumpClock:
    """time.monotonic, plus whatever the test adds."""

    def __init__(self) -> None:
        self.offset_s = 0.0

    def __call__(self) -> float:
        return time.monotonic() + self.offset_s


@pytest.fixture
def stack() -> Iterator[ExitStack]:
    with ExitStack() as s:
        yield s


def test_a_timed_velocity_lasts_its_duration_of_sim_time_while_the_ground_holds_the_clock(
    stack: ExitStack,
) -> None:
    """VELOCITY 1 m/s forward for 1 s; after 0.5 s of sim time the ground station holds the
    clock for 5 s of wall time. The vehicle must still be FLYING when the clock moves on, and
    fly the rest of its second. The duration was counted on the wall clock: HOLDING and a
    hover at the first tick after the wall-clock second, with 0.5 s of the flight flown
    (0.18 m instead of about 0.8 m), and a seeded ground-clock run did not repeat."""
    server = stack.enter_context(running_sim(mode="lockstep", seed=23))
    clock = JumpClock()
    flight = _fly(stack, server.port, settings=BoardSettings(link_timeout_s=60.0), clock=clock)
    _hold_at(flight, 1.5)
    n0, e0, _ = flight.robot.ground_truth.latest.position_ned_m  # type: ignore[attr-defined]
    flight.vehicle.set_velocity(forward_m_s=1.0, duration_s=1.0)
    assert flight.run_for(0.5).state is NavState.FLYING
    clock.offset_s += 5.0  # the ground station thinks for 5 s; sim time stands still
    ns = flight.run_for(0.05)
    assert ns.state is NavState.FLYING, ns
    ns = flight.run_for(0.6)  # past the end of the second of sim time
    assert ns.state is NavState.HOLDING, ns
    n, e, _ = flight.robot.ground_truth.latest.position_ned_m  # type: ignore[attr-defined]
    assert math.hypot(n - n0, e - e0) > 0.5
