"""Commands in awkward moments, flown on a real lockstep simulator with the clock in the test's
hands (``ground_clock``, as tests/pilot/test_takeover.py): sim time moves only when granted,
and the pilot's wall clock (its link timeouts') is injected, so "the ground station took 5 s
to grant more time" is a jump of that clock, not a sleep."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path

import pytest

from skeye.errors import CommandRejected, VehicleLost
from skeye.pilot.boards import MIN_TAKE_OFF_M, BoardSettings
from skeye.pilot.envelope import FlightEnvelope
from skeye.wire.packets import HealthStatus, NavState, PadAction
from tests.pilot.test_takeover import _fly, _hold_at, pad_landing_under_way
from tests.sim.conftest import running_sim
from tests.sim.test_cameras import sim_with_images, small_camera_robot


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


def test_a_pad_search_climbs_no_higher_than_the_flight_envelope_allows(
    stack: ExitStack, tmp_path: Path,
) -> None:
    """PAD_MODE HOLD 10 m from the pad, which the camera cannot see: the vehicle searches,
    climbing to widen its view, but not above a 3 m ceiling. The pad modes fly while HOLDING,
    where the envelope guard does not act, and their velocities were not limited: the search
    climbed to its own 8 m ceiling, 5 m above the envelope's."""
    control, images, _cameras = stack.enter_context(sim_with_images(
        robot_dirs=(small_camera_robot(tmp_path),), estimator="truth"))
    ceiling_m = 3.0
    flight = _fly(stack, control.port, images.port, robot_class="smallcam",
                  settings=BoardSettings(envelope=FlightEnvelope(ceiling_m=ceiling_m)))
    _hold_at(flight, 2.0)
    flight.vehicle.move_by(right_m=10.0, speed_m_s=3.0)
    flight.run_until(lambda ns: ns.state is NavState.HOLDING, 30.0, step_s=0.5)
    flight.vehicle.pad_mode(1, deadband_m=0.05, max_speed_m_s=0.3)
    highest = 0.0
    for _ in range(16):  # 8 s of sim time: unlimited, the search reached 4.3 m in them
        ns = flight.run_for(0.5)
        assert ns.state is NavState.HOLDING and ns.pad_mode is PadAction.HOLD, ns
        highest = max(highest, -ns.z / 1000.0)
    assert ceiling_m - 0.5 < highest < ceiling_m + 0.3, highest  # searched up to the ceiling


def test_hold_during_a_pad_landing_stops_it_where_it_is(
    stack: ExitStack, tmp_path: Path,
) -> None:
    """HOLD ("stop and hover here", the page's Hold button) in the middle of a pad landing:
    the pad mode ends and the vehicle hovers at its height. The landing went on to the pad:
    only PAD_MODE 0 or the sticks stopped it."""
    flight = pad_landing_under_way(stack, tmp_path)
    flight.vehicle.hold()
    held_m = flight.height()
    ns = flight.run_for(2.0)  # the landing, still on, would have come down 0.4 m or more
    assert ns.state is NavState.HOLDING and ns.pad_mode is PadAction.OFF, ns
    assert abs(flight.height() - held_m) < 0.1, (held_m, flight.height())


def test_a_target_below_the_ground_is_refused_and_landing_still_lands(stack: ExitStack) -> None:
    """The flight envelope has a floor: home's ground. A MOVE_BY 2 m down from 0.5 m, or a
    timed VELOCITY that would end below the ground, is refused with RESULT code 3 naming the
    floor, and the vehicle holds where it was; a move down that stays above the ground is
    flown, and LAND still lands. The MOVE_BY was flown, into the ground at the descent rate
    (1.2 m/s at the touchdown, three times the landing's 0.4 m/s)."""
    server = stack.enter_context(running_sim(mode="lockstep", seed=23))
    flight = _fly(stack, server.port, settings=BoardSettings(link_timeout_s=60.0))
    _hold_at(flight, 0.5)
    held_m = flight.height()
    for command in (lambda: flight.vehicle.move_by(up_m=-2.0),
                    lambda: flight.vehicle.set_velocity(up_m_s=-1.0, duration_s=2.0)):
        with pytest.raises(CommandRejected) as info:
            command()
        assert info.value.code == 3 and "below home" in info.value.reason, info.value
        assert "floor" in info.value.reason and "LAND" in info.value.reason, info.value
    ns = flight.run_for(0.5)
    assert ns.state is NavState.HOLDING, ns
    # The onboard estimate's hover jitters by centimetres (docs/control.md: 4.8 cm median):
    # it did not come down the 0.4 m to the ground.
    assert abs(flight.height() - held_m) < 0.1, (held_m, flight.height())
    flight.vehicle.move_by(up_m=-0.3)  # to 0.2 m above home: inside, flown
    flight.run_until(lambda ns: ns.state is NavState.HOLDING, 10.0)
    flight.vehicle.land()
    flight.run_until(lambda ns: ns.state is NavState.LANDED, 10.0)


def test_a_take_off_below_the_minimum_is_refused_naming_it(stack: ExitStack) -> None:
    """TAKE_OFF 1 mm is refused with RESULT code 3 naming the minimum take-off height, and the
    vehicle stays landed with its motors off; a take-off to the minimum flies and hovers clear
    of the ground. The 1 mm one was accepted: the motion was done before the vehicle left its
    gear (the target within the 5 cm arrival tolerance), the pilot read the still-landed
    snapshot as a touchdown and said LANDED with its motors off, while the robot, armed, hopped
    on its gear up to 3 cm for seconds and then sat there armed."""
    server = stack.enter_context(running_sim(mode="lockstep", seed=23))
    flight = _fly(stack, server.port, settings=BoardSettings(link_timeout_s=60.0))
    with pytest.raises(CommandRejected) as info:
        flight.vehicle.take_off(0.001)
    assert info.value.code == 3, info.value
    assert f"minimum of {MIN_TAKE_OFF_M:g} m" in info.value.reason, info.value
    ns = flight.run_for(1.0)
    status = flight.robot.status.latest  # type: ignore[attr-defined]
    assert ns.state is NavState.LANDED and not status.armed and status.landed, (ns, status)
    flight.vehicle.take_off(MIN_TAKE_OFF_M)
    flight.run_until(lambda ns: ns.state is NavState.HOLDING, 10.0)
    ns = flight.run_for(1.0)
    status = flight.robot.status.latest  # type: ignore[attr-defined]
    assert ns.state is NavState.HOLDING and status.armed and not status.landed, (ns, status)


def test_velocities_over_the_robot_files_limits_are_refused_in_the_users_terms(
    stack: ExitStack, capsys: pytest.CaptureFixture[str],
) -> None:
    """VELOCITY beyond the robot file's limits (the hummingbird's 3 m/s forward or right,
    1.5 m/s up or down, 1.745 rad/s of yaw) is refused by the boards, RESULT code 3, naming the
    value as the packet means it and the limit, and the vehicle holds. The simulator's robot
    refused it in its own words, which the user read: ``skeye link ... velocity 0 0 0
    --yaw-rate-deg-s 200`` said "rejected: set_velocity: yaw_rate_rad_s=3.491 exceeds the limit
    1.745" (a Python parameter, in rad/s for a value typed in deg/s); now the yaw rate is said in
    deg/s and rad/s, as the packet carries it (to 1 mrad/s: 200 deg/s is 3.491 rad/s, 200.02
    deg/s). A yaw rate at the limit (99.98 deg/s is 1.745 rad/s on the wire) is flown."""
    server = stack.enter_context(running_sim(mode="lockstep", seed=23))
    flight = _fly(stack, server.port, settings=BoardSettings(link_timeout_s=60.0))
    _hold_at(flight, MIN_TAKE_OFF_M)
    for asked, said in (
        ({"forward_m_s": 5.0}, "forward 5 m/s is over this vehicle's limit of 3 m/s"),
        ({"right_m_s": -3.5}, "right -3.5 m/s is over this vehicle's limit of 3 m/s"),
        ({"up_m_s": -2.0}, "up -2 m/s is over this vehicle's climb and descent limit of 1.5 m/s"),
        ({"yaw_rate_rad_s": -2.0}, "yaw rate -114.59 deg/s (-2 rad/s) is over this vehicle's "
                                   "limit of 99.981 deg/s (1.745 rad/s)"),
    ):
        with pytest.raises(CommandRejected) as info:
            flight.vehicle.set_velocity(**asked)
        assert info.value.code == 3 and info.value.reason == f"velocity: {said}", info.value
    assert flight.run_for(0.2).state is NavState.HOLDING
    flight.vehicle.close()  # the one ground station goes: `skeye link` is the next
    from skeye.cli import main

    link = ["link", flight.pilot.address, "velocity", "0", "0", "0", "--yaw-rate-deg-s"]
    assert main([*link, "200"]) == 3
    assert capsys.readouterr().err == (
        "skeye link: rejected: velocity: yaw rate 200.02 deg/s (3.491 rad/s) is over this "
        "vehicle's limit of 99.981 deg/s (1.745 rad/s) (code 3)\n")
    assert main([*link, "99.98", "--duration", "0.5"]) == 0, capsys.readouterr().err
    assert flight.pilot.boards.state is NavState.FLYING


def test_a_grant_the_vehicle_cannot_reach_ends_when_the_pilot_says_it_is_lost(
    stack: ExitStack,
) -> None:
    """The simulator dies under a ground-clock pilot: sim time stands still for good, and
    ``run_until`` waited out its whole timeout for a NAV_STATUS that could not come (validate's
    E2 trials: 800 s and more, so a run with a faulted simulator looked hung). The pilot says
    HEALTH LOST; ``run_until`` now raises VehicleLost with its reason, and so does every later
    grant."""
    server = stack.enter_context(running_sim(mode="lockstep", seed=5))
    flight = _fly(stack, server.port)
    flight.run_for(0.2)
    server.close()  # the simulator is gone; the pilot finds out at its next step
    for _ in range(2):
        with pytest.raises(VehicleLost, match="vehicle is lost"):
            flight.vehicle.run_until(flight.now() + 5.0, timeout_s=300.0)
    health = flight.vehicle.health
    assert health is not None and health.status is HealthStatus.LOST, health
