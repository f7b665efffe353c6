"""benchmarks/bench_vision.py's command line: a count it cannot measure is refused by its option.

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
    ["--frames", "0"], ["--frames", "-2"], ["--repeats", "0"], ["--per-height", "0"],
])
def test_a_count_it_cannot_measure_is_refused_naming_its_option(args: list[str]) -> None:
    """``--frames 0``, ``-2`` or ``--repeats 0`` ended in a ZeroDivisionError traceback (frames/s
    of no frame); ``--per-height 0`` printed an accuracy table of "0/0" rows."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_vision.py"), *args],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {args[0]}" in done.stderr, done.stderr
