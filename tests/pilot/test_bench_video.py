"""benchmarks/bench_video.py's command line: a frame size or quality the video port cannot serve
is refused by its option.

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
    ["--width", "0"], ["--height", "1"], ["--width", "-5"], ["--quality", "500"],
    ["--quality", "0"],
])
def test_a_frame_it_cannot_serve_is_refused_naming_its_option(args: list[str]) -> None:
    """``--width 0`` ended in a LocalProtocolError traceback ("image must be at least 2x2
    pixels") after rendering the views, ``--quality 500`` in a ConfigError traceback from the
    video server."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_video.py"),
                           "--frames", "3", *args], env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {args[0]}" in done.stderr, done.stderr
