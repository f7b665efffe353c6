"""The connection's threads: no interleaved bytes, bounded queues, clean close, clear failures."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

import skeye
from skeye.control import LinkClosed
from skeye.errors import CommandRejected, LinkTimeout, LocalProtocolError, SkeyeError
from skeye.wire.sim_lines import LineDecoder, LineError, Message, format_message
from skeye.wire.sim_messages import Ping
from tests.control.conftest import SimHandle, sim_running


def _control_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("skeye-control")]


def _assert_only(before: set[threading.Thread]) -> None:
    """Our threads are gone at once; the server's session threads within a second."""
    assert not _control_threads(), _control_threads()
    deadline = time.monotonic() + 2.0
    while set(threading.enumerate()) - before and time.monotonic() < deadline:
        time.sleep(0.02)
    assert set(threading.enumerate()) <= before, set(threading.enumerate()) - before


@contextmanager
def relay(port: int, downstream: threading.Event | None = None) -> Iterator[tuple[int, bytearray]]:
    """A TCP relay to the simulator that records every byte the client sends; while
    ``downstream`` is clear it holds what the simulator sends (a silent link)."""
    listener = socket.create_server(("127.0.0.1", 0))
    captured = bytearray()
    threads: list[threading.Thread] = []
    sockets: list[socket.socket] = []
    stop = threading.Event()

    def pump(src: socket.socket, dst: socket.socket, record: bool) -> None:
        try:
            while data := src.recv(65536):
                if record:
                    captured.extend(data)
                elif downstream is not None:
                    while not downstream.wait(0.1) and not stop.is_set():
                        pass
                dst.sendall(data)
        except OSError:
            pass
        finally:
            for s in (src, dst):
                try:
                    s.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass

    def accept() -> None:
        client, _ = listener.accept()
        upstream = socket.create_connection(("127.0.0.1", port))
        sockets.extend((client, upstream))
        for args in ((client, upstream, True), (upstream, client, False)):
            t = threading.Thread(target=pump, args=args, daemon=True)
            t.start()
            threads.append(t)

    acceptor = threading.Thread(target=accept, daemon=True)
    acceptor.start()
    try:
        yield listener.getsockname()[1], captured
    finally:
        stop.set()
        acceptor.join(5)
        listener.close()
        for t in threads:
            t.join(5)
        for s in sockets:
            s.close()


def test_eight_producers_never_interleave_bytes(lockstep_sim: SimHandle) -> None:
    per_thread = 60
    # Long lines (unserialised writers would interleave them): an Id near its 1000 characters.
    padding = "x" * 990
    with relay(lockstep_sim.server.port) as (port, captured):
        with skeye.connect(f"127.0.0.1:{port}", queue_size=8) as sim:
            errors: list[BaseException] = []

            def produce(i: int) -> None:
                try:
                    for k in range(per_thread):
                        ident = f"t{i}-{k}-{padding}"
                        if k % 2:
                            sim.send("PING", ("Id", ident))
                        else:  # requests are matched to their own answers by Id
                            answer = sim.request("PING", ("Id", ident))
                            assert answer.get("Id") == ident
                except BaseException as exc:
                    errors.append(exc)

            workers = [threading.Thread(target=produce, args=(i,)) for i in range(8)]
            for w in workers:
                w.start()
            for w in workers:
                w.join(30)
            assert not errors, errors
            sim.ping()  # everything before it has been written and answered
    events = LineDecoder().feed(bytes(captured))
    assert not [e for e in events if isinstance(e, LineError)]
    pings = [e for e in events if isinstance(e, Message) and e.type == "PING"]
    assert len(pings) == 1 + 8 * per_thread + 1  # connect()'s, the producers', the last
    for i in range(8):  # each producer's commands arrive whole and in its order
        ids = [m.get("Id") for m in pings if (m.get("Id") or "").startswith(f"t{i}-")]
        assert ids == [f"t{i}-{k}-{padding}" for k in range(per_thread)]


def test_full_queue_blocks_then_raises_link_timeout() -> None:
    """A simulator that stops reading: the queue fills and the producer gets LinkTimeout."""
    listener = socket.create_server(("127.0.0.1", 0))
    accepted: list[socket.socket] = []

    def serve() -> None:
        conn, _ = listener.accept()
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        conn.sendall(format_message("NFO", ("Gametype", "skeye"), ("TimeStep", 0.001),
                                    ("Mode", "realtime")))
        accepted.append(conn)
        greeting = b""  # connect() asks the sim time: answered, ...
        while not greeting.endswith(b"\n"):
            greeting += conn.recv(1)
        (ping,) = LineDecoder().feed(greeting)
        assert isinstance(ping, Message) and ping.type == "PING"
        conn.sendall(format_message("RES", ("Command", "PING"), ("Id", ping.get("Id")),
                                    ("Time", 0.0)))
        # ... and then never read

    server = threading.Thread(target=serve, daemon=True)
    server.start()
    big = "y" * 60000
    with skeye.connect(f"127.0.0.1:{listener.getsockname()[1]}", queue_size=2,
                       timeout_s=0.5) as sim:
        started = time.monotonic()
        with pytest.raises(LinkTimeout, match="queue full"):
            for _ in range(10000):
                sim.send("PING", ("Pad", big), timeout_s=0.3)
        assert time.monotonic() - started < 30
    server.join(5)
    for c in accepted:
        c.close()
    listener.close()
    assert not _control_threads()


def test_close_stops_every_thread_lockstep(lockstep_sim: SimHandle) -> None:
    before = set(threading.enumerate())
    sim = skeye.connect(lockstep_sim.address)
    copter = sim.spawn("hummingbird", start="Pad1")
    copter.take_off(0.5)
    assert len(_control_threads()) == 2  # message handler + command handler
    sim.close()
    sim.close()  # idempotent
    _assert_only(before)
    with pytest.raises(LinkClosed):
        copter.fly_to(1.0, 0.0, 0.5)
    with pytest.raises(LinkClosed):
        sim.ping()


def test_close_stops_every_thread_realtime() -> None:
    with sim_running(mode="realtime") as handle:
        before = set(threading.enumerate())
        with skeye.connect(handle.address) as sim:
            assert sim.mode == "realtime"
            copter = sim.spawn("hummingbird", start="Pad1")
            copter.take_off(0.3, wait=False)  # the control thread flies it
            first = copter.ins.wait_next(2.0)
            time.sleep(0.3)
            assert copter.ins.latest is not None and copter.ins.latest.time_s > first.time_s
            assert len(_control_threads()) == 3  # + the realtime control thread
        _assert_only(before)


def test_simulator_dying_mid_flight_raises_quickly() -> None:
    with sim_running() as handle, skeye.connect(handle.address, timeout_s=5.0) as sim:
        copter = sim.spawn("hummingbird", start="Pad1")
        copter.take_off(1.0)
        killer = threading.Timer(0.3, handle.server.close)
        killer.start()
        started = time.monotonic()
        with pytest.raises(SkeyeError) as info:
            # Far and slow (400 s of sim time): in lockstep the client steps the sim as fast as
            # it can, and the compiled sim flies 20 m at full speed in under the 0.3 s.
            copter.fly_to(20.0, 0.0, 1.0, max_speed_m_s=0.05)
        killer.join()
        assert time.monotonic() - started < 3.0
        assert isinstance(info.value, LinkClosed | CommandRejected), info.value
        assert "closed" in str(info.value) or "shutting down" in str(info.value)
        with pytest.raises(SkeyeError):
            copter.ins.wait_next(1.0)


def test_engine_stopping_mid_flight_raises_quickly() -> None:
    with sim_running() as handle, skeye.connect(handle.address, timeout_s=5.0) as sim:
        copter = sim.spawn("hummingbird", start="Pad1")
        copter.take_off(1.0)
        killer = threading.Timer(0.3, handle.runner.close)
        killer.start()
        started = time.monotonic()
        with pytest.raises(CommandRejected, match="shutting down"):
            copter.fly_to(20.0, 0.0, 1.0, max_speed_m_s=0.05)  # 400 s of sim time
        killer.join()
        assert time.monotonic() - started < 3.0


def test_realtime_simulator_dying_mid_flight_raises() -> None:
    with sim_running(mode="realtime") as handle, skeye.connect(handle.address) as sim:
        copter = sim.spawn("hummingbird", start="Pad1")
        killer = threading.Timer(0.5, handle.server.close)
        killer.start()
        started = time.monotonic()
        with pytest.raises(LinkClosed, match="closed the connection"):
            copter.take_off(2.0)
        killer.join()
        assert time.monotonic() - started < 3.0


@contextmanager
def taking_off_through_a_relay(timeout_s: float) -> Iterator[tuple[Any, Any, threading.Event]]:
    """A realtime simulator behind a relay, a hummingbird taking off from Pad1 (its first
    reading in): the connection, the robot, and the relay's downstream gate (clear it to hold
    back every line the simulator sends)."""
    downstream = threading.Event()
    downstream.set()
    with sim_running(mode="realtime") as handle, relay(handle.server.port, downstream) as (
            port, _), skeye.connect(f"127.0.0.1:{port}", timeout_s=timeout_s) as sim:
        copter = sim.spawn("hummingbird", start="Pad1")
        copter.take_off(1.0, wait=False)
        copter.ins.wait_next(5.0)
        try:
            yield sim, copter, downstream
        finally:
            downstream.set()


def test_a_realtime_link_silent_for_a_while_is_waited_out() -> None:
    """The simulator's lines held back for 3 s (a busy machine, a starved process) mid take-off:
    the motion goes on once they arrive. Feedback is judged stale on the sim clock; a silent
    link fails a motion only after the connection's timeout_s (the next test)."""
    with taking_off_through_a_relay(10.0) as (sim, copter, downstream):
        downstream.clear()
        deadline = time.monotonic() + 30.0  # a ceiling: the reader counts 1 s waits
        while sim.silent_s < 2.5:  # past the 2 s that the wall-clock age check took as lost
            assert time.monotonic() < deadline, sim.silent_s
            time.sleep(0.05)
        downstream.set()
        copter.wait_done(60.0)
        assert sim.silent_s < 1.0


def test_a_realtime_link_silent_for_its_timeout_fails_the_motion() -> None:
    with taking_off_through_a_relay(4.0) as (_sim, copter, downstream):
        downstream.clear()
        with pytest.raises(LinkTimeout, match=r"the simulator has sent nothing for [4-9]\.\d s "
                                              r"\(the connection's timeout_s is 4 s\)"):
            copter.wait_done(60.0)


def test_nothing_listening_is_a_clear_error() -> None:
    probe = socket.create_server(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    with pytest.raises(LinkClosed, match="cannot connect"):
        skeye.connect(f"127.0.0.1:{port}", timeout_s=1.0)


def test_a_connection_knows_the_sim_time_from_the_start(lockstep_sim: SimHandle) -> None:
    """A second client joining a simulator that has run reads its time at once, not 0 until
    the first reading arrives."""
    with skeye.connect(lockstep_sim.address) as first:
        t = first.step(250)
        assert t == pytest.approx(250 * first.time_step_s)
        with skeye.connect(lockstep_sim.address) as late:
            assert late.time_s == t  # lockstep: no step since, so exactly the first's time


def test_a_server_that_greets_but_never_answers_is_named_at_connect() -> None:
    """connect() asks the sim time (one PING): a server that sends NFO and then answers nothing
    is refused naming that PING (the user sent none), and nothing is left running."""
    listener = socket.create_server(("127.0.0.1", 0))
    accepted: list[socket.socket] = []

    def serve() -> None:
        conn, _ = listener.accept()
        conn.sendall(format_message("NFO", ("Gametype", "skeye"), ("TimeStep", 0.001),
                                    ("Mode", "realtime")))
        accepted.append(conn)

    server = threading.Thread(target=serve, daemon=True)
    server.start()
    try:
        with pytest.raises(LinkTimeout, match=r"no answer in 0\.5 s to the PING connect\(\) "
                                              r"sends to learn the sim time"):
            skeye.connect(f"127.0.0.1:{listener.getsockname()[1]}", timeout_s=0.5)
        assert not _control_threads()
    finally:
        server.join(5)
        for c in accepted:
            c.close()
        listener.close()


@pytest.mark.parametrize("mode", ["lockstep", "realtime"])
def test_a_closed_connections_robot_is_gone_when_close_returns(mode: str) -> None:
    """The robot went when the simulator read the closed connection, after ``close()`` had
    returned: a view of ``skeye up``'s camera calibration, one robot a connection, was refused
    onto the place its predecessor still took (CI, a busy host). ``close()`` now ends its side
    and waits for the simulator's, which comes once the removal is queued, ahead of any later
    command: a spawn after ``close()`` finds the place free, every time."""
    with sim_running(mode=mode) as handle:
        for i in range(20):
            with skeye.connect(handle.address) as sim:
                sim.spawn("hummingbird", name=f"R{i}", location_ned_m=(0.0, 0.0, 0.0))
            # The engine thread runs its tasks in order: one queued now runs after a removal
            # queued before close() returned.
            robots = handle.runner.call(lambda s: list(s.robots))
            assert robots == [], (i, robots)


def test_a_name_or_ping_id_beyond_the_simulators_limits_is_refused_before_it_is_sent(
        lockstep_sim: SimHandle) -> None:
    """The simulator refuses a robot name over 64 characters and a PING Id over 1000 (its
    answers echo them within the line limit); the client built and sent such a command and
    learnt it only from the ERR. It is now a LocalProtocolError naming the limit, as a value
    out of its range is, and nothing goes out."""
    received: list[bytes] = []
    lockstep_sim.server.observers.append(
        lambda conn_id, direction, data: received.append(data) if direction == "<" else None)
    with skeye.connect(lockstep_sim.address) as sim:
        with pytest.raises(LocalProtocolError, match=r"Name: .* at most 64 characters"):
            sim.spawn(name="N" * 65, location_ned_m=(0.0, 0.0, -1.0))
        with pytest.raises(LocalProtocolError, match=r"Id: .* at most 1000 characters"):
            sim.request_message(Ping("y" * 1001))
        assert sim.request_message(Ping("y" * 1000)).id == "y" * 1000  # the limit itself
    assert received and not [line for line in received
                              if line.startswith(b"INIT") or b"y" * 1001 in line], received


def test_a_ping_id_given_twice_is_matched_by_its_first_block(lockstep_sim: SimHandle) -> None:
    """The simulator reads a key's first block (as USARSim's GetArgVal); the client matched a
    PING's answer by the last Id given, so the answer (Id a) was never matched and the
    request ran into its timeout."""
    with skeye.connect(lockstep_sim.address) as sim:
        # a stuck guard: the answer unmatched, the request ran out
        answer = sim.request("PING", ("Id", "a"), ("Id", "b"), timeout_s=30.0)
        assert answer.get("Id") == "a", answer


def test_waiting_for_a_camera_of_a_simulator_without_images_names_the_cause(
        lockstep_sim: SimHandle) -> None:
    """examples/camera.py against ``skeye sim`` without ``--image-port`` took off and ended in
    "Camera 'Down': no reading within 5 s", which did not say that such a simulator announces no
    frames at all; a camera that never had a frame says so now."""
    with skeye.connect(lockstep_sim.address) as sim:
        copter = sim.spawn("hummingbird", start="Pad1")
        with pytest.raises(LinkTimeout, match=r"^Camera 'Down': no reading within 0\.5 s, and "
                           r"none before: .*--image-port"):
            copter.camera.wait_next(0.5)
        copter.imu.wait_next()  # the link is still up
