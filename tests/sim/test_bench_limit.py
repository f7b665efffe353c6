"""benchmarks/bench_limit.py's command line: a value it cannot measure is refused by its option.

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
    ["--sim-seconds", "0"], ["--sim-seconds", "nan"], ["--sim-seconds", "-1"],
    ["--repeats", "0"], ["--vehicles", "1", "0"], ["--vehicles", "-1"], ["--seed", "-5"],
])
def test_a_value_it_cannot_measure_is_refused_naming_its_option(args: list[str]) -> None:
    """``--sim-seconds 0`` ended in a ZeroDivisionError traceback, ``nan`` in "cannot convert
    float NaN to integer", ``--repeats 0`` in "max() arg is an empty sequence", ``--seed -5``
    in numpy's "expected non-negative integer", each after building the hovering vehicles;
    ``--vehicles 0`` or ``-1`` printed real-time factors of a world with no vehicle in it."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_limit.py"), *args],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {args[0]}" in done.stderr, done.stderr
