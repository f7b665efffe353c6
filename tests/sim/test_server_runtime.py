"""The control server at run time, over real loopback sockets: a busy engine, clients that stop
reading. Waits are on events and answers with deadlines, never on how fast a machine runs."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Iterator

import pytest

from skeye.sim import session as session_module
from skeye.sim.engine import FLUSH_EVENTS, Simulation
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.session import CLOSE_LINGER_S, ClientSession
from skeye.sim.world import load_world
from tests.robustness.helpers import wait_for
from tests.sim.conftest import LineClient, running_sim


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


def _writer_of(client: socket.socket) -> list[threading.Thread]:
    host, port = client.getsockname()[:2]
    return [t for t in threading.enumerate() if t.name == f"sim-write-{host}:{port}"]


def test_a_client_that_reads_nothing_is_closed_for_good_when_its_session_ends(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A client without a robot floods commands and never reads its answers, then falls
    silent: the idle timeout ends its session and frees its slot, and within the close linger
    its writer thread ends and its socket is closed. The writer stayed blocked in sendall for
    as long as the client lived (keepalive sees a live peer), with the socket and up to its
    outbox of answers (8 MiB; 300 kB here, so that fewer commands fill it, as in
    tests/robustness/test_faults.py): every such connection outlived its freed slot."""
    monkeypatch.setattr(session_module, "OUTBOX_BYTES", 300_000)
    sim = Simulation(load_world("pad"), seed=1)
    with (
        SimulationRunner(sim, mode="lockstep") as runner,
        ControlServer(runner, port=0, idle_timeout_s=3.0) as server,
    ):
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect(("127.0.0.1", server.port))
        try:
            sock.sendall(b"GETSTARTPOSES\r\n")
            got = b""
            while got.count(b"\n") < 2:  # NFO and the first answer
                got += sock.recv(1 << 16)
            answer_bytes = len(got.split(b"\n")[1]) + 1
            # More answers than the outbox and the kernel's buffers hold: this socket's 4 kB
            # and the server's send buffer, 4 MiB at most (Linux's tcp_wmem maximum).
            lines = (300_000 + 4096 + 4 * 1024 * 1024) * 5 // 4 // answer_bytes
            sock.sendall(b"GETSTARTPOSES\r\n" * lines)
            # A stuck guard, not a speed bound: the commands are answered first (80 000 of
            # them took over 60 s of wall time at a load average near 20, 2026-11-27).
            deadline = time.monotonic() + 240
            while server.client_count:
                assert time.monotonic() < deadline, "the idle session was not ended"
                time.sleep(0.05)
            deadline = time.monotonic() + CLOSE_LINGER_S + 30
            while _writer_of(sock):
                assert time.monotonic() < deadline, "its writer thread is still blocked"
                time.sleep(0.05)
            # The server's end is closed: the client reads what had got out, then the end.
            sock.settimeout(30)
            received = 0
            with contextlib.suppress(ConnectionResetError):
                while data := sock.recv(1 << 20):
                    received += len(data)
            # Answers were dropped: the writer had been held by the client, not done.
            assert received < lines * answer_bytes
        finally:
            sock.close()


def test_a_connection_waiting_on_its_own_long_step_is_not_closed_as_idle() -> None:
    """A lockstep clock driver without a robot sends one STEP that takes longer than the idle
    timeout (the engine busy, as with a STEP {Count 10000000}); it gets its RES STEP and the
    connection stays open: the time the server spent on its command is not the client's
    silence. It was closed right after the RES with 'idle for ... without a robot'."""
    sim = Simulation(load_world("pad"), seed=1)
    gate = threading.Event()
    with (
        SimulationRunner(sim, mode="lockstep") as runner,
        ControlServer(runner, port=0, idle_timeout_s=1.0) as server,
    ):
        client = LineClient(server.port)
        try:
            client.expect("NFO")
            busy = runner.submit(lambda sim: gate.wait(60))
            client.send("STEP {Count 1}")
            assert not gate.wait(2.5)  # the STEP waits behind the busy engine, past 1 s
            gate.set()
            busy.result(10)
            client.read_until(lambda m: m.type == "RES" and m.get("Command") == "STEP")
            answer = client.answer("PING {Id after}", "PING")
            assert answer.type == "RES", answer
        finally:
            gate.set()
            client.close()


def test_a_client_gone_during_its_own_long_step_stops_it_and_the_others_are_served() -> None:
    """A lockstep client sends a STEP of 10 000 s of sim time and closes its connection. The
    engine used to step on to the end for nobody, and every other client's command waited the
    whole of it (then ``ERR ... not done``). Now the STEP stops at the next point between steps
    after the server sees the connection gone, its robot goes, and another client's INIT is
    taken up: the sim time then is a sliver of what was asked."""
    sim = Simulation(load_world("pad"), seed=1)
    count = 10_000_000  # 10 000 s of sim time at 1 ms: hours of wall time
    with (
        SimulationRunner(sim, mode="lockstep") as runner,
        ControlServer(runner, port=0, command_timeout_s=5.0) as server,
    ):
        stepper, other = LineClient(server.port), LineClient(server.port)
        stepper.expect("NFO")
        other.expect("NFO")
        assert stepper.answer("INIT {ClassName hummingbird} {Name R1} {Start Pad1}",
                              "INIT").type == "RES"
        stepper.send(f"STEP {{Count {count}}}")
        # PING is answered without the engine: its time shows the STEP under way.
        deadline = time.monotonic() + 30
        started_s = 0.0
        while started_s <= 0.0:
            assert time.monotonic() < deadline, "the STEP never started"
            started_s = float(other.answer("PING {Id 1}", "PING").require("Time"))
        stepper.close()
        res = other.answer("INIT {ClassName hummingbird} {Name R2} {Location 5,0,-1}", "INIT")
        assert res.type == "RES", res  # taken up within the 5 s command timeout
        stopped_s = float(other.answer("PING {Id 2}", "PING").require("Time"))
        asked_s = count * sim.dt
        assert started_s < stopped_s < asked_s / 100, (started_s, stopped_s)
        assert runner.call(lambda sim: sorted(sim.robots)) == ["R2"]
        other.close()


def test_a_sensor_query_for_a_robot_stopped_meanwhile_says_it_is_gone() -> None:
    """GETCONF for a sensor, read while the connection drives U, reaches the engine after a STEP
    (another client's) that stopped U: the answer says U is gone and to send INIT. It was
    'failed: KeyError: 'U'' with a traceback in the simulator's log."""
    sim = Simulation(load_world("pad"), seed=1)
    gate = threading.Event()
    with (
        SimulationRunner(sim, mode="lockstep") as runner,
        ControlServer(runner, port=0) as server,
    ):
        client = LineClient(server.port)
        try:
            client.expect("NFO")
            client.answer("INIT {ClassName hummingbird} {Name U} {Location 0,0,-3}", "INIT")

            def poison(sim: Simulation) -> None:
                sim.data.qvel[sim._slots["U"].qvel_adr + 3] = float("nan")

            runner.call(poison)
            busy = runner.submit(lambda sim: gate.wait(60))
            stepped = runner.submit(lambda sim: sim.step(50))  # another client's STEP
            client.send("GETCONF {Type Sonar}")
            deadline = time.monotonic() + 30
            while runner._tasks.qsize() < 2:  # the STEP, then the GETCONF's lookup
                assert time.monotonic() < deadline, "the GETCONF never reached the engine"
                time.sleep(0.01)
            gate.set()
            busy.result(10)
            stepped.result(30)
            _, err = client.read_until(
                lambda m: m.type in ("CONF", "ERR") and m.get("Command") != "PHYSICS")
            assert err.type == "ERR" and err.get("Command") == "GETCONF", err
            assert "robot U is gone; send INIT" in err.require("Reason"), err
        finally:
            gate.set()
            client.close()


@pytest.mark.parametrize(("params", "named"), [
    ("speed_m_s=1_0", "speed_m_s is not a number: '1_0'"),  # was read as 10 m/s
    ("speed_m_s=3,speed_m_s=25", "speed_m_s given twice"),  # the last one was kept
    ("3,25", "a lone number (the mode's first parameter) given twice"),
    ("3,speed_m_s=25", "speed_m_s given twice"),
])
def test_odd_wind_params_in_flight_are_refused_naming_them(params: str, named: str) -> None:
    """SET {Type Wind} with parameters that are not plain numbers, or give one twice, while a
    robot flies: refused with the reason, the wind as it was, the robot flying on."""
    with running_sim() as server:
        client = LineClient(server.port)
        try:
            client.expect("NFO")
            client.answer("INIT {ClassName hummingbird} {Name R1} {Location 0,0,-2}", "INIT")
            assert client.answer("SET {Type Wind} {Mode constant} {Params speed_m_s=1}",
                                 "SET").type == "RES"
            client.step(200)
            before = server.runner.call(lambda sim: sim.wind.settings)
            err = client.answer(f"SET {{Type Wind}} {{Mode constant}} {{Params {params}}}", "SET")
            assert err.type == "ERR" and named in err.require("Reason"), err
            assert server.runner.call(lambda sim: sim.wind.settings) == before
            seen = client.step(200)
            assert not [m for m in seen if m.type == "ERR"], seen
        finally:
            client.close()


def test_a_long_step_hands_its_lines_over_as_it_goes() -> None:
    """A STEP of 100 s of sim time with a Hummingbird streaming (about 300 lines a sim second):
    its lines reach the client while the STEP still runs, as soon as ``FLUSH_EVENTS`` of them
    wait (another connection's PING, answered without the engine, shows a sim time short of the
    STEP's end when the first line has come), and the RES comes after the last of them. The
    engine used to keep every line of a STEP in memory until its end: 10 000 000 steps, the
    most one STEP may ask, are hours of the robot's stream (measured on a ``skeye sim``: 93 MB
    more for 600 s of one Hummingbird's, so about 1.5 GB for the whole of it)."""
    sim = Simulation(load_world("pad"), seed=1)
    count = 100_000  # 100 s of sim time at 1 ms: some 30 000 lines, FLUSH_EVENTS 10 000
    with (
        SimulationRunner(sim, mode="lockstep") as runner,
        ControlServer(runner, port=0) as server,
    ):
        stepper, other = LineClient(server.port, timeout_s=120), LineClient(server.port)
        try:
            stepper.expect("NFO")
            other.expect("NFO")
            assert stepper.answer("INIT {ClassName hummingbird} {Name R1} {Start Pad1}",
                                  "INIT").type == "RES"
            stepper.send(f"STEP {{Count {count}}}")
            first, _ = stepper.read_until(lambda m: m.type == "SEN")
            assert first == []  # nothing came before it (the STEP's own lines begin)
            now_s = float(other.answer("PING {Id 1}", "PING").require("Time"))
            assert now_s < count * sim.dt, "the first line came only when the STEP had ended"
            lines, res = stepper.read_until(lambda m: m.type == "RES", timeout_s=600)
            assert res.get("Command") == "STEP"
            assert float(res.require("Time")) == pytest.approx(count * sim.dt)
            assert len(lines) > FLUSH_EVENTS  # the whole stream came, in several hand-overs
        finally:
            stepper.close()
            other.close()


@contextlib.contextmanager
def _slow_client_of_small_queues(monkeypatch: pytest.MonkeyPatch
                                 ) -> Iterator[tuple[Simulation, socket.socket, ClientSession]]:
    """A lockstep simulator whose clients' queues hold 20 kB of stream lines (a few seconds of
    sim time overfill them), a client of it on a slow link and its session: the kernel's
    buffers both ways small, so that a few chunks fill them (Linux would grow the server's
    send buffer to 4 MiB on loopback). Yielded once its session is set up (its NFO came)."""
    monkeypatch.setattr(session_module, "OUTBOX_BYTES", 20_000)
    sim = Simulation(load_world("pad"), seed=1)
    with (
        SimulationRunner(sim, mode="lockstep") as runner,
        ControlServer(runner, port=0) as server,
        contextlib.closing(socket.socket()) as slow,
    ):
        slow.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        slow.connect(("127.0.0.1", server.port))
        assert slow.recv(4096).startswith(b"NFO")  # sent once its session is set up
        port = slow.getsockname()[1]
        session = next(s for s in server._sessions if s.peer.endswith(f":{port}"))
        session.sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
        yield sim, slow, session


def _lines_until_ping(slow: socket.socket) -> bytes:
    """Everything the server sends up to the answer of a PING sent now (it is answered after
    everything queued before it); a lost answer is a recv timeout."""
    slow.sendall(b"PING {Id done}\r\n")
    slow.settimeout(10)
    received = b""
    while b"{Id done}" not in received:
        data = slow.recv(1 << 16)
        assert data, "the server closed the connection"
        received += data
    return received


def test_a_stream_backlog_never_costs_a_client_its_step_answer(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A lockstep client whose reading falls behind its robot's stream loses stream lines (the
    queue is bounded), never the RES of its STEP: that answer is what it waits for. Answers
    have an eighth more room than the stream lines; they used to share the stream's bound,
    so a RES queued while the backlog was full was dropped and the client waited for good."""
    with _slow_client_of_small_queues(monkeypatch) as (sim, slow, session):
        # Each STEP's lines are one chunk (fewer than FLUSH_EVENTS), some 45 kB: the
        # first fills the queue while the writer waits on the client, the others find it
        # full and are dropped.
        slow.sendall(b"INIT {ClassName hummingbird} {Name S} {Start Pad1}\r\n"
                     + b"STEP {Count 1000}\r\n" * 4)
        # S's reader takes its next STEP once the last is answered: wait (on sim time) for
        # the fourth to be under way. Its client has read nothing: the first three RES
        # were queued behind a full queue of stream lines.
        assert wait_for(lambda: sim.time_s >= 3.5, timeout_s=30), "the STEPs did not run"
        assert session.dropped > 0
        received = _lines_until_ping(slow)
        lines = received.split(b"\r\n")
        assert [line for line in lines if line.startswith(b"RES {Command STEP}")] == [
            b"RES {Command STEP} {Time %d.000000}" % t for t in (1, 2, 3, 4)], lines[-5:]


def test_a_stream_backlog_never_costs_a_client_the_err_of_its_robots_crash(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The simulator's own ERR lines to a robot's connection (``ERR {Command CRASH}``,
    ``ERR {Command PHYSICS}``) are answers too (simulator.md): a client whose reading falls
    behind its robot's stream loses stream lines, not the news that its robot crashed (the
    pilot's airframe and skeye.control learn of a crash from that line alone). They came
    inside the engine's chunk of stream lines, and were dropped with it."""
    with _slow_client_of_small_queues(monkeypatch) as (sim, slow, session):
        # Motors off 8 m up: the impact (a crash) comes in the second STEP, whose chunk
        # finds the queue full of the first one's lines.
        slow.sendall(b"INIT {ClassName hummingbird} {Name F} {Location 0,3,-8}\r\n"
                     b"DRIVE {RollAngle 0} {PitchAngle 0} {Thrust 0}\r\n"
                     + b"STEP {Count 1000}\r\n" * 4)
        assert wait_for(lambda: sim.time_s >= 3.5, timeout_s=30), "the STEPs did not run"
        assert session.dropped > 0
        assert sim.robots["F"].flight.crashed  # (the simulator saw the crash)
        received = _lines_until_ping(slow)
        crashes = [line for line in received.split(b"\r\n")
                   if line.startswith(b"ERR {Command CRASH} {Name F}")]
        assert len(crashes) == 1, received[-300:]
