"""The shared value checks (skeye.values): what counts as a number, and their messages."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skeye.errors import ConfigError
from skeye.values import is_finite_number, is_number, number, numbers, text


@pytest.mark.parametrize("value", [0, -3, 2.5, np.int64(4), np.float32(1.5), math.inf])
def test_real_numbers_are_numbers(value: object) -> None:
    assert is_number(value)


@pytest.mark.parametrize("value", [True, np.bool_(False), "1", None, [1.0], 1j])
def test_bools_strings_and_others_are_not(value: object) -> None:
    assert not is_number(value)


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan, np.float64("nan"), True,
                                   pytest.param(10**400, id="10**400"),
                                   pytest.param(-(10**400), id="-10**400")])
def test_finite_number_refuses_infinities_nan_bools_and_ints_beyond_floats(value: object) -> None:
    assert not is_finite_number(value)
    with pytest.raises(ConfigError, match=r"^x must be a finite number, got "):
        number("x", value)


def test_checkers_return_floats_and_strings() -> None:
    assert number("x", np.int64(3)) == 3.0 and type(number("x", 3)) is float
    assert numbers("v", (1, 2.5, np.float32(3)), 3, "3 metres") == (1.0, 2.5, 3.0)
    assert text("s", "pad") == "pad"


@pytest.mark.parametrize("value", ["abc", 3.0, (1.0, 2.0), (1.0, math.nan, 2.0)])
def test_numbers_names_what_it_wanted(value: object) -> None:
    with pytest.raises(ConfigError, match=r"^v must be 3 metres, got "):
        numbers("v", value, 3, "3 metres")


def test_text_refuses_non_strings() -> None:
    with pytest.raises(ConfigError, match=r"^s must be a string, got 3$"):
        text("s", 3)
