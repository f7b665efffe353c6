"""The engine against MuJoCo's own speed: skeye's in-process real-time factor beside raw mj_step.

For 1 and 10 Hummingbirds hovering over the pad (every sensor of the robot file sampled, the
board, its onboard estimator and the readings handed to a sink, as an in-process user or a
learning environment steps :class:`skeye.sim.engine.Simulation`), this measures:

- skeye: ``sim.step(n)``, wall time per simulated second;
- raw mj_step on the very model skeye built (``sim.model``), from skeye's state at the end of
  its run, with the wrench skeye's boards last set held constant (the vehicles hover on, no
  contacts, as in skeye's run): once as MuJoCo's own C loop (``mj_step(model, data, n)``) and
  once as a Python loop of single ``mj_step`` calls (what a Python user of MuJoCo writes).

Both are measured ``--repeats`` times, alternating, in this one process; each figure is the best
(closest to what the code costs on a shared machine) with the median beside it, and the ratio
skeye / raw is taken from the best of each. The machine's load average is printed before and
after. The simulator's hot path is compiled with mypyc (skeye.native): the figures are only
meaningful where that line says "compiled".

Usage: python benchmarks/bench_limit.py [--vehicles 1 10] [--sim-seconds 5] [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from skeye import native
from skeye.cliargs import positive_float, positive_int, seed
from skeye.sim.engine import Simulation
from skeye.sim.gl import GL_BACKEND  # noqa: F401  (before mujoco: picks MUJOCO_GL)
from skeye.sim.readings import Event
from skeye.sim.world import load_world

# isort: split
import mujoco


def load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f}, {five:.2f}, {fifteen:.2f} ({os.cpu_count()} cores)"


class Counter:
    """A sink that keeps count of the readings (the engine makes them all the same)."""

    def __init__(self) -> None:
        self.events = 0

    def __call__(self, events: list[Event]) -> None:
        self.events += len(events)


def hovering(vehicles: int, seed: int) -> tuple[Simulation, Counter]:
    sim = Simulation(load_world("pad"), seed=seed)
    sink = Counter()
    for i in range(vehicles):
        sim.spawn("hummingbird", name=f"R{i + 1}", sink=sink,
                  location_ned_m=(3.0 * (i % 5) - 6.0, 3.0 * (i // 5) - 1.5, -2.0))
    sim.step(500)  # settle into the hover
    return sim, sink


def measure(vehicles: int, args: argparse.Namespace) -> None:
    sim, sink = hovering(vehicles, args.seed)
    steps = max(1, round(args.sim_seconds / sim.dt))
    sim_s = steps * sim.dt  # what is simulated: --sim-seconds to the nearest step
    model = sim.model
    data = mujoco.MjData(model)
    skeye_rtf: list[float] = []
    c_rtf: list[float] = []
    loop_rtf: list[float] = []
    events = 0
    for _ in range(args.repeats):
        before = sink.events
        t0 = time.perf_counter()
        sim.step(steps)
        skeye_rtf.append(sim_s / (time.perf_counter() - t0))
        events = sink.events - before
        for target, loop in ((c_rtf, False), (loop_rtf, True)):
            data.qpos[:] = sim.data.qpos
            data.qvel[:] = sim.data.qvel
            data.xfrc_applied[:] = sim.data.xfrc_applied
            data.time = sim.data.time
            mujoco.mj_forward(model, data)
            t0 = time.perf_counter()
            if loop:
                for _ in range(steps):
                    mujoco.mj_step(model, data)
            else:
                mujoco.mj_step(model, data, steps)
            target.append(sim_s / (time.perf_counter() - t0))
        if data.ncon:
            print(f"  (note: the raw run met {data.ncon} contacts)")

    def line(name: str, values: list[float]) -> str:
        return f"{name} {max(values):7.1f}x (median {statistics.median(values):7.1f}x)"

    skeye_best, c_best, loop_best = max(skeye_rtf), max(c_rtf), max(loop_rtf)
    print(f"{vehicles:2d} vehicle(s), {sim_s:g} s x {args.repeats}: "
          f"{line('skeye', skeye_rtf)}; raw {line('mj_step C loop', c_rtf)}, "
          f"{line('Python loop', loop_rtf)}", flush=True)
    print(f"   skeye / raw mj_step: {skeye_best / c_best:.2f} (C loop), "
          f"{skeye_best / loop_best:.2f} (Python loop); {events / sim_s:.0f} "
          f"readings per sim second; skeye's own share of a step "
          f"{1.0 - skeye_best / c_best:.0%}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=positive_int, nargs="+", default=[1, 10])
    parser.add_argument("--sim-seconds", type=positive_float, default=5.0)
    parser.add_argument("--repeats", type=positive_int, default=5)
    parser.add_argument("--seed", type=seed, default=1)
    args = parser.parse_args()
    print(f"bench_limit: {native.status().describe()}; MuJoCo {mujoco.__version__}; {load()}")
    for vehicles in args.vehicles:
        measure(vehicles, args)
    print(f"bench_limit: {load()} at the end")


if __name__ == "__main__":
    main()
