"""Wind and disturbances acting on the vehicles.

How this works: a wind model gives, at each board tick, the air velocity (NED, m/s) that drag
acts against and an extra force on the centre of mass (NED, N). Modes:

- ``none``: still air.
- ``constant``: a steady wind ``speed_m_s`` from a direction (``from_deg``, meteorological:
  the direction the wind comes from, clockwise from north).
- ``turbulence``: the constant wind plus Dryden-style gusts: each axis is white noise shaped by
  a first-order filter with time constant L/V (length scales L_u = L_v = 30 m, L_w = 10 m, the
  low-altitude values of MIL-F-8785C at ~10 m, V = max(mean speed, 1 m/s)), with standard
  deviations ``sigma_m_s`` horizontally and half that vertically. Seeded.
- ``random_force``: the paper's disturbance (docs/experiments.md): a horizontal force on the centre
  of mass whose direction is uniform in the plane and magnitude uniform in [0, f_max_n],
  redrawn every ``tick_s`` (default 1/30 s). Seeded.

Parameters come from ``SET {Type Wind} {Mode m} {Params k=v,k=v}`` or the command line; bad keys
or values raise ConfigError naming them. Every parameter has a physical range
(:data:`PARAM_RANGES`), checked before a setting is accepted: a value outside it (a 1e-320 s
redraw period, a 1e6 m/s wind) would overflow the model or blow every vehicle out of the world.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

import numpy as np

from skeye.errors import ConfigError

WIND_MODES = ("none", "constant", "turbulence", "random_force")

_DEFAULTS: Final[dict[str, dict[str, float]]] = {
    "none": {},
    "constant": {"speed_m_s": 2.0, "from_deg": 270.0},
    "turbulence": {"speed_m_s": 2.0, "from_deg": 270.0, "sigma_m_s": 1.0},
    "random_force": {"f_max_n": 0.3, "tick_s": 1.0 / 30.0},
}

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
    """``"speed_m_s=3,from_deg=90"`` -> dict. A lone number sets the mode's first parameter."""
    text = text.strip()
    if not text:
        return {}
    out: dict[str, float] = {}
    for part in text.split(","):
        if "=" not in part:
            try:
                out["_"] = float(part)
            except ValueError:
                raise ConfigError(f"wind params: expected key=value, got {part!r}") from None
            continue
        key, _, value = part.partition("=")
        try:
            out[key.strip()] = float(value)
        except ValueError:
            raise ConfigError(f"wind params: {key.strip()} is not a number: {value!r}") from None
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
        values[next(iter(values))] = given.pop("_")
    for key, value in given.items():
        if key not in values:
            raise ConfigError(
                f"wind: unknown parameter {key!r} for mode {mode!r}; "
                f"known: {sorted(values) or 'none'}"
            )
        values[key] = value
    for key, value in values.items():
        low, high = PARAM_RANGES[key]
        if not (math.isfinite(value) and low <= value <= high):
            raise ConfigError(f"wind: {key} must be in [{low:g}, {high:g}], got {value!r}")
    return WindSettings(mode, tuple(sorted(values.items())))


class WindModel:
    """Air velocity and disturbance force over time, for one world (shared by all vehicles)."""

    def __init__(self, settings: WindSettings, rng: np.random.Generator) -> None:
        self.settings = settings
        self.rng = rng
        self._gust = [0.0, 0.0, 0.0]
        self._force = (0.0, 0.0, 0.0)
        self._next_draw_s = 0.0
        s = dict(settings.params)
        speed = s.get("speed_m_s", 0.0)
        frm = math.radians(s.get("from_deg", 0.0))
        # Wind blowing *from* frm moves air towards frm + pi.
        self._mean = (-speed * math.cos(frm), -speed * math.sin(frm), 0.0)

    def advance(self, time_s: float, dt_s: float) -> None:
        """Advance the random processes to ``time_s`` (called once per board tick)."""
        mode = self.settings.mode
        if mode == "turbulence":
            s = dict(self.settings.params)
            sigma = s["sigma_m_s"]
            v = max(1.0, math.hypot(self._mean[0], self._mean[1]))
            for axis, (length, sig) in enumerate(((30.0, sigma), (30.0, sigma), (10.0, sigma / 2))):
                a = math.exp(-dt_s * v / length)
                self._gust[axis] = a * self._gust[axis] + sig * math.sqrt(1 - a * a) * float(
                    self.rng.standard_normal()
                )
        elif mode == "random_force" and time_s + 1e-12 >= self._next_draw_s:
            s = dict(self.settings.params)
            direction = float(self.rng.uniform(0.0, 2.0 * math.pi))
            magnitude = float(self.rng.uniform(0.0, s["f_max_n"]))
            self._force = (magnitude * math.cos(direction), magnitude * math.sin(direction), 0.0)
            tick = s["tick_s"]
            self._next_draw_s = (math.floor(time_s / tick + 1e-9) + 1) * tick

    def air_velocity_ned(self) -> tuple[float, float, float]:
        m, g = self._mean, self._gust
        return m[0] + g[0], m[1] + g[1], m[2] + g[2]

    def force_ned(self) -> tuple[float, float, float]:
        return self._force
