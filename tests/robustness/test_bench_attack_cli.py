"""benchmarks/bench_attack.py's command line: a port it does not know or a count it cannot
attack with is refused by its option, before any process starts.

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
    ["--ports", "control,bogus"], ["--ports", ""], ["--connections", "0"], ["--rate", "nan"],
    ["--samples", "0"], ["--ramp-s", "-1"],
])
def test_a_value_it_cannot_attack_with_is_refused_naming_its_option(args: list[str]) -> None:
    """``--ports ''`` or ``control,bogus`` started the simulator, the pilot and the ground
    station, then ended in a KeyError traceback (after timing every port named before the
    unknown one); the counts were handed to the attackers as they were."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_attack.py"), *args],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {args[0]}" in done.stderr, done.stderr
