"""benchmarks/bench_pilot.py's command line: a value it cannot measure with is refused by its
option.

The benchmark's figures are not asserted (speed is the benchmark's job).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("args", [
    ["--polls", "0"], ["--polls", "-1"], ["--stream-s", "-1"], ["--stream-s", "nan"],
    ["--stream-s", "0"],
])
def test_a_value_it_cannot_measure_with_is_refused_naming_its_option(args: list[str]) -> None:
    """``--polls 0`` started the simulator and the pilot, then ended in a StatisticsError
    traceback (the median of no poll); ``--stream-s -1`` or ``nan`` in time.sleep's ValueError
    after the polls; ``--stream-s 0`` printed push rates over no stream (912 pushes/s at a 20 ms
    period)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_pilot.py"),
                           "--polls", "5", *args], env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {args[0]}" in done.stderr, done.stderr
