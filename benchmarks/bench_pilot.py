"""Pilot benchmark over loopback TCP: poll round-trip latency and telemetry stream rate.

Runs a realtime simulator, a pilot on a spawned Hummingbird, and a ``skeye.link.Vehicle``:
``N`` polls of LL_STATUS and of every structure (p50/p99 round trip), then a STREAM of
NAV_STATUS + IMU_CALCDATA at the fastest period (1 ms, bounded by the pilot's tick) and at
20 ms, counting frames per second. Usage: ``python benchmarks/bench_pilot.py [--polls 500]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from skeye.cliargs import positive_float, positive_int
from skeye.control.connection import connect
from skeye.link.vehicle import Vehicle
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.sim.engine import Simulation
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.world import load_world
from skeye.wire.packets import PD, POLL_MASK_ALL, PollMask, SkeyeMask


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--polls", type=positive_int, default=500)
    ap.add_argument("--stream-s", type=positive_float, default=3.0)
    args = ap.parse_args()
    sim = Simulation(load_world("pad"), seed=1)
    with (
        SimulationRunner(sim, mode="realtime") as runner,
        ControlServer(runner, port=0) as server,
        connect(f"127.0.0.1:{server.port}") as conn,
    ):
        robot = conn.spawn("hummingbird", start="Pad1")
        with (
            PilotServer(SimAirframe(conn, robot), port=0, tick_s=0.001) as pilot,
            Vehicle.open(pilot.address) as vehicle,
        ):
            for label, mask in (("LL_STATUS", int(PollMask.LL_STATUS)), ("all 8", POLL_MASK_ALL)):
                vehicle.poll(mask)
                rtts = []
                for _ in range(args.polls):
                    t0 = time.perf_counter()
                    vehicle.poll(mask)
                    rtts.append((time.perf_counter() - t0) * 1000)
                print(
                    f"poll {label:9s}: p50 {statistics.median(rtts):.3f} ms, "
                    f"p99 {percentile(rtts, 0.99):.3f} ms, max {max(rtts):.3f} ms "
                    f"({args.polls} polls)"
                )
            for period_s in (0.001, 0.02):
                vehicle.stream(int(PollMask.IMU_CALCDATA), int(SkeyeMask.NAV_STATUS), period_s)
                start = vehicle.parser.messages
                t0 = time.monotonic()
                vehicle.wait_for(PD.NAV_STATUS)
                time.sleep(args.stream_s)
                frames = vehicle.parser.messages - start
                elapsed = time.monotonic() - t0
                vehicle.stream(0, 0, 0.0)
                print(
                    f"stream period {period_s * 1000:g} ms: {frames / elapsed / 2:.0f} pushes/s "
                    f"({frames / elapsed:.0f} frames/s, 2 frames per push)"
                )
            print(f"realtime factor of the sim meanwhile: {runner.realtime_factor():.2f}")


if __name__ == "__main__":
    main()
