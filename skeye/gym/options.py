"""Checks for the environments' keywords and reset options, each naming the option it checks.

How this works: every ``gymnasium.make`` keyword and ``reset(options=...)`` value passes through
one of these before it is used, so a value of the wrong type or out of its range is a
:class:`~skeye.errors.ConfigError` naming the option, never a ``TypeError`` or ``ValueError``
from deeper down (docs/gym.md, "Options").
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from skeye.errors import ConfigError


def is_number(value: Any) -> bool:
    """A real number (int or float, numpy's included), not a bool."""
    if isinstance(value, bool | np.bool_):
        return False
    return isinstance(value, int | float | np.integer | np.floating)


def number(name: str, value: Any) -> float:
    """``value`` as a finite float, or a ConfigError naming ``name``."""
    if not is_number(value) or not math.isfinite(float(value)):
        raise ConfigError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def numbers(name: str, value: Any, count: int, what: str) -> tuple[float, ...]:
    """``value`` as ``count`` finite floats (``what`` says what they are), or a ConfigError
    naming ``name``."""
    if isinstance(value, str | bytes) or not hasattr(value, "__iter__"):
        raise ConfigError(f"{name} must be {what}, got {value!r}")
    items = list(value)
    if len(items) != count or not all(is_number(v) and math.isfinite(float(v)) for v in items):
        raise ConfigError(f"{name} must be {what}, got {value!r}")
    return tuple(float(v) for v in items)


def text(name: str, value: Any) -> str:
    """``value`` as a string, or a ConfigError naming ``name``."""
    if not isinstance(value, str):
        raise ConfigError(f"{name} must be a string, got {value!r}")
    return value
