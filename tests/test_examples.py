"""Every script in examples/ runs to completion against a real lockstep simulator."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.control.conftest import sim_running

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
NEEDS_IMAGES = {"camera.py"}


def test_there_are_examples() -> None:
    names = {p.name for p in EXAMPLES}
    assert {"takeoff_land.py", "square.py", "gps_tour.py", "camera.py"} <= names


def test_takeoff_and_landing_is_under_ten_lines() -> None:
    text = (ROOT / "examples/takeoff_land.py").read_text()
    lines = [line for line in text.splitlines() if line.strip()]
    assert len(lines) < 10, lines


@pytest.mark.parametrize("script", EXAMPLES, ids=lambda p: p.name)
def test_example_runs(script: Path, tmp_path: Path) -> None:
    with sim_running(images=script.name in NEEDS_IMAGES) as handle:
        env = dict(os.environ, SKEYE_SIM=handle.address, PYTHONPATH=str(ROOT),
                   SKEYE_CAMERA_OUT=str(tmp_path / "camera.png"))
        if handle.images is not None:
            env["SKEYE_IMAGES"] = handle.images
        done = subprocess.run(
            [sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True,
            text=True, timeout=120,
        )
    assert done.returncode == 0, f"{script.name} failed:\n{done.stdout}\n{done.stderr}"
    if script.name == "camera.py":
        assert (tmp_path / "camera.png").stat().st_size > 1000
        assert "(600, 800, 3)" in done.stdout
