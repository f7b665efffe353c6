"""benchmarks/bench_poll.py's figures: a phase with no answer is reported as such, and the
start-up line names its time (its options' refusals: tests/test_benchmark_options.py).

The benchmark's figures are not asserted (speed is the benchmark's job).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from bench_poll import _stats

ROOT = Path(__file__).resolve().parents[2]


def test_a_phase_with_no_answer_is_reported_not_raised(capsys: pytest.CaptureFixture[str]) -> None:
    """Every poll of a phase unanswered (a pilot that stopped answering) raised an IndexError
    (the p99 of no round trip) and ended the run before the other phases' figures."""
    _stats("steady LL_STATUS", [], 5)
    assert "steady LL_STATUS: no poll answered, unanswered 5" in capsys.readouterr().out


def test_the_start_up_line_names_the_time_it_polled_for() -> None:
    """``--startup-s 0.5`` printed "in the first 0 s" (the seconds rounded to a whole number)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_poll.py"),
                           "--polls", "1", "--startup-s", "0.5"], env=env, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "in the first 0.5 s" in done.stdout, done.stdout
