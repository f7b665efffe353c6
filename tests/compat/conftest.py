"""Fixtures: a real simulator (engine + control server) on a loopback port, lockstep mode."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from skeye.sim.engine import Simulation
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.world import load_world
from tests.compat.usarsim_client import UsarClient


@pytest.fixture(params=["pad"])
def server(request: pytest.FixtureRequest) -> Iterator[ControlServer]:
    sim = Simulation(load_world(request.param), seed=1)
    with SimulationRunner(sim, mode="lockstep") as runner, ControlServer(runner, port=0) as srv:
        yield srv


@pytest.fixture
def client(server: ControlServer) -> Iterator[UsarClient]:
    c = UsarClient(server.port)
    yield c
    c.close()
