"""Sweep throughput: trials per minute with 1 and 2 workers, local pool and Ray, on this machine.

    python benchmarks/bench_sweep.py [--trials 4] [--hold-s 2] [--no-ray]

The trial is E2 in quick mode with a ``--hold-s`` hold (take-off, pad hold and drift baseline:
two full stacks of real processes). First ``--trials`` trials run one after another *alone*
(``run_experiment`` in this process, no sweep machinery) to give the time of a trial by itself;
then the same trials run as a sweep on each backend with 1 and 2 workers, each into a fresh
folder. Reported per configuration: wall time, trials per minute, overhead per trial against
running it alone (wall x workers / trials - alone), and scaling efficiency (rate with 2 workers /
(2 x rate with 1)). The Ray figures include starting its local cluster, shown separately.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from skeye.cliargs import positive_float, positive_int
from skeye.sweep.backends import LocalBackend, RayBackend
from skeye.sweep.cli import run_trials
from skeye.sweep.spec import parse_spec
from skeye.sweep.worker import run_experiment


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=positive_int, default=4, help="trials per configuration")
    ap.add_argument("--hold-s", type=positive_float, default=2.0, help="E2 hold per trial (sim s)")
    ap.add_argument("--no-ray", action="store_true", help="local backend only")
    args = ap.parse_args()
    spec = parse_spec({"experiment": "E2", "quick": True, "seeds": args.trials,
                       "grid": {"e2_duration_s": [args.hold_s]}}, Path("."))
    alone = []
    for t in spec.trials:
        with tempfile.TemporaryDirectory() as tmp:
            start = time.monotonic()
            run_experiment(t, Path(tmp))
            alone.append(time.monotonic() - start)
    alone_s = statistics.fmean(alone)
    print(f"trial alone (in-process, no sweep): {alone_s:.1f} s mean "
          f"({min(alone):.1f}-{max(alone):.1f}) over {len(alone)} trials")
    rates: dict[tuple[str, int], float] = {}
    configs = [("local", 1), ("local", 2)] + ([] if args.no_ray else [("ray", 1), ("ray", 2)])
    print("| backend | workers | wall (s) | trials/min | overhead per trial (s) | start (s) |")
    print("| --- | --- | --- | --- | --- | --- |")
    for name, workers in configs:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.monotonic()
            backend = (LocalBackend(workers) if name == "local"
                       else RayBackend(None, workers))
            started_s = time.monotonic() - t0
            try:
                t1 = time.monotonic()
                result = run_trials(spec, Path(tmp), backend, show_progress=False)
                wall_s = time.monotonic() - t1
            finally:
                backend.close()
            if result.failed:
                raise SystemExit(f"{name} x{workers}: {result.failed} trial(s) failed: "
                                 f"{[r['error'] for r in result.rows if r['error']]}")
            rate = len(spec.trials) / wall_s * 60
            rates[name, workers] = rate
            overhead = wall_s * workers / len(spec.trials) - alone_s
            print(f"| {name} | {workers} | {wall_s:.1f} | {rate:.2f} | {overhead:+.1f} | "
                  f"{started_s:.1f} |", flush=True)
    for name in ("local", "ray"):
        if (name, 2) in rates:
            eff = rates[name, 2] / (2 * rates[name, 1])
            print(f"{name}: scaling efficiency 1 -> 2 workers {eff * 100:.0f} %")


if __name__ == "__main__":
    main()
