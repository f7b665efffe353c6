"""benchmarks/bench_estimator.py's command line: a value it cannot measure is refused by its option.

The benchmark's figures are not asserted (accuracy figures are the benchmark's job).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("args", [
    ["--sim-seconds", "0"], ["--sim-seconds", "0.05"], ["--sim-seconds", "nan"],
    ["--sim-seconds", "-1"], ["--seed", "-1"],
])
def test_a_value_it_cannot_measure_is_refused_naming_its_option(args: list[str]) -> None:
    """``--sim-seconds 0``, ``0.05`` or ``-1`` (no comparison with the truth) ended in a
    ZeroDivisionError traceback, ``nan`` in "cannot convert float NaN to integer", ``--seed -1``
    in numpy's "expected non-negative integer"."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_estimator.py"),
                           *args], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {args[0]}" in done.stderr, done.stderr
