"""Wall-clock guards stretch with the machine (skeye.processes.machine_scale)."""

from __future__ import annotations

import os

import pytest

from skeye.errors import ConfigError
from skeye.processes import TIMEOUT_SCALE_ENV, machine_scale, scaled_s


def test_the_scale_follows_the_load_and_never_shrinks(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(TIMEOUT_SCALE_ENV, raising=False)
    cores = os.cpu_count() or 1
    monkeypatch.setattr(os, "getloadavg", lambda: (3.0 * cores, 0.0, 0.0))
    assert machine_scale() == pytest.approx(3.0)
    assert scaled_s(10.0) == pytest.approx(30.0)
    monkeypatch.setattr(os, "getloadavg", lambda: (0.1, 0.0, 0.0))
    assert scaled_s(10.0) == 10.0


def test_the_environment_sets_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(TIMEOUT_SCALE_ENV, "4")
    assert scaled_s(10.0) == 40.0
    monkeypatch.setenv(TIMEOUT_SCALE_ENV, "0.5")
    with pytest.raises(ConfigError, match=TIMEOUT_SCALE_ENV):
        machine_scale()
    monkeypatch.setenv(TIMEOUT_SCALE_ENV, "fast")
    with pytest.raises(ConfigError, match="number"):
        machine_scale()
