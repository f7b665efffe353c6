"""A crash is a crash, for the pilot too (issue 31, item 1), against real servers on loopback: a
lockstep simulator with its image server, the pilot with its pad vision, a ground link.

Before: the probe's wind line tumbled the vehicle, the vision thread died on the roll it read
(``LocalProtocolError: roll_rad must be finite and within (-pi/2, pi/2)``), the pilot called the
vehicle lost and stayed so. Now the vehicle is CRASHED with the simulator's cause, the vision
looks on ("pad not seen"), take-off is refused naming the crash, and RESET brings it back."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import pytest

from skeye.control.connection import connect
from skeye.errors import CommandRejected
from skeye.link.vehicle import Vehicle
from skeye.pilot.boards import BoardSettings
from skeye.pilot.cli import pad_vision_factory
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.pilot.vision import PadVision, looks_at_ground
from skeye.sim.cameras import CameraSystem
from skeye.sim.engine import Simulation
from skeye.sim.image_server import FrameBuffer, ImageServer
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.world import load_world
from skeye.wire.packets import PD, HealthStatus, NavState, SkeyeMask
from tests.ground.conftest import SMALL_CAMERA_ROBOT, _robot_dir, wait_until


@contextmanager
def _lockstep_sim_with_images(robots: Path) -> Iterator[tuple[ControlServer, ImageServer]]:
    sim = Simulation(load_world("pad"), seed=5, robot_dirs=(robots,))
    buffer = FrameBuffer()
    with (
        SimulationRunner(sim, mode="lockstep") as runner,
        CameraSystem(sim, buffer, synchronous=True),
        ControlServer(runner, port=0) as control,
        ImageServer(buffer, port=0) as images,
    ):
        yield control, images


def _fly(stack: ExitStack, control: ControlServer, images: ImageServer,
         before: Callable[[], None] = lambda: None, **spawn: object
         ) -> tuple[PilotServer, PadVision, Vehicle]:
    """A pilot on a robot spawned as ``spawn`` says; ``before`` runs before the pilot steps the
    lockstep simulator (so what it sets happens at a known step)."""
    sim = stack.enter_context(connect(f"127.0.0.1:{control.port}",
                                      images=f"127.0.0.1:{images.port}", timeout_s=60.0))
    robot = sim.spawn(SMALL_CAMERA_ROBOT, **spawn)  # type: ignore[arg-type]
    before()
    pilot = stack.enter_context(PilotServer(
        SimAirframe(sim, robot), port=0, lockstep=True, lockstep_rate=0.0, tick_s=0.02,
        settings=BoardSettings(link_timeout_s=600.0), vision=pad_vision_factory(sim, robot)))
    assert isinstance(pilot.vision, PadVision)
    vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=60.0))
    vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.05)
    return pilot, pilot.vision, vehicle


def test_the_probe_wind_line_is_a_crash_and_reset_brings_the_vehicle_back(tmp_path) -> None:
    """The vehicle on the pad, as under ``skeye up``; the probe's line is sent before the pilot
    steps the lockstep simulator, so the force it draws (direction and magnitude uniform: a
    draw under what the vehicle's gear holds would not move it) is the same every run."""
    with ExitStack() as stack:
        control, images = stack.enter_context(_lockstep_sim_with_images(_robot_dir(tmp_path)))
        wind = stack.enter_context(connect(f"127.0.0.1:{control.port}", timeout_s=60.0))
        pilot, vision, vehicle = _fly(
            stack, control, images, start="Pad1",
            before=lambda: wind.set_wind("random_force", "f_max_n=50,tick_s=3600"))

        vehicle.wait_state(NavState.CRASHED, timeout_s=120)
        health = wait_until(lambda: vehicle.health if vehicle.health and
                            vehicle.health.status is HealthStatus.CRASHED else None,
                            60, "HEALTH CRASHED")
        assert "crashed" in health.reason, health
        assert pilot.vehicle_lost is None and pilot.loop_error is None
        with pytest.raises(CommandRejected) as info:
            vehicle.take_off(1.0)
        assert info.value.code == 4 and "crashed" in info.value.reason
        assert "RESET" in info.value.reason
        # The wreck tumbles on in the wind: the vision keeps looking and keeps living.
        frames = vision.stats.frames + vision.stats.bad_attitude
        wait_until(lambda: vision.stats.frames + vision.stats.bad_attitude > frames + 5, 120,
                   "the vision looking on after the crash")
        assert vision._worker is not None and vision._worker.alive

        wind.set_wind("none")
        robot = pilot.airframe.robot  # type: ignore[attr-defined]
        vehicle.reset()
        vehicle.wait_state(NavState.LANDED, timeout_s=60)
        # Back on the pad (its start pose, Pad1 at the origin), not where the wreck lay: the
        # simulator's truth, once its first reading after the respawn has arrived.
        wait_until(lambda: math.hypot(*robot.position()[:2]) < 0.05, 60,
                   "the truth at the start pose after the reset")
        wait_until(lambda: vehicle.health and vehicle.health.status is HealthStatus.OK, 60,
                   "HEALTH OK after the reset")
        vehicle.take_off(1.0)
        vehicle.wait_state(NavState.HOLDING, timeout_s=120)
        # It flies again, on its own GPS-aided estimate: its hold is off the pad by as much as
        # that estimate is, within 3x the accuracy it states (the receiver's 2.5 m CEP
        # included, docs/physics.md). A fixed 1 m was exceeded with both cores busy (1.24 m
        # estimate, 1.33 m truth): the more sim time passes on the pad before the take-off,
        # the further the estimate has followed the receiver's error.
        nav = vehicle.wait_for(PD.NAV_STATUS, timeout_s=60)
        assert nav.sigma_h > 0, "the vehicle states no accuracy for its estimate"
        north_m, east_m, up_m = robot.position()
        assert up_m > 0.5 and math.hypot(north_m, east_m) < 3.0 * nav.sigma_h / 1000.0, \
            (north_m, east_m, up_m, nav.sigma_h)


def test_a_vehicle_upside_down_is_pad_not_seen_not_a_dead_vision(tmp_path) -> None:
    """The vision's attitude input at its extremes: spawned upside down in the air, the INS
    says roll ~ pi; the detector is never asked (it takes |roll| < pi/2 only)."""
    with ExitStack() as stack:
        control, images = stack.enter_context(_lockstep_sim_with_images(_robot_dir(tmp_path)))
        pilot, vision, vehicle = _fly(stack, control, images, location_ned_m=(0.0, 0.0, -3.0),
                                      rotation_rpy_rad=(3.1, 0.0, 0.0))
        wait_until(lambda: vision.stats.bad_attitude >= 3, 120, "frames at an upside-down roll")
        assert vision._worker is not None and vision._worker.alive
        assert vision.stats.errors == 0, vision.stats.last_error
        vehicle.wait_state(NavState.CRASHED, timeout_s=120)  # and it falls: a crash
        assert pilot.vehicle_lost is None and pilot.loop_error is None


@pytest.mark.parametrize(("roll", "pitch", "sees"), [
    (0.0, 0.0, True), (1.5, -1.5, True), (math.pi / 2, 0.0, False), (0.0, -math.pi / 2, False),
    (math.pi, 0.0, False), (-3.0, 0.0, False), (math.nan, 0.0, False), (0.0, math.inf, False),
    (-math.inf, 0.0, False), (1e308, 0.0, False),
])
def test_which_attitudes_the_camera_sees_the_ground_at(roll, pitch, sees) -> None:
    assert looks_at_ground(roll, pitch) is sees
