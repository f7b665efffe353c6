"""Fixtures: a real simulator (engine + control server) on a loopback port, and a line client."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from skeye.sim.engine import Simulation
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.world import load_world
from skeye.wire.sim_lines import LineDecoder, LineError, Message


class LineClient:
    """A minimal test client: raw protocol lines in, decoded messages out."""

    def __init__(self, port: int, timeout_s: float = 10.0) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout_s)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.decoder = LineDecoder()
        self.pending: list[Message] = []
        self.raw = bytearray()
        self.timeout_s = timeout_s

    def send(self, line: str) -> None:
        self.sock.sendall(line.encode() + b"\r\n")

    def _fill(self, deadline: float) -> bool:
        self.sock.settimeout(max(0.01, deadline - time.monotonic()))
        try:
            data = self.sock.recv(1 << 20)
        except TimeoutError:
            return True
        if not data:
            return False
        self.raw.extend(data)
        for event in self.decoder.feed(data):
            assert not isinstance(event, LineError), event
            self.pending.append(event)
        return True

    def read_until(
        self, predicate: Callable[[Message], bool], timeout_s: float | None = None
    ) -> tuple[list[Message], Message]:
        """Read messages until one satisfies ``predicate``; returns (all before it, it)."""
        deadline = time.monotonic() + (timeout_s or self.timeout_s)
        seen: list[Message] = []
        while True:
            while self.pending:
                msg = self.pending.pop(0)
                if predicate(msg):
                    return seen, msg
                seen.append(msg)
            if time.monotonic() > deadline:
                raise TimeoutError(f"no matching message; last seen: {seen[-3:]}")
            if not self._fill(deadline):
                raise ConnectionError("server closed the connection")

    def expect(self, type_: str, timeout_s: float | None = None) -> Message:
        return self.read_until(lambda m: m.type == type_, timeout_s)[1]

    def answer(self, line: str, command: str) -> Message:
        """Send a command and return its RES or ERR."""
        self.send(line)
        return self.read_until(
            lambda m: m.type in ("RES", "ERR") and (m.get("Command") or "").upper() == command
        )[1]

    def step(self, count: int) -> list[Message]:
        """Lockstep: advance and return every message those steps produced."""
        self.send(f"STEP {{Count {count}}}")
        seen, _ = self.read_until(
            lambda m: m.type == "RES" and m.get("Command") == "STEP", timeout_s=600
        )
        return seen

    def close(self) -> None:
        self.sock.close()


@contextmanager
def running_sim(
    world: str = "pad",
    mode: str = "lockstep",
    seed: int = 1,
    robot_dirs: tuple[Path, ...] = (),
    **kwargs: object,
) -> Iterator[ControlServer]:
    port = int(kwargs.pop("port", 0))  # type: ignore[call-overload]
    sim = Simulation(load_world(world), seed=seed, robot_dirs=robot_dirs, **kwargs)  # type: ignore[arg-type]
    with SimulationRunner(sim, mode=mode) as runner, ControlServer(runner, port=port) as server:
        yield server


@pytest.fixture
def lockstep_server() -> Iterator[ControlServer]:
    with running_sim() as server:
        yield server


@pytest.fixture
def truth_server() -> Iterator[ControlServer]:
    """A lockstep simulator whose boards fly on the oracle estimator (``--estimator truth``):
    for tests of the controller's own response, not of the estimate it flies on."""
    with running_sim(estimator="truth") as server:
        yield server


@pytest.fixture
def client_factory() -> Iterator[Callable[[ControlServer], LineClient]]:
    clients: list[LineClient] = []

    def make(server: ControlServer) -> LineClient:
        c = LineClient(server.port)
        c.expect("NFO")
        clients.append(c)
        return c

    yield make
    for c in clients:
        c.close()


def sensor_series(messages: list[Message], type_name: str, key: str) -> list[tuple[float, str]]:
    """(time, raw value) of every SEN of a type in a message list."""
    return [
        (float(m.require("Time")), m.require(key))
        for m in messages
        if m.type == "SEN" and (m.get("Type") or "").lower() == type_name.lower()
    ]


def vec(text: str) -> tuple[float, ...]:
    return tuple(float(v) for v in text.split(","))
