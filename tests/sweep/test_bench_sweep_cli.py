"""benchmarks/bench_sweep.py's command line: a value it cannot measure with is refused by
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
    ["--hold-s", "nan"],
    ["--hold-s", "-1"],
])
def test_a_value_it_cannot_measure_with_is_refused_naming_its_option(args: list[str]) -> None:
    """``--trials 0`` ended in the spec's LocalProtocolError traceback ("seeds must be >= 1"),
    ``--hold-s nan`` in another ("e2_duration_s must be finite"); ``--hold-s -1`` was handed to
    the experiment."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_sweep.py"), *args],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {args[0]}" in done.stderr, done.stderr
