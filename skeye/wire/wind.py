"""Wind settings: the modes and parameters of ``SET {Type Wind} {Mode m} {Params k=v,...}``
(docs/protocols/simulator.md) and of ``skeye sim --wind/--wind-params``, checked.

The simulator's wind model (:mod:`skeye.sim.wind`) takes a :class:`WindSettings`; clients and
tools that only start or configure a simulator (``skeye validate``, ``skeye sweep``) check
their settings here by the same rule, without the simulator. Bad keys or values raise
ConfigError naming them; every parameter has a physical range (:data:`PARAM_RANGES`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from skeye.errors import ConfigError
from skeye.wire.sim_lines import DECIMAL_PATTERN

WIND_MODES = ("none", "constant", "turbulence", "dryden", "random_force")

_DEFAULTS: Final[dict[str, dict[str, float]]] = {
    "none": {},
    "constant": {"speed_m_s": 2.0, "from_deg": 270.0},
    "turbulence": {"speed_m_s": 2.0, "from_deg": 270.0, "sigma_m_s": 1.0},
    "dryden": {"w20_m_s": 2.6, "from_deg": 270.0, "height_m": 1.0},
    "random_force": {"f_max_n": 0.3, "tick_s": 1.0 / 30.0},
}

# Plain decimal text, as the wire's numbers (the digits split one way only: see
# DECIMAL_PATTERN); nan and inf are read so that the range check names them with the
# parameter's range.
_NUMBER = re.compile(rf"\s*(?:{DECIMAL_PATTERN}|[+-]?(?:nan|inf|infinity))\s*\Z",
                     re.ASCII | re.IGNORECASE)

# Physical ranges, inclusive (name: (low, high, why)). Winds above 40 m/s are beyond any small
# UAV's operating envelope (Beaufort 12 starts at 32.7 m/s); a disturbance above 50 N is many
# times the weight of the vehicles simulated here; redraw periods run from one physics step at
# the coarsest (1 ms) up to an hour.
PARAM_RANGES: Final[dict[str, tuple[float, float]]] = {
    "speed_m_s": (0.0, 40.0),
    "from_deg": (-360.0, 360.0),
    "sigma_m_s": (0.0, 20.0),
    "f_max_n": (0.0, 50.0),
    "tick_s": (0.001, 3600.0),
    "w20_m_s": (0.0, 40.0),
    "height_m": (0.0, 304.8),  # the specification's low-altitude model ends at 1000 ft
}


@dataclass(frozen=True)
class WindSettings:
    """A validated wind mode and its parameters."""

    mode: str
    params: tuple[tuple[str, float], ...]

    def get(self, key: str) -> float:
        return dict(self.params)[key]

    def describe(self) -> str:
        return ",".join(f"{k}={v:g}" for k, v in self.params)


def parse_params(text: str) -> dict[str, float]:
    """``"speed_m_s=3,from_deg=90"`` -> dict. A lone number sets the mode's first parameter.

    Numbers are plain decimal text, as everywhere in the protocol (not ``1_0`` nor ``0x1``;
    ``nan`` and ``inf`` are left to the range check, which names them); a key given twice, or
    two lone numbers, is refused rather than the last one silently kept.
    """
    text = text.strip()
    if not text:
        return {}
    out: dict[str, float] = {}
    for part in text.split(","):
        if "=" not in part:
            if not _NUMBER.match(part):
                raise ConfigError(f"wind params: expected key=value, got {part!r}")
            key, value = "_", part
        else:
            key, _, value = part.partition("=")
            key = key.strip()
            if not _NUMBER.match(value):
                raise ConfigError(f"wind params: {key} is not a number: {value!r}")
        if key in out:
            what = "a lone number (the mode's first parameter)" if key == "_" else key
            raise ConfigError(f"wind params: {what} given twice in {text!r}")
        out[key] = float(value)
    return out


def make_settings(mode: str, params: Mapping[str, float] | None = None) -> WindSettings:
    """Validate a mode and its parameters (unknown keys, negative or non-finite values)."""
    mode = mode.strip().lower()
    if mode not in _DEFAULTS:
        raise ConfigError(f"wind: unknown mode {mode!r}; modes: {', '.join(WIND_MODES)}")
    values = dict(_DEFAULTS[mode])
    given = dict(params or {})
    if "_" in given:
        if not values:
            raise ConfigError(f"wind: mode {mode!r} takes no parameters")
        first = next(iter(values))
        if first in given:
            raise ConfigError(f"wind: {first} given twice (a lone number is the mode's first "
                              f"parameter, {first})")
        values[first] = given.pop("_")
    for key, value in given.items():
        if key not in values:
            raise ConfigError(
                f"wind: unknown parameter {key!r} for mode {mode!r}; "
                f"known: {', '.join(sorted(values)) or 'none'}"
            )
        values[key] = value
    for key, value in values.items():
        low, high = PARAM_RANGES[key]
        if not (math.isfinite(value) and low <= value <= high):
            raise ConfigError(f"wind: {key} must be in [{low:g}, {high:g}], got {value!r}")
    return WindSettings(mode, tuple(sorted(values.items())))
