"""The sticks always win (issue 30): CTRL_INPUT with its axis bits set takes over from every
automatic mode, and the state says MANUAL (docs/pilot.md, "Manual sticks take over").

A real pilot flies a real lockstep simulator with ``ground_clock``: sim time moves only when
the test grants it (CLOCK), so "within 0.5 s" is 0.5 s of sim time whatever the machine's
load. In each automatic mode (a take-off, a GOTO_GPS, a pad landing with the camera and the
detector running, a link-loss failsafe) the ground station sends one CTRL_INPUT, roll 614
(15.35 deg) in height mode (ctrl 0x1F, thrust stick centred: hold the height), and grants
0.5 s: the vehicle must lean right by then and NAV_STATUS must say MANUAL. Refused before
("busy while taking off", "not allowed while failsafe"; a pad landing or a GOTO flew on).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import pytest

from skeye.control.connection import connect
from skeye.link.vehicle import Vehicle
from skeye.pilot.boards import BoardSettings
from skeye.pilot.cli import pad_vision_factory
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.wire.packet_units import gps_data_to_si, s_to_ms
from skeye.wire.packets import (
    PD,
    Ack,
    Clock,
    CtrlInput,
    NavState,
    NavStatus,
    PadAction,
    PollMask,
    SkeyeMask,
)
from tests.sim.conftest import running_sim
from tests.sim.test_cameras import sim_with_images, small_camera_robot

ROLL_COUNTS = 614  # 614 x 0.025 deg = 15.35 deg (sdk.h: +-2047 = 51.2 deg)
TAKEOVER = CtrlInput(pitch=0, roll=ROLL_COUNTS, yaw=0, thrust=2048, ctrl=0x1F)
LEANING_RAD = math.radians(5.0)  # a third of the commanded roll: it has begun to lean
GRANT_S = 0.05  # sim time granted per step while watching the roll


@dataclass
class Flight:
    vehicle: Vehicle
    robot: object
    pilot: PilotServer

    def now(self) -> float:
        """Sim time where the pilot holds the clock (the latest NAV_STATUS carries it)."""
        ns = self.vehicle.nav_status()
        assert ns is not None
        return ns.time / 1000.0

    def run_for(self, seconds: float) -> NavStatus:
        return self.vehicle.run_until(self.now() + seconds, timeout_s=60.0)

    def run_until(self, done: Callable[[NavStatus], bool], limit_s: float,
                  step_s: float = 0.1) -> NavStatus:
        start = self.now()
        while True:
            ns = self.run_for(step_s)
            if done(ns):
                return ns
            assert self.now() - start < limit_s, f"not reached in {limit_s} s of sim time: {ns}"

    def height(self) -> float:
        return -self.robot.ground_truth.latest.position_ned_m[2]  # type: ignore[attr-defined]


@pytest.fixture
def stack() -> Iterator[ExitStack]:
    with ExitStack() as s:
        yield s


def _fly(stack: ExitStack, control_port: int, images_port: int | None = None,
         robot_class: str = "hummingbird", settings: BoardSettings | None = None,
         clock: Callable[[], float] = time.monotonic) -> Flight:
    """A pilot on a lockstep simulator with the clock in the test's hands (``ground_clock``);
    ``clock`` is the pilot's wall clock (the link timeouts')."""
    images = None if images_port is None else f"127.0.0.1:{images_port}"
    sim = stack.enter_context(connect(f"127.0.0.1:{control_port}", images=images,
                                      timeout_s=30.0))
    robot = sim.spawn(robot_class, start="Pad1")
    vision = pad_vision_factory(sim, robot) if images is not None else None
    pilot = stack.enter_context(PilotServer(
        SimAirframe(sim, robot), port=0, lockstep=True, ground_clock=True, tick_s=0.05,
        settings=settings, vision=vision, clock=clock))
    vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=30.0))
    mask = SkeyeMask.NAV_STATUS | (SkeyeMask.PAD if images is not None else 0)
    vehicle.stream(0, int(mask), 0.02)
    vehicle.wait_for(PD.NAV_STATUS, timeout_s=30.0)
    return Flight(vehicle, robot, pilot)


def _hold_at(flight: Flight, height_m: float) -> None:
    flight.vehicle.take_off(height_m)
    flight.run_until(lambda ns: ns.state is NavState.HOLDING, 30.0, step_s=0.5)


def _take_over(flight: Flight, before: NavState) -> float:
    """Send the sticks once; grant sim time in steps until the vehicle leans: returns how
    long (sim time) that took, after checking the state."""
    assert flight.vehicle.nav_status().state is before  # type: ignore[union-attr]
    start = flight.now()
    assert isinstance(flight.vehicle.command(TAKEOVER), Ack)
    took = None
    ns = None
    while flight.now() - start < 0.5 - 1e-6:
        ns = flight.vehicle.run_until(min(start + 0.5, flight.now() + GRANT_S), timeout_s=60.0)
        roll = flight.robot.ground_truth.latest.rpy_rad[0]  # type: ignore[attr-defined]
        if took is None and roll > LEANING_RAD:
            took = flight.now() - start
    assert ns is not None and ns.state is NavState.MANUAL, ns
    assert took is not None, f"not leaning right 0.5 s after the sticks (from {before.name})"
    assert flight.pilot.boards.taken_over_from is before
    print(f"sticks over {before.name}: leaning {math.degrees(LEANING_RAD):.0f} deg after "
          f"{took:.2f} s of sim time")
    return took


def test_sticks_take_over_a_take_off(stack: ExitStack) -> None:
    server = stack.enter_context(running_sim(mode="lockstep", seed=21))
    flight = _fly(stack, server.port)
    flight.vehicle.take_off(3.0)
    flight.run_until(lambda ns: flight.height() > 0.6, 10.0)  # climbing
    _take_over(flight, NavState.TAKING_OFF)
    climbing = flight.height()
    flight.run_for(1.0)  # the take-off is over: the sticks hold the height
    assert abs(flight.height() - climbing) < 0.3


def test_sticks_take_over_a_goto(stack: ExitStack) -> None:
    server = stack.enter_context(running_sim(mode="lockstep", seed=22))
    flight = _fly(stack, server.port)
    _hold_at(flight, 1.5)
    gps = gps_data_to_si(flight.vehicle.poll(int(PollMask.GPS_DATA))[PD.GPS_DATA])
    flight.vehicle.goto_gps(gps.latitude_deg + 10.0 / 111_320.0, gps.longitude_deg, 1.5, 2.0)
    flight.run_until(lambda ns: ns.state is NavState.FLYING and math.hypot(ns.vx, ns.vy) > 500,
                     10.0)
    _take_over(flight, NavState.FLYING)
    ns = flight.run_for(3.0)  # the GOTO is over: nothing keeps it flying north at 2 m/s
    assert ns.state is NavState.MANUAL
    assert ns.vx < 1500 and ns.vy > 500  # coasting north, slowing; leaning right: going east


def pad_landing_under_way(stack: ExitStack, tmp_path: Path) -> Flight:
    """The small-camera robot in a pad landing from 1.2 m, descending through 1.05 m."""
    control, images, _cameras = stack.enter_context(sim_with_images(
        robot_dirs=(small_camera_robot(tmp_path),), estimator="truth"))
    flight = _fly(stack, control.port, images.port, robot_class="smallcam")
    _hold_at(flight, 1.2)
    flight.vehicle.pad_mode(2, deadband_m=0.05, max_speed_m_s=0.3)  # land on the pad
    flight.run_until(lambda ns: flight.height() < 1.05, 20.0)  # descending onto it
    ns = flight.vehicle.nav_status()
    assert ns is not None and ns.state is NavState.HOLDING and ns.pad_mode is PadAction.LAND
    return flight


def test_sticks_take_over_a_pad_landing(stack: ExitStack, tmp_path: Path) -> None:
    flight = pad_landing_under_way(stack, tmp_path)
    _take_over(flight, NavState.HOLDING)
    ns = flight.run_for(1.0)
    assert ns.pad_mode is PadAction.OFF  # the sticks ended the pad landing
    assert ns.state is NavState.MANUAL and flight.height() > 0.7


def test_a_stalled_process_is_not_a_silent_ground_station(stack: ExitStack) -> None:
    """The pilot, its simulator and its ground station in one process (the tests, a gym
    environment), stalled 3 s of wall time in a take-off (a loaded machine): the ground's
    packets stopped for 3 s of wall time, but for no sim time. The boards judged the link on
    the wall clock alone: FAILSAFE (no warning logged), and the take-off never became HOLDING
    (the LL board test's ``sim://`` flight, never HOLDING within 60 s of sim time, at load
    12-20). The stall is the pilot's clock jumping 3 s while the station sends nothing."""
    server = stack.enter_context(running_sim(mode="lockstep", seed=23))
    offset_s = [0.0]
    reads = [0]

    def clock() -> float:
        reads[0] += 1
        return time.monotonic() + offset_s[0]

    flight = _fly(stack, server.port, settings=BoardSettings(link_timeout_s=2.0), clock=clock)
    flight.vehicle.take_off(0.6)
    flight.run_for(0.2)
    keepalive_s, flight.vehicle.keepalive_s = flight.vehicle.keepalive_s, None
    offset_s[0] = 3.0
    seen = reads[0]
    deadline = time.monotonic() + 60.0  # a stuck guard: the loop ticks on the new time
    while reads[0] < seen + 50:
        assert time.monotonic() < deadline, "the pilot's loop stopped reading its clock"
        time.sleep(0.01)
    # The stall happened as meant: the boards have heard nothing for over the link timeout
    # of their (wall) clock (a keep-alive in flight when it was turned off came before it).
    assert clock() - flight.pilot.boards._last_packet_s >= 2.0
    flight.vehicle.keepalive_s = keepalive_s
    ns = flight.run_until(lambda ns: ns.state is not NavState.TAKING_OFF, 30.0, step_s=0.5)
    assert ns.state is NavState.HOLDING, ns


def test_sticks_take_over_a_failsafe(stack: ExitStack) -> None:
    server = stack.enter_context(running_sim(mode="lockstep", seed=23))
    flight = _fly(stack, server.port, settings=BoardSettings(link_timeout_s=2.0))
    _hold_at(flight, 1.5)
    # The station grants 3 s ahead and falls silent: silent on the wall clock and on the
    # vehicle's (sim time runs 2 s without a packet), the link is lost. (Silent with no time
    # granted, the simulated world stands still: no failsafe, as for a stalled process.)
    keepalive_s, flight.vehicle.keepalive_s = flight.vehicle.keepalive_s, None
    flight.vehicle.command(Clock(s_to_ms(flight.now() + 3.0)))
    flight.vehicle.wait_state(NavState.FAILSAFE, timeout_s=30.0)
    flight.vehicle.keepalive_s = keepalive_s  # the ground station is back
    _take_over(flight, NavState.FAILSAFE)
    ns = flight.run_for(1.0)
    assert ns.state is NavState.MANUAL  # the failsafe (and its landing countdown) is over
    assert abs(flight.height() - 1.6) < 0.4
