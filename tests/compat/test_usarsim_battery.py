"""Issue 19, point 4: ``STA {Battery n}`` is whole seconds and sensible from the first line.

USARSim (``USARVehicle.GetStatus``, ``Battery.ExpectedLifeTime``) writes the expected life as an
int: the energy left over an average discharge rate that starts at the rated rate, so the
first figure is already the battery's life. A client that shows "minutes left" must get a
figure that counts down about one second per second at a steady draw, from the first line.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Iterator

import pytest

from tests.compat.usarsim_client import UsarClient, blocks, unreal_float
from tests.control.conftest import sim_running


def _battery(lines: list[str]) -> list[tuple[float, int]]:
    out = []
    for line in lines:
        if line.startswith("STA "):
            b = blocks(line)
            assert b[1][0] == "Battery" and re.fullmatch(r"\d+", b[1][1]), line
            out.append((unreal_float(b[0][1]), int(b[1][1])))
    return out


@pytest.fixture
def steady_client() -> Iterator[UsarClient]:
    """A lockstep simulator whose boards fly on the oracle estimator: a hover without the
    onboard estimate's centimetre corrections, so the draw is steady (on the onboard estimator
    the same hover's figure swings by a few seconds, 0.3 %, as the corrections come and go)."""
    with sim_running(estimator="truth") as handle:
        c = UsarClient(handle.server.port)
        yield c
        c.close()


@pytest.mark.parametrize("robot", ["hummingbird", "airrobot"])
def test_battery_counts_down_from_the_first_status(steady_client: UsarClient, robot: str
                                                   ) -> None:
    client = steady_client
    client.send(f"INIT {{ClassName {robot}}} {{Location 0,0,-2}}")  # spawned hovering
    assert client.read_line().startswith("RES {Command INIT}")
    series = _battery(client.step(7000))
    assert len(series) >= 60
    (t0, first), (t1, last) = series[0], series[-1]
    # A small quadrotor hovers 10 to 60 minutes on a full pack, and says so from the start.
    assert 600 <= first <= 3600, series[:5]
    # At a steady hover it counts down like a clock (the filter does not wander).
    assert first - last == pytest.approx(t1 - t0, abs=3.0), (series[0], series[-1])
    assert all(b <= a + 1 for (_, a), (_, b) in itertools.pairwise(series))


def test_battery_on_the_ground_is_the_flight_time_left(client: UsarClient) -> None:
    """Disarmed on the pad the draw is the avionics only; the figure is still the time left
    to fly (hover), not hours of standing."""
    client.send("INIT {ClassName hummingbird} {Start Pad1}")
    assert client.read_line().startswith("RES {Command INIT}")
    series = _battery(client.step(3000))
    assert series and all(600 <= b <= 3600 for _, b in series), series[:3]
