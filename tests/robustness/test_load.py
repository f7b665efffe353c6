"""Short load test: 5 control clients and 2 image clients against one real-time simulator.

The long version (20 + 8 clients) is benchmarks/bench_load.py; both share its run_load().
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from bench_load import run_load


def test_simulator_keeps_serving_under_load() -> None:
    """Every client keeps being served and the clock keeps running. Speed figures (RTF, frame
    rates) are the benchmark's job: on a shared 2-core machine they are not asserted tightly
    (the brief: speed is checked by benchmarks, never by timed tests).

    The run lasts 4 s of *sim* time, however long the host takes, and rates are per second of
    sim time: a loaded host (this failed with both cores busy when it ran for 4 wall seconds and
    asserted RTF > 0.2 and wall-clock rates) slows the run down instead of failing it. "Not
    stalled" is now: 4 s of sim time passed within the (generous) wall limit."""
    result = run_load(control=5, image=2, seconds=4.0, sim_seconds=4.0)
    print(result)
    assert result.sim_alive
    assert result.sim_seconds >= 4.0, result  # running: not stalled
    assert result.rtf < 1.2, result  # paced: not bursting (a loaded host only lowers it)
    assert result.ping_rtt_max_ms < 2000, result  # every PING answered
    assert result.lines_per_client_sim_s > 30, result  # every control client's stream flows
    assert result.image_errors == 0
    assert all(fps > 0.2 for fps in result.frames_per_client_sim_s), result  # images flow
