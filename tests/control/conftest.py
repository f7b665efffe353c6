"""Fixtures: a real lockstep simulator in-process (optionally with cameras and images)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest

from skeye.sim.engine import Simulation
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.world import load_world


@dataclass
class SimHandle:
    """A running simulator: its runner, control server and (maybe) image-server address."""

    runner: SimulationRunner
    server: ControlServer
    images: str | None = None

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.server.port}"


@contextmanager
def sim_running(
    *,
    mode: str = "lockstep",
    world: str = "pad",
    seed: int = 1,
    images: bool = False,
    robot_dirs: tuple[Path, ...] = (),
    estimator: str | None = None,
) -> Iterator[SimHandle]:
    """A simulator on loopback port 0, like ``skeye sim`` (cli.cmd_sim) builds it."""
    sim = Simulation(load_world(world), seed=seed, robot_dirs=robot_dirs, estimator=estimator)
    with SimulationRunner(sim, mode=mode) as runner:
        cameras = None
        if images:
            from skeye.sim.cameras import CameraSystem
            from skeye.sim.image_server import FrameBuffer, ImageServer

            cameras = CameraSystem(sim, FrameBuffer(), synchronous=mode == "lockstep")
        try:
            with ControlServer(runner, port=0) as server:
                if cameras is None:
                    yield SimHandle(runner, server)
                else:
                    with ImageServer(cameras.buffer, port=0) as image_server:
                        yield SimHandle(runner, server, f"127.0.0.1:{image_server.port}")
        finally:
            if cameras is not None:
                cameras.close()


@pytest.fixture
def lockstep_sim() -> Iterator[SimHandle]:
    with sim_running() as handle:
        yield handle


@pytest.fixture
def truth_sim() -> Iterator[SimHandle]:
    """Lockstep, boards on the oracle estimator (``--estimator truth``): for checks of the
    navigation logic at centimetre precision."""
    with sim_running(estimator="truth") as handle:
        yield handle
