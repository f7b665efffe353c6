"""benchmarks/bench_gym.py's command line: a count it cannot run is refused by its option.

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
    ["--envs", "0"], ["--envs", "257"], ["--steps", "0"], ["--camera-steps", "-1"],
    ["--repeats", "0"],
])
def test_a_count_it_cannot_run_is_refused_naming_its_option(args: list[str]) -> None:
    """``--envs 0`` ended in a ZeroDivisionError traceback, ``--envs 257`` in the native
    vector environment's ConfigError after the single environment's run, and ``--steps 0``
    or ``--repeats 0`` printed rates of 0 steps/s measured on nothing."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_gym.py"),
                           "--no-camera", *args], env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {args[0]}" in done.stderr, done.stderr
