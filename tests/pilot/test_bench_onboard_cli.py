"""benchmarks/bench_onboard.py's command line: a value it cannot measure with is refused by
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
    ["--hold-s", "0"],
    ["--e2-s", "nan"],
    ["--seeds", "-1"],
])
def test_a_value_it_cannot_measure_with_is_refused_naming_its_option(args: list[str]) -> None:
    """``--hold-s 0``, ``--e2-s nan`` or ``--seeds -1`` were taken, and the run started the
    simulator with its LL board before anything looked at them."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_onboard.py"), *args],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {args[0]}" in done.stderr, done.stderr


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
