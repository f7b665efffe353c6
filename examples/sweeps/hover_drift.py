"""A flight script for ``skeye sweep`` (experiment = "script"): hover under wind, no vision.

The entry point is ``trial(settings, params, workdir) -> dict[str, float]``: ``settings`` is the
trial's RunSettings (seed, quick, wind, f_max_n, ...: the spec's parameters that RunSettings has),
``params`` every parameter of the trial (here ``height_m`` and ``hold_s``), ``workdir`` a folder
of its own. It returns the trial's figures. It runs in its own process, one trial at a time.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from skeye.validate.experiments import (
    RunSettings,
    flight_stack,
    ground_truth,
    until_state,
    wait_sim,
)
from skeye.wire.packets import NavState


def trial(settings: RunSettings, params: dict[str, Any], workdir: Path) -> dict[str, float]:
    record = workdir / "hover.rec"
    hold_s = float(params.get("hold_s", 10.0))
    with flight_stack(settings, record, vision=False, wind=True) as vehicle:
        vehicle.take_off(float(params.get("height_m", 1.0)))
        start = until_state(vehicle, NavState.HOLDING)
        end = wait_sim(vehicle, hold_s, timeout_s=hold_s * 10 + 120)
    drift = [math.hypot(n, e) for t, n, e, _d, _tilt in ground_truth(record) if start <= t <= end]
    return {"max_drift_m": max(drift), "final_drift_m": drift[-1], "samples": len(drift)}
