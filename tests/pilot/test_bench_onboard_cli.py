"""benchmarks/bench_onboard.py: its CPU run opens the airframe the simulator names (its
options' refusals: tests/test_benchmark_options.py).

The benchmark's figures are not asserted (what it measures is the benchmark's job).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_cpu_run_opens_the_airframe_the_simulator_names() -> None:
    """The simulator's LL-board line quotes the URIs for a shell (``--airframe
    'asctec-ll://serial/dev/pts/0?lockstep=1'``); the benchmark took the quotes as part of the
    URI, and every ``--only cpu`` run (and the default run) ended in "no backend for
    'asctec-ll://"."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_onboard.py"),
                           "--only", "cpu", "--hold-s", "0.5"], env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert "CPU per control tick" in done.stdout, done.stdout
