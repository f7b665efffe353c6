"""Every benchmark refuses a value it cannot run with, by its option, before it starts anything.

Almost every benchmark took ``type=int`` / ``type=float`` unchecked, and a bad value ended in a
traceback, often after it had started a simulator and a pilot (the median or p99 of no sample,
a ZeroDivisionError over no time, numpy's refusal of a negative seed), or, worse, printed
figures measured over nothing with status 0 (``fuzz_protocols --seconds 0``: "OK: only
protocol errors" after no input; ``bench_pilot --stream-s 0``: 912 pushes/s). They now use
:mod:`skeye.cliargs`' types. Each case runs the benchmark as a user does; its figures are not
asserted (speed is the benchmarks' job).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CASES = [
    *(("bench_limit", a) for a in (
        ["--sim-seconds", "0"], ["--sim-seconds", "nan"], ["--sim-seconds", "-1"],
        ["--repeats", "0"], ["--vehicles", "1", "0"], ["--vehicles", "-1"], ["--seed", "-5"])),
    # --sim-seconds under one 0.5 s STEP printed real-time factors of 0.0x over no step
    *(("bench_sim", a) for a in (
        ["--sim-seconds", "0.3"], ["--sim-seconds", "nan"], ["--samples", "0"],
        ["--repeats", "-1"], ["--timestep", "0"], ["--board-rate", "nan"])),
    *(("bench_vision", a) for a in (
        ["--frames", "0"], ["--frames", "-2"], ["--repeats", "0"], ["--per-height", "0"])),
    # under 0.1 s there is no comparison with the truth to average
    *(("bench_estimator", a) for a in (
        ["--sim-seconds", "0"], ["--sim-seconds", "0.05"], ["--sim-seconds", "nan"],
        ["--sim-seconds", "-1"], ["--seed", "-1"])),
    *(("bench_poll", a) for a in (
        ["--polls", "0"], ["--polls", "-3"], ["--startup-s", "nan"], ["--startup-s", "-1"])),
    *(("bench_camera", a) for a in (
        ["--stages", "--stage-repeats", "0"], ["--only-lockstep", "--lockstep", "0"],
        ["--clients", "0"], ["--fps", "nan"], ["--seconds", "-1"])),
    # --seconds nan or inf hung: the client processes' results were waited for that long
    *(("bench_image_server", ["--seconds", s]) for s in ("0", "-1", "nan", "inf")),
    *(("fuzz_protocols", ["--seconds", s]) for s in ("0", "-1", "nan", "inf")),
    *(("bench_video", a) for a in (
        ["--width", "0"], ["--height", "1"], ["--width", "-5"], ["--quality", "500"],
        ["--quality", "0"])),
    *(("bench_pilot", a) for a in (
        ["--polls", "0"], ["--polls", "-1"], ["--stream-s", "-1"], ["--stream-s", "nan"],
        ["--stream-s", "0"])),
    *(("bench_load", a) for a in (
        ["--control", "-1"], ["--control", "0"], ["--image", "-1"], ["--seconds", "nan"],
        ["--seconds", "0"], ["--fps", "0"])),
    *(("bench_hardening", a) for a in (
        ["--clients", "0"], ["--handshake-timeout", "nan"], ["--handshake-timeout", "0"])),
    *(("bench_sweep", a) for a in (["--trials", "0"], ["--hold-s", "nan"], ["--hold-s", "-1"])),
    *(("bench_mavlink", a) for a in (["--trials", "0"], ["--trials", "-1"])),
    *(("bench_pad_latency", a) for a in (["--latency-ms", "nan"], ["--latency-ms", "-1"])),
    *(("bench_onboard", a) for a in (["--hold-s", "0"], ["--e2-s", "nan"], ["--seeds", "-1"])),
    # --ports '' started the simulator, the pilot and the ground station, then a KeyError
    *(("bench_attack", a) for a in (
        ["--ports", "control,bogus"], ["--ports", ""], ["--connections", "0"],
        ["--rate", "nan"], ["--samples", "0"], ["--ramp-s", "-1"])),
]


@pytest.mark.parametrize(("bench", "args"), CASES,
                         ids=[f"{b} {' '.join(a)}" for b, a in CASES])
def test_a_value_a_benchmark_cannot_run_with_is_refused_naming_its_option(
        bench: str, args: list[str]) -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / f"{bench}.py"), *args],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    option = next(a for a in reversed(args) if a.startswith("--"))
    assert f"argument {option}" in done.stderr, done.stderr
