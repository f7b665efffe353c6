"""benchmarks/bench_camera.py's command line: a value it cannot measure is refused by its option.

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
    ["--stages", "--stage-repeats", "0"], ["--only-lockstep", "--lockstep", "0"],
    ["--clients", "0"], ["--fps", "nan"], ["--seconds", "-1"],
])
def test_a_value_it_cannot_measure_is_refused_naming_its_option(args: list[str]) -> None:
    """Each started a simulator (or rendered the world) first: ``--stage-repeats 0`` then ended
    in "min() arg is an empty sequence", ``--lockstep 0`` in an IndexError, ``--clients 0`` in
    "max() arg is an empty sequence", ``--fps nan`` in a stream thread's LocalProtocolError
    traceback and "a client got fewer than 2 frames", ``--seconds -1`` in that same line."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_camera.py"), *args],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    option = next(a for a in args if a not in ("--stages", "--only-lockstep") and a[:2] == "--")
    assert f"argument {option}" in done.stderr, done.stderr
