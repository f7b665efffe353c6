"""The control server at run time, over real loopback sockets: a busy engine, clients that stop
reading. Waits are on events and answers with deadlines, never on how fast a machine runs."""

from __future__ import annotations

import threading

from skeye.sim.engine import Simulation
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.world import load_world
from tests.sim.conftest import LineClient


def test_a_command_the_busy_engine_never_took_up_is_refused_and_never_done() -> None:
    """In lockstep another client's long STEP holds the engine; a command queued behind it past
    the command timeout is answered ``ERR ... not done``, and is not done later either. An INIT
    so refused used to spawn its robot anyway when the engine got to it (RES INIT after the ERR):
    the connection was not bound, DRIVE was refused, and a second INIT spawned a second robot
    while the first stayed in the world for good."""
    sim = Simulation(load_world("pad"), seed=1)
    gate = threading.Event()
    with (
        SimulationRunner(sim, mode="lockstep") as runner,
        ControlServer(runner, port=0, command_timeout_s=0.5) as server,
    ):
        # The engine busy, as with another client's STEP {Count 10000000}.
        busy = runner.submit(lambda sim: gate.wait(60))
        client = LineClient(server.port)
        try:
            client.expect("NFO")
            try:
                err = client.answer("INIT {ClassName hummingbird} {Name B} {Start Pad1}", "INIT")
            finally:
                gate.set()
            assert err.type == "ERR", err
            assert "not done" in err.require("Reason"), err
            busy.result(10)
            seen = client.step(1)  # queued after the refused INIT: the engine is past it
            assert not [m for m in seen if m.type == "RES"], seen
            assert runner.call(lambda sim: sorted(sim.robots)) == []
            # The connection is as it was: a new INIT binds it, DRIVE works.
            assert client.answer("INIT {ClassName hummingbird} {Name B} {Start Pad1}",
                                 "INIT").type == "RES"
            client.send("DRIVE {AltitudeVelocity 0.5}")
            seen = client.step(10)
            assert not [m for m in seen if m.type == "ERR"], seen
            assert runner.call(lambda sim: sorted(sim.robots)) == ["B"]
        finally:
            gate.set()
            client.close()
