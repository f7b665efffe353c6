"""Checks for plain values read from outside: numbers, finite numbers, vectors and strings.

How this works: one set of predicates and checkers shared by every package that reads settings
from a file, a header, a keyword or a spec (world files, recordings, run settings, the
Gymnasium options), so they agree on what a number is. A number is a real number (``int``,
``float`` or another :class:`numbers.Real`, numpy's scalars included) that is not a bool; the
checkers raise :class:`~skeye.errors.ConfigError` naming the value. This module imports only the
standard library and :mod:`skeye.errors`, so any package may use it.
"""

from __future__ import annotations

import math
import numbers as _numbers
from typing import Any

from skeye.errors import ConfigError


def is_number(value: Any) -> bool:
    """A real number (int or float, numpy's included), not a bool."""
    return isinstance(value, _numbers.Real) and not isinstance(value, bool)


def is_finite_number(value: Any) -> bool:
    """A real number (as :func:`is_number`) that is neither infinite nor NaN, and that a float
    holds (an int beyond float's range, 10**400, is not: ``float()`` of it overflows)."""
    if not is_number(value):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def number(name: str, value: Any) -> float:
    """``value`` as a finite float, or a ConfigError naming ``name``."""
    if not is_finite_number(value):
        raise ConfigError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def numbers(name: str, value: Any, count: int, what: str) -> tuple[float, ...]:
    """``value`` as ``count`` finite floats (``what`` says what they are), or a ConfigError
    naming ``name``."""
    if isinstance(value, str | bytes) or not hasattr(value, "__iter__"):
        raise ConfigError(f"{name} must be {what}, got {value!r}")
    items = list(value)
    if len(items) != count or not all(is_finite_number(v) for v in items):
        raise ConfigError(f"{name} must be {what}, got {value!r}")
    return tuple(float(v) for v in items)


MAX_BAUD = 4_000_000
"""The fastest serial line a baud option takes (the fastest FTDI and CP210x USB adapters')."""


def baud_rate(text: str) -> int | None:
    """A serial line's baud rate as written in a URI or spec: a whole number 1..MAX_BAUD in
    ASCII digits, else None (each caller names its option). ``str.isdigit`` alone also takes
    digits ``int()`` refuses (a superscript 2), and ``int()`` alone takes a sign and spaces."""
    if not (text.isascii() and text.isdigit()):
        return None
    value = int(text)
    return value if 1 <= value <= MAX_BAUD else None


def text(name: str, value: Any) -> str:
    """``value`` as a string, or a ConfigError naming ``name``."""
    if not isinstance(value, str):
        raise ConfigError(f"{name} must be a string, got {value!r}")
    return value
