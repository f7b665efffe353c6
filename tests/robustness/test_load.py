"""Short load test: 5 control clients and 2 image clients against one real-time simulator.

The long version (20 + 8 clients) is benchmarks/bench_load.py; both share its run_load().
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from bench_load import run_load


def test_simulator_keeps_real_time_under_load() -> None:
    result = run_load(control=5, image=2, seconds=4.0)
    assert result.sim_alive
    assert 0.7 < result.rtf < 1.1, result
    assert result.ping_rtt_max_ms < 500, result
    assert result.lines_per_client_s > 150, result  # ~300 lines/s per hummingbird
    assert result.image_errors == 0
    assert all(fps > 0.5 for fps in result.frames_per_client_s), result
