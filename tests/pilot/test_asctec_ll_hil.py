"""The pilot on an AscTec LL board, with the simulator as the hardware in the loop (issue 29).

The same flights twice, on one seed: the pilot on ``sim://`` (its robot in the simulator, as
always), and the pilot on ``asctec-ll://serial/dev/pts/N?lockstep=1`` against the simulator's
emulated LL board on a pseudo-terminal (``skeye sim --ll-board R1=pty``): sticks and polled
structures over the very bytes a real board would exchange, the camera from the image server
alone (``--camera sim://...``). E2's pad hold (0.70 m above the pad under the paper's random
force, F_max 0.3 N, PAD_MODE 1 with 5 cm deadband and 0.3 m/s; here 8 s of it) and a pad
landing (PAD_MODE 2 from 1.2 m, 0.5 m off the pad): the HIL figures must be within 1.5x of
the ``sim://`` ones.

Seed 5: over seeds 1-8 (this hold, 320x240 camera, the code with the realism round's sensors
and the sticks' take-over rule, 2026-11-26) the ratios asctec-ll / sim were 0.57-1.40 for the
standard deviation (median 1.0) and 0.65-1.55 for the maximum (one of eight, seed 7, above
1.5: 8.35 / 5.38 cm); seed 5 is at the median (1.06 and 1.01). Before those changes seed 7 was
the median (1.14 and 1.12). The difference is the board's GPS hold (docs/pilot.md, "On an
AscTec LL board").

Lean for CI: lockstep, the time granted by a scripted ground client (``--ground-clock``), so
both runs are reproducible on any machine, and each pad mode starts at the same sim time on
both (the random force is a sequence in sim time: the two flights meet the same gusts); the
Hummingbird's camera at 320x240 instead of 800x600 (the figures with the full camera and E2's
20 s are ``benchmarks/bench_onboard.py --only hil``'s, in docs/pilot.md). Ground truth is
sampled in the simulator every 20 ms of sim time.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from skeye.hil.cli import parse_ll_board, start_ll_board
from skeye.link.vehicle import Vehicle
from skeye.pilot.airframe import AirframeOptions, open_airframe
from skeye.pilot.cli import camera_vision_factory, open_camera_for, pad_vision_factory
from skeye.pilot.server import PilotServer
from skeye.sim.cameras import CameraSystem
from skeye.sim.engine import Simulation
from skeye.sim.image_server import FrameBuffer, ImageServer
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.world import load_world
from skeye.wire.packets import NavState, SkeyeMask
from skeye.wire.wind import make_settings
from tests.sim.test_cameras import small_camera_robot

RATIO = 1.5
HOLD_S = 8.0
HOLD_FROM_S = 6.0  # sim time PAD_MODE HOLD starts at, on both airframes
LAND_FROM_S = 9.0  # ... and PAD_MODE LAND
SAMPLE_S = 0.02


@dataclass
class Flight:
    vehicle: Vehicle
    pilot: PilotServer
    truth: list[tuple[float, float, float, float]] = field(default_factory=list)
    granted_s: float = 0.0

    def run(self, seconds: float) -> None:
        """Grant ``seconds`` more of sim time and wait until the pilot is there."""
        self.granted_s += seconds
        self.vehicle.run_until(self.granted_s, timeout_s=300)
        assert self.pilot.loop_error is None and self.pilot.vehicle_lost is None, (
            self.pilot.loop_error, self.pilot.vehicle_lost)

    def until_time(self, time_s: float) -> None:
        """Run to a sim time (both flights start a manoeuvre at the same one: the random force
        is then the same sequence for both)."""
        assert self.granted_s <= time_s, f"already at {self.granted_s} s, past {time_s} s"
        self.run(time_s - self.granted_s)

    def until_state(self, state: NavState, limit_s: float) -> float:
        end = self.granted_s + limit_s
        while self.pilot.boards.state is not state:
            assert self.granted_s < end, f"not {state.name} in {limit_s} s"
            self.run(0.25)
        return self.granted_s


@contextmanager
def flight(kind: str, robot_dir: Path, seed: int = 5) -> Iterator[Flight]:
    """A lockstep simulator with E2's disturbance, and a pilot on ``kind`` (sim or hil)."""
    with ExitStack() as stack:
        sim = Simulation(load_world("pad"), seed=seed, robot_dirs=(robot_dir,),
                         wind=make_settings("random_force", {"f_max_n": 0.3}))
        runner = stack.enter_context(SimulationRunner(sim, mode="lockstep"))
        buffer = FrameBuffer()
        stack.enter_context(CameraSystem(sim, buffer, synchronous=True))
        control = stack.enter_context(ControlServer(runner, port=0))
        images = stack.enter_context(ImageServer(buffer, port=0))
        truth: list[tuple[float, float, float, float]] = []

        def sample(s: Simulation) -> None:
            if "R1" in s.robots and (not truth or s.time_s >= truth[-1][0] + SAMPLE_S - 1e-9):
                n, e, d = s.body_state("R1").pos_ned_m
                truth.append((s.time_s, float(n), float(e), float(d)))

        sim.step_hooks.append(sample)
        options = AirframeOptions(robot="smallcam", robot_dirs=(str(robot_dir),),
                                  images=f"127.0.0.1:{images.port}")
        if kind == "hil":
            board = start_ll_board(stack, parse_ll_board("R1=pty,robot=smallcam"),
                                   f"127.0.0.1:{control.port}")
            fov = board.airframe.connection.request(  # type: ignore[attr-defined]
                "GETCONF", ("Type", "Camera"), ("Name", "Down")).get_float("FOV")
            airframe = open_airframe(board.line.client_uri() + "?lockstep=1", options)
            stack.callback(airframe.close)
            camera = open_camera_for(f"sim://127.0.0.1:{images.port}/R1/Down?fov_rad={fov!r}",
                                     airframe, "R1", None, 30.0)
            stack.callback(camera.close)
            vision = camera_vision_factory(camera, camera.fov_h_rad, lockstep=True)
        else:
            airframe = open_airframe(f"sim://127.0.0.1:{control.port}", options)
            stack.callback(airframe.close)
            vision = pad_vision_factory(airframe.connection, airframe.robot)  # type: ignore[attr-defined]
        pilot = stack.enter_context(PilotServer(
            airframe, port=0, lockstep=True, lockstep_rate=0, ground_clock=True,
            tick_s=airframe.control_period_s, vision=vision))
        vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=60.0))
        vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.01)
        f = Flight(vehicle, pilot, truth, airframe.snapshot().time_s)
        yield f


def pad_hold(kind: str, robot_dir: Path) -> dict[str, float]:
    """E2's hold for HOLD_S: distance from the pad centre (std, max, mean), m."""
    with flight(kind, robot_dir) as f:
        f.vehicle.take_off(0.70 - 0.081)  # body centre 0.70 m above the pad
        f.until_state(NavState.HOLDING, 60.0)
        f.until_time(HOLD_FROM_S)
        f.vehicle.pad_mode(1, deadband_m=0.05, max_speed_m_s=0.3)
        start = f.granted_s
        f.run(HOLD_S)
        d = [math.hypot(n, e) for t, n, e, _ in f.truth if start <= t <= start + HOLD_S]
        assert f.pilot.vision.stats.detections > HOLD_S * 10  # type: ignore[union-attr]
    return {"std_m": statistics.pstdev(d), "max_m": max(d), "mean_m": statistics.fmean(d)}


def pad_landing(kind: str, robot_dir: Path) -> dict[str, float]:
    """PAD_MODE LAND from 1.2 m, 0.5 m east of the pad: time to landed (s), miss (m)."""
    with flight(kind, robot_dir) as f:
        f.vehicle.take_off(1.2)
        f.until_state(NavState.HOLDING, 60.0)
        f.vehicle.move_by(right_m=0.5, speed_m_s=0.5)  # facing north: east of the pad
        f.run(0.25)
        f.until_state(NavState.HOLDING, 60.0)
        f.until_time(LAND_FROM_S)
        start = f.granted_s
        f.vehicle.pad_mode(2, deadband_m=0.05, max_speed_m_s=0.3)
        landed = f.until_state(NavState.LANDED, 60.0)
        _, n, e, _ = f.truth[-1]
        t0 = next(x for x in f.truth if x[0] >= start)
    return {"start_m": math.hypot(t0[1], t0[2]), "landed_s": landed - start,
            "miss_m": math.hypot(n, e)}


def within(hil: float, sim: float, floor: float) -> bool:
    """``hil`` within RATIO of ``sim`` either way (figures below ``floor`` count as it: a
    ratio of two tiny figures says nothing)."""
    a, b = max(hil, floor), max(sim, floor)
    return a <= RATIO * b and b <= RATIO * a


def test_e2_pad_hold_through_the_emulated_ll_board_is_within_1_5x_of_sim(tmp_path):
    robot_dir = small_camera_robot(tmp_path)
    sim = pad_hold("sim", robot_dir)
    hil = pad_hold("hil", robot_dir)
    print(f"\nE2 pad hold {HOLD_S:g} s, 320x240 camera: sim:// std {sim['std_m'] * 100:.2f} cm, "
          f"max {sim['max_m'] * 100:.2f} cm; asctec-ll:// std {hil['std_m'] * 100:.2f} cm, "
          f"max {hil['max_m'] * 100:.2f} cm")
    assert sim["max_m"] < 0.15 and hil["max_m"] < 0.15  # both held over the pad
    # the 5 cm deadband: below 1 cm a standard deviation is the deadband, not the flight
    assert within(hil["std_m"], sim["std_m"], 0.01), (hil, sim)
    assert within(hil["max_m"], sim["max_m"], 0.05), (hil, sim)


def test_pad_landing_through_the_emulated_ll_board_is_within_1_5x_of_sim(tmp_path):
    robot_dir = small_camera_robot(tmp_path)
    sim = pad_landing("sim", robot_dir)
    hil = pad_landing("hil", robot_dir)
    print(f"\npad landing from 1.2 m: sim:// from {sim['start_m']:.2f} m, {sim['landed_s']:.1f} s, "
          f"{sim['miss_m'] * 100:.1f} cm off; asctec-ll:// from {hil['start_m']:.2f} m, "
          f"{hil['landed_s']:.1f} s, {hil['miss_m'] * 100:.1f} cm off")
    # Moved 0.5 m east on the onboard estimate; by the landing's start the estimate's drift
    # has moved it some (0.24 m and more from the pad here): an approach all the same.
    assert sim["start_m"] > 0.15 and hil["start_m"] > 0.15
    assert within(hil["landed_s"], sim["landed_s"], 1.0), (hil, sim)
    # The landing law commits to the vehicle's own landing within 8 cm of the centre: below
    # that a miss is where the final descent started and drifted (2-6 cm either way over
    # seeds 1-4), not how well it flew.
    assert within(hil["miss_m"], sim["miss_m"], 0.08), (hil, sim)
