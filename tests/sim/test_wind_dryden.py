"""The dryden wind mode: MIL-F-8785C's low-altitude figures and the gusts' statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skeye.errors import ConfigError
from skeye.sim.wind import FT, WindModel, dryden_profile
from skeye.wire.wind import make_settings


def test_the_specifications_low_altitude_figures() -> None:
    mean, sig_u, sig_w, l_u, l_w = dryden_profile(2.6, 1.0)  # below 10 ft: the 10 ft values
    k = 0.177 + 0.000823 * 10.0
    assert sig_w == pytest.approx(0.26)
    assert sig_u == pytest.approx(0.26 / k ** 0.4)
    assert l_w == pytest.approx(10 * FT) and l_u == pytest.approx(10 / k ** 1.2 * FT)
    assert mean == pytest.approx(2.6 * math.log(10 / 0.15) / math.log(20 / 0.15))
    # at 20 ft the mean wind is W20 itself
    assert dryden_profile(2.6, 20 * FT)[0] == pytest.approx(2.6)
    assert dryden_profile(2.6, 1.0) == dryden_profile(2.6, 2.0)  # both below 10 ft


def test_gusts_have_the_specified_spread_around_the_mean_wind() -> None:
    settings = make_settings("dryden", {"w20_m_s": 5.0, "from_deg": 0.0})
    mean, sig_u, sig_w, l_u, _ = dryden_profile(5.0, 1.0)
    model = WindModel(settings, np.random.default_rng(4))
    dt = 0.004
    samples = []
    for k in range(int(2000 / dt)):
        model.advance(k * dt, dt)
        if k % 25 == 0:
            samples.append(model.air_velocity_ned())
    air = np.array(samples)
    # from the north: the air moves south; along it u, across it v (east), w vertical
    n_corr = 2000 / (l_u / mean)  # roughly independent stretches of the longitudinal gust
    tol = 4 / math.sqrt(2 * n_corr)
    assert air[:, 0].mean() == pytest.approx(-mean, abs=4 * sig_u / math.sqrt(n_corr))
    assert air[:, 0].std() == pytest.approx(sig_u, rel=tol)
    assert air[:, 1].std() == pytest.approx(sig_u, rel=tol)
    assert air[:, 2].std() == pytest.approx(sig_w, rel=0.15)
    # the same seed, the same air
    again = WindModel(settings, np.random.default_rng(4))
    for k in range(10):
        again.advance(k * dt, dt)
    first = WindModel(settings, np.random.default_rng(4))
    for k in range(10):
        first.advance(k * dt, dt)
    assert again.air_velocity_ned() == first.air_velocity_ned()


def test_bad_parameters_are_named() -> None:
    with pytest.raises(ConfigError, match="w20_m_s"):
        make_settings("dryden", {"w20_m_s": -1.0})
    with pytest.raises(ConfigError, match="height_m"):
        make_settings("dryden", {"height_m": 1000.0})
    with pytest.raises(ConfigError, match="sigma_m_s"):
        make_settings("dryden", {"sigma_m_s": 1.0})
