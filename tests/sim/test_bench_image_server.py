"""benchmarks/bench_image_server.py's command line: a time it cannot measure over is refused by
its option.

The benchmark's figures are not asserted (speed is the benchmark's job).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("seconds", ["0", "-1", "nan", "inf"])
def test_a_time_it_cannot_measure_over_is_refused_naming_its_option(seconds: str) -> None:
    """``--seconds nan`` hung (the client processes' results waited for with a timeout of nan),
    with leaked semaphores when killed; ``--seconds 0`` or ``-1`` printed a table of client
    frame rates of 0.0 measured over no time."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_image_server.py"),
                           "--seconds", seconds], env=env, capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert "argument --seconds" in done.stderr, done.stderr
