"""The pad hold / landing law on scripted observations (no simulator needed)."""

from __future__ import annotations

import math

import pytest

from skeye.errors import LocalProtocolError
from skeye.pilot.pad_hold import PadHoldLaw, PadHoldParams


def test_inside_the_deadband_commands_nothing():
    law = PadHoldLaw()
    sp = law.update(0.0, True, 0.03, -0.02, 1.0)
    assert (sp.forward_m_s, sp.right_m_s, sp.up_m_s) == (0.0, 0.0, 0.0)


def test_outside_the_deadband_flies_towards_the_pad_within_the_speed_limit():
    law = PadHoldLaw(PadHoldParams(max_speed_m_s=0.3))
    sp = law.update(0.0, True, 0.10, 0.0, 1.0)
    assert sp.forward_m_s > 0 and sp.right_m_s == 0
    far = law.update(0.033, True, -2.0, 2.0, 1.0)
    assert math.hypot(far.forward_m_s, far.right_m_s) == pytest.approx(0.3)
    assert far.forward_m_s < 0 < far.right_m_s


def test_integral_compensates_a_steady_offset_and_is_bounded():
    law = PadHoldLaw()
    first = law.update(0.0, True, 0.0, 0.08, 1.0).right_m_s
    for i in range(1, 300):
        sp = law.update(i / 30, True, 0.0, 0.08, 1.0)
    assert sp.right_m_s > first
    p = PadHoldParams()
    assert sp.right_m_s <= p.kp * 0.08 + p.integral_limit_m_s + 1e-9


def test_landing_descends_within_the_cone_and_commits_low_when_centred():
    law = PadHoldLaw()
    # 1.5 m up, the cone is 0.2 x (1.5 - 0.5) = 0.2 m wide: approach first
    assert law.update(0.0, True, 0.25, 0.0, 1.5, landing=True).up_m_s == 0.0
    approach = law.update(0.05, True, 0.15, 0.0, 1.5, landing=True)
    assert approach.up_m_s == -0.25 and approach.forward_m_s > 0  # descends while approaching
    assert law.update(0.1, True, 0.01, 0.0, 1.5, landing=True).up_m_s == -0.25
    high = law.update(0.15, True, 0.5, 0.0, 4.5, landing=True)  # cone 0.8 m at 4.5 m
    assert high.up_m_s == -0.5
    assert law.update(0.2, True, 0.01, 0.0, 0.6, landing=True).up_m_s == -0.12
    assert law.update(0.22, True, 0.09, 0.0, 0.6, landing=True).up_m_s == 0.0  # not centred
    assert not law.update(0.25, True, 0.01, 0.0, 0.6, landing=True).touchdown
    final = law.update(0.3, True, 0.01, 0.0, 0.3, landing=True)
    assert final.touchdown and final.up_m_s < 0


def test_losing_the_pad_holds_then_searches_upwards_to_a_ceiling():
    law = PadHoldLaw(PadHoldParams(lost_after_s=0.5, search_ceiling_m=2.0))
    law.update(0.0, True, 0.0, 0.0, 1.0)
    brief = law.update(0.2, False)
    assert not brief.searching and brief.up_m_s == 0.0
    lost = law.update(0.6, False)
    assert lost.searching and lost.up_m_s == pytest.approx(0.1)
    assert (lost.forward_m_s, lost.right_m_s) == (0.0, 0.0)
    law.update(0.7, True, 0.0, 0.0, 2.1)
    assert law.update(1.5, False).up_m_s == 0.0  # at the ceiling: stop climbing


def test_the_search_climbs_faster_higher_up_and_stops_at_the_ceiling_unseen():
    """Never seen: the vehicle's own height sets the climb (10 % of it per second, 0.1-0.5 m/s)
    and the ceiling."""
    law = PadHoldLaw(PadHoldParams(search_ceiling_m=6.0))
    assert law.update(0.0, False, altitude_m=0.8).up_m_s == pytest.approx(0.1)
    assert law.update(0.1, False, altitude_m=3.0).up_m_s == pytest.approx(0.3)
    assert law.update(0.2, False, altitude_m=5.5).up_m_s == pytest.approx(0.5)
    at_top = law.update(0.3, False, altitude_m=6.0)
    assert at_top.searching and at_top.up_m_s == 0.0
    # no height at all (never seen, no estimate given): no ceiling to stop at, so no climb
    blind = PadHoldLaw().update(0.0, False)
    assert blind.searching and blind.up_m_s == 0.0


def test_bad_parameters_are_refused():
    with pytest.raises(LocalProtocolError, match="max_speed"):
        PadHoldParams(max_speed_m_s=0.0)
    with pytest.raises(LocalProtocolError, match="kp"):
        PadHoldParams(kp=float("nan"))


def test_the_integral_does_not_wind_up_while_the_speed_is_at_its_limit():
    law = PadHoldLaw(PadHoldParams(max_speed_m_s=0.3))
    for i in range(400):  # 20 s approaching from 3 m at the speed limit
        law.update(i * 0.05, True, 3.0, 0.0, 1.5)
    # Just past the pad: the command turns back at once (no integral left pushing on).
    assert law.update(20.0, True, -0.1, 0.0, 1.5).forward_m_s < 0


def test_a_clock_that_goes_back_counts_no_time_across_the_step():
    # A pad last seen at 500 s, then a clock that starts again (a restarted simulator under a
    # re-attached pilot): the law searches once the pad has been unseen for lost_after_s of
    # the new clock, not only once the new clock passes 500 s.
    law = PadHoldLaw(PadHoldParams(lost_after_s=0.5))
    law.update(500.0, True, 0.3, 0.0, 2.0)
    brief = law.update(0.0, False, altitude_m=2.0)
    assert not brief.searching and brief.up_m_s == 0.0  # a missed frame: keep still
    sp = law.update(0.6, False, altitude_m=2.0)
    assert sp.searching and sp.up_m_s > 0
    # A snapshot a little older than the last keeps what the law has learnt: the integral
    # still pushes as it did.
    law = PadHoldLaw()
    for i in range(60):
        steady = law.update(i / 20, True, 0.0, 0.08, 1.0)
    again = law.update(59 / 20 - 0.01, True, 0.0, 0.08, 1.0)
    assert again.right_m_s == pytest.approx(steady.right_m_s)


def test_a_time_that_is_not_finite_is_refused():
    law = PadHoldLaw()
    law.update(1.0, True, 0.3, 0.0, 2.0)
    for bad in (math.nan, math.inf):
        with pytest.raises(LocalProtocolError, match="time must be finite"):
            law.update(bad, True, 0.3, 0.0, 2.0)
    assert law.update(2.0, False, altitude_m=2.0).searching  # the law's clock is intact
