"""benchmarks/bench_mavlink.py's command line: a value it cannot measure with is refused by
its option.

The benchmark's figures are not asserted (what it measures is the benchmark's job).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("args", [
    ["--trials", "0"],
    ["--trials", "-1"],
])
def test_a_value_it_cannot_measure_with_is_refused_naming_its_option(args: list[str]) -> None:
    """``--trials 0`` or ``-1`` started the simulator, the pilot and the MAVLink endpoint, took
    off, then ended in a StatisticsError traceback (the median of no trial)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_mavlink.py"), *args],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {args[0]}" in done.stderr, done.stderr
