"""benchmarks/bench_load.py's command line: a value it cannot measure with is refused by
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
    ["--control", "-1"],
    ["--control", "0"],
    ["--image", "-1"],
    ["--seconds", "nan"],
    ["--seconds", "0"],
    ["--fps", "0"],
])
def test_a_value_it_cannot_measure_with_is_refused_naming_its_option(args: list[str]) -> None:
    """``--control 0`` or ``-1`` started the simulator, then ended in an IndexError traceback
    (the pinger is the first control client); ``--image -1`` ran with none; ``--seconds nan``
    printed an empty result with status 0; ``--fps 0`` asked the image server for no frames."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_load.py"), *args],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {args[0]}" in done.stderr, done.stderr
