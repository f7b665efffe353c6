"""The connection limits both simulator servers (control and image) take, checked one way, and
the physics step's range (here, not in :mod:`skeye.sim.engine`: ``skeye sim --check`` checks
``--timestep`` without importing MuJoCo)."""

from __future__ import annotations

import math

from skeye.errors import ConfigError

TIMESTEP_RANGE_S = (1e-5, 0.01)
"""The physics step a simulation takes (``skeye sim --timestep``), seconds, both ends in."""


def check_server_limits(server: str, **limits: float) -> None:
    """Refuse a limit that is not a finite number above zero.

    Raises:
        ConfigError: naming the server, the limit and the value given.
    """
    for what, value in limits.items():
        if not (math.isfinite(value) and value > 0):
            raise ConfigError(f"{server}: {what} must be > 0, got {value!r}")
