"""``STEP {Sync true}``: several connections, one robot each, drive a lockstep simulator's clock
together (skeye.sim.clock_barrier). With plain STEPs their steps added up: two pilots ran sim
time at twice their pace, each robot's control ticking every other period of its own."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from skeye.sim.server import ControlServer
from tests.robustness.helpers import wait_for
from tests.sim.conftest import LineClient, running_sim


def _time(msg) -> float:
    assert msg.type == "RES", msg
    return float(msg.get("Time"))


def _flyer(port: int, name: str, north_m: float) -> LineClient:
    client = LineClient(port)
    client.expect("NFO")
    answer = client.answer(f"INIT {{ClassName hummingbird}} {{Name {name}}} "
                           f"{{Location {north_m},0,-0.5}}", "INIT")
    assert answer.type == "RES", answer
    return client


@contextmanager
def _b_waiting_for_a(**sim_options) -> Iterator[tuple[ControlServer, LineClient, LineClient]]:
    """A simulator with two members: A has stepped alone to 0.010, B has sent its first Sync
    STEP (10 steps), which waits for A's next."""
    with running_sim(**sim_options) as server:
        a, b = _flyer(server.port, "A", 0.0), _flyer(server.port, "B", 3.0)
        try:
            a.send("STEP {Count 10} {Sync true}")  # alone in the barrier: steps at once
            assert _time(_res(a)) == pytest.approx(0.010)
            b.send("STEP {Count 10} {Sync true}")  # joins; waits for A to ask
            yield server, a, b
        finally:
            a.close()
            b.close()


def _res(client: LineClient):
    return client.read_until(lambda m: m.type in ("RES", "ERR")
                             and m.get("Command") == "STEP", timeout_s=120)[1]


def test_two_clients_in_sync_step_the_world_once_to_each_ones_boundary() -> None:
    with _b_waiting_for_a() as (server, a, b):
        barrier = server.clock_barrier
        watcher = LineClient(server.port)
        watcher.expect("NFO")
        try:
            assert wait_for(lambda: barrier.members == 2 and barrier.waiting == 1, 60)
            a.send("STEP {Count 30} {Sync true}")  # the world goes to B's boundary, not A's
            assert _time(_res(b)) == pytest.approx(0.020)
            b.send("STEP {Count 10} {Sync true}")
            assert _time(_res(b)) == pytest.approx(0.030)
            b.send("STEP {Count 10} {Sync true}")  # both boundaries at 0.040
            assert _time(_res(b)) == pytest.approx(0.040)
            assert _time(_res(a)) == pytest.approx(0.040)  # 30 steps of A, not 30 + B's 30

            # Another connection's plain STEP passes B's boundary: B is answered then.
            b.send("STEP {Count 10} {Sync true}")
            assert wait_for(lambda: barrier.waiting == 1, 60)
            watcher.send("STEP {Count 20}")
            assert _time(_res(watcher)) == pytest.approx(0.060)
            assert _time(_res(b)) == pytest.approx(0.060)

            # A member gone: the others step on without it.
            a.send("STEP {Count 100} {Sync true}")  # waits for B, then B goes away
            assert wait_for(lambda: barrier.waiting == 1, 60)
            b.close()
            assert _time(_res(a)) == pytest.approx(0.160)
            assert wait_for(lambda: barrier.members == 1, 60)
        finally:
            watcher.close()


def test_sync_needs_a_robot_and_a_lone_member_steps_as_a_plain_step() -> None:
    with running_sim() as server:
        watcher = LineClient(server.port)
        watcher.expect("NFO")
        a = _flyer(server.port, "A", 0.0)
        try:
            watcher.send("STEP {Count 10} {Sync true}")
            refused = _res(watcher)
            assert refused.type == "ERR" and "needs a robot" in refused.get("Reason"), refused
            a.send("STEP {Count 123} {Sync true}")
            assert _time(_res(a)) == pytest.approx(0.123)
            assert server.clock_barrier.members == 1
        finally:
            a.close()
            watcher.close()


def test_an_engine_failure_ends_a_waiting_members_step_with_an_error() -> None:
    """The engine dies in one member's steps while another waits: the waiting STEP is answered
    with the failure, not left for the hour a STEP may wait."""
    with _b_waiting_for_a() as (server, a, b):
        assert wait_for(lambda: server.clock_barrier.waiting == 1, 60)

        def fault(sim) -> None:
            raise RuntimeError("injected engine fault")

        server.runner.sim.step_hooks.append(fault)
        a.send("STEP {Count 10} {Sync true}")
        said = b.read_until(lambda m: m.type == "ERR", timeout_s=60)[1]
        assert "injected engine fault" in said.get("Reason"), said
        # both sessions end (the server ends them all): B's reader is not left waiting
        assert wait_for(lambda: server.client_count == 0, 60), server.client_count


def test_a_step_the_others_never_let_through_is_withdrawn(monkeypatch) -> None:
    """Past the server's STEP limit (an hour; here a second) the waiting STEP is refused and
    withdrawn: the world no longer stops at its boundary."""
    import skeye.sim.session

    monkeypatch.setattr(skeye.sim.session, "STEP_TIMEOUT_S", 1.0)
    with _b_waiting_for_a() as (server, a, b):  # A never asks again in time
        barrier = server.clock_barrier
        refused = _res(b)
        assert refused.type == "ERR" and "withdrawn, not done" in refused.get("Reason"), refused
        assert wait_for(lambda: barrier.waiting == 0, 60)
        a.send("STEP {Count 100} {Sync true}")  # B is a member not waiting: A waits for it
        assert wait_for(lambda: barrier.waiting == 1, 60)
        b.send("STEP {Count 200} {Sync true}")
        assert _time(_res(a)) == pytest.approx(0.110)  # not stopped at B's withdrawn 0.020
