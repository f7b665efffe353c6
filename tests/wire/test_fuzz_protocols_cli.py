"""benchmarks/fuzz_protocols.py's command line: a time it cannot fuzz for is refused by its
option, not reported as a clean run."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("seconds", ["0", "-1", "nan", "inf"])
def test_a_time_it_cannot_fuzz_for_is_refused_naming_its_option(seconds: str) -> None:
    """``--seconds 0``, ``-1`` or ``nan`` tried 0 inputs per codec and printed "OK: only
    protocol errors" with status 0: a fuzz run that fuzzed nothing passed; ``inf`` never ended."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "fuzz_protocols.py"),
                           "--seconds", seconds], env=env, capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert "argument --seconds" in done.stderr, done.stderr
    assert "OK" not in done.stdout
