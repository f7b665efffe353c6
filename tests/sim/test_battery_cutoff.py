"""The battery's cutoff voltage (``[battery] cutoff_cell_v``): the charge below it is not used.
It was validated and then read by nothing, so any cutoff flew as 3.3 V (a probe of 2026-11-27).
"""

from __future__ import annotations

import pytest

from skeye.robots.params import BatteryParams
from skeye.sim.vehicle import Battery, cell_open_circuit_v, cutoff_state_of_charge

HOVER_SHAFT_W = 47.1  # the Hummingbird's (docs/physics.md)


def _flown_until_empty(params: BatteryParams) -> tuple[Battery, float]:
    """Hover power drawn in 1 s steps until the battery is empty; (it, seconds flown)."""
    battery = Battery(params, HOVER_SHAFT_W)
    flown = 0.0
    while not battery.empty:
        battery.draw(HOVER_SHAFT_W, 1.0)
        flown += 1.0
        assert flown < 10_000, "never empty"
    return battery, flown


def test_the_default_cutoff_uses_the_whole_charge() -> None:
    battery, _ = _flown_until_empty(BatteryParams())
    assert battery.state_of_charge == 0.0 and battery.remaining_s == 0.0


def test_a_higher_cutoff_stops_the_motors_where_the_cell_rests_at_it() -> None:
    assert cutoff_state_of_charge(3.8) == pytest.approx(0.40)
    assert cell_open_circuit_v(cutoff_state_of_charge(3.7)) == pytest.approx(3.7)
    _, full_s = _flown_until_empty(BatteryParams())
    spared, spared_s = _flown_until_empty(BatteryParams(cutoff_cell_v=3.8))
    # Empty within one 1 s draw of 40 % charge left (a draw at hover takes about 0.1 %).
    assert 0.40 - 0.002 <= spared.state_of_charge <= 0.40
    assert spared.remaining_s == 0.0
    # About 60 % of the default's endurance (the current rises a little as the voltage falls).
    assert 0.55 * full_s < spared_s < 0.65 * full_s
    # The life figure counted down to the cutoff from the start: a fresh battery says so.
    assert Battery(BatteryParams(cutoff_cell_v=3.8), HOVER_SHAFT_W).remaining_s == \
        pytest.approx(0.6 * Battery(BatteryParams(), HOVER_SHAFT_W).remaining_s, rel=1e-9)
