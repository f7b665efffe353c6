"""Pad hold and landing against vision latency, with and without the prediction (issue 18).

Run: ``python benchmarks/bench_pad_latency.py [--latency-ms 540 300 ...] [--only hold|land]``.
Each flight is the lockstep flight of ``tests/pilot/test_pad_latency.py`` (latency in sim
time, so the figures do not depend on this machine's speed), written out here so that the
benchmark runs from an installed package: pad hold started 0.6 m off for 20 s, and PAD_MODE
LAND from 3 m east of the pad at 4.5 m; for each latency it flies with the prediction, without
it (gains derived for that loop's delay), and without it with the gains the pilot had before
(kp 1.2, ki 0.15). About 30-60 s of wall time per flight.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass

from skeye.cliargs import non_negative_float
from skeye.control.connection import connect
from skeye.link.vehicle import Vehicle
from skeye.pilot.cli import pad_vision_factory
from skeye.pilot.pad_hold import PadHoldParams
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.pilot.vision import PadVision
from skeye.sim.cameras import CameraSystem
from skeye.sim.engine import Simulation
from skeye.sim.frame_store import FrameBuffer
from skeye.sim.image_server import ImageServer
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.world import load_world
from skeye.wire.packets import NavState, SkeyeMask

Sample = tuple[float, float, float, float]  # sim time, north, east, down

VARIANTS = (
    ("predicted", True, None),
    ("not predicted, gains for its delay", False, None),
    ("not predicted, previous gains 1.2/0.15", False, PadHoldParams(kp=1.2, ki=0.15)),
)


@dataclass
class Flight:
    vehicle: Vehicle
    runner: SimulationRunner
    pilot: PilotServer

    @property
    def vision(self) -> PadVision:
        assert isinstance(self.pilot.vision, PadVision)
        return self.pilot.vision

    def truth(self) -> Sample:
        """Sim time and the true position (north, east, down) of the vehicle."""
        def read(sim: Simulation) -> Sample:
            n, e, d = sim.body_state("R1").pos_ned_m
            return (sim.time_s, float(n), float(e), float(d))
        return self.runner.call(read)

    def record_until(self, done: Callable[[list[Sample]], bool],
                     timeout_s: float = 600.0) -> list[Sample]:
        """Sample (time, north, east, down) until ``done(samples)`` (waiting on sim time)."""
        samples = [self.truth()]
        deadline = time.monotonic() + timeout_s
        while not done(samples):
            if time.monotonic() > deadline:
                raise TimeoutError("the flight did not finish in time")
            if self.pilot.loop_error is not None:
                raise RuntimeError(f"the pilot failed: {self.pilot.loop_error}")
            time.sleep(0.005)
            sample = self.truth()
            if sample[0] > samples[-1][0]:
                samples.append(sample)
        return samples


@contextmanager
def flight(location_ne_m: tuple[float, float], *, predict: bool,
           params: PadHoldParams | None, latency_s: float) -> Iterator[Flight]:
    """The pad world in lockstep with its image server (the oracle estimator: the hold is
    measured against ground truth in centimetres), the pilot with pad vision on top."""
    with ExitStack() as stack:
        sim = Simulation(load_world("pad"), seed=3, estimator="truth")
        buffer = FrameBuffer()
        runner = stack.enter_context(SimulationRunner(sim, mode="lockstep"))
        stack.enter_context(CameraSystem(sim, buffer, synchronous=True, profile="ideal"))
        control = stack.enter_context(ControlServer(runner, port=0))
        images = stack.enter_context(ImageServer(buffer, port=0))
        client = stack.enter_context(
            connect(f"127.0.0.1:{control.port}", images=f"127.0.0.1:{images.port}")
        )
        robot = client.spawn("hummingbird", location_ned_m=(*location_ne_m, 0.0))
        pilot = stack.enter_context(
            PilotServer(SimAirframe(client, robot), port=0, lockstep=True, lockstep_rate=5.0,
                        tick_s=0.05,
                        vision=pad_vision_factory(client, robot, latency_s=latency_s,
                                                  predict=predict, params=params))
        )
        vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=10.0))
        vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.05)
        yield Flight(vehicle, runner, pilot)


def hold_from_0_6_m(predict: bool, params: PadHoldParams | None,
                    latency_s: float) -> tuple[float, float, float]:
    """Pad hold started 0.6 m off: (start offset, settling time within 0.1 m after which it
    stays within, largest offset in the last 10 of 20 s), in m and s."""
    with flight((0.6, 0.0), predict=predict, params=params, latency_s=latency_s) as f:
        f.vehicle.take_off(1.5)
        f.vehicle.wait_state(NavState.HOLDING, timeout_s=120)
        start = f.truth()
        f.vehicle.pad_mode(1, deadband_m=0.05, max_speed_m_s=0.3)
        samples = f.record_until(lambda s: s[-1][0] >= start[0] + 20.0)
    offsets = [(t - start[0], math.hypot(n, e)) for t, n, e, _ in samples]
    settled = 0.0
    for t, off in offsets:
        if off > 0.1:
            settled = t
    late = max(off for t, off in offsets if t >= 10.0)
    return math.hypot(start[1], start[2]), settled, late


def land_from_3_m(predict: bool, params: PadHoldParams | None,
                  latency_s: float) -> tuple[float, float, float]:
    """PAD_MODE LAND from 3 m east of the pad at 4.5 m: (start distance, time to landed, the
    landed position's distance from the pad centre), in m and s; NaN time if it never landed
    within 120 s."""
    with flight((0.0, 3.0), predict=predict, params=params, latency_s=latency_s) as f:
        f.vehicle.take_off(4.5)
        f.vehicle.wait_state(NavState.HOLDING, timeout_s=120)
        start = f.truth()
        f.vehicle.pad_mode(2, deadband_m=0.05, max_speed_m_s=0.3)

        def landed(samples: list[Sample]) -> bool:
            return (f.pilot.boards.state is NavState.LANDED
                    or samples[-1][0] > start[0] + 120.0)

        samples = f.record_until(landed)
        did_land = f.pilot.boards.state is NavState.LANDED
    t, n, e, _ = samples[-1]
    return math.hypot(start[1], start[2]), t - start[0] if did_land else math.nan, math.hypot(n, e)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--latency-ms", type=non_negative_float, nargs="+", default=[540.0])
    ap.add_argument("--only", choices=("hold", "land"), default=None)
    args = ap.parse_args()
    for ms in args.latency_ms:
        for label, predict, params in VARIANTS:
            if args.only != "land":
                start, settled, late = hold_from_0_6_m(predict, params, ms / 1e3)
                print(f"{ms:.0f} ms, {label}: hold from {start:.2f} m: within 0.1 m from "
                      f"{settled:.1f} s on; largest offset 10-20 s {late * 100:.1f} cm", flush=True)
            if args.only != "hold":
                start, landed, miss = land_from_3_m(predict, params, ms / 1e3)
                print(f"{ms:.0f} ms, {label}: LAND from {start:.2f} m: landed after "
                      f"{landed:.1f} s, {miss * 100:.1f} cm from the centre", flush=True)


if __name__ == "__main__":
    main()
