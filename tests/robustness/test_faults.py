"""Fault tests: clients that die mid-message, mid-frame or mid-command, or never read, and
1000 connect/disconnect cycles with no leaked threads, sockets or memory."""

from __future__ import annotations

import gc
import socket
import struct
import time
import tracemalloc
from collections.abc import Iterator

import numpy as np
import pytest

import skeye.sim.session as session_module
from skeye.control.image_client import ImageClient
from skeye.pixels import frame_image_rgb
from skeye.sim.image_server import Frame, FrameBuffer, ImageServer, _ClientHandler
from skeye.sim.server import ControlServer
from tests.robustness.helpers import open_fds, thread_count, wait_for
from tests.sim.conftest import LineClient, running_sim

MEMORY_BOUND_BYTES = 256 * 1024  # growth allowed over 1000 cycles, after a warm-up


def _abort(sock: socket.socket) -> None:
    """Close with a TCP reset, as a killed process's socket does when data is unread."""
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    sock.close()


@pytest.fixture(scope="module")
def control() -> Iterator[ControlServer]:
    with running_sim() as server:
        yield server


def _robots(server: ControlServer) -> list[str]:
    return server.runner.call(lambda sim: list(sim.robots))


@pytest.mark.parametrize("hard", [False, True])
def test_client_dies_mid_line(control: ControlServer, hard: bool) -> None:
    witness = LineClient(control.port)
    witness.expect("NFO")
    sock = socket.create_connection(("127.0.0.1", control.port))
    sock.sendall(b"INIT {ClassName hummingbird} {Loca")
    _abort(sock) if hard else sock.close()
    assert wait_for(lambda: control.client_count == 1)
    assert _robots(control) == []
    assert witness.answer("PING {Id 1}", "PING").type == "RES"
    witness.close()


@pytest.mark.parametrize("hard", [False, True])
def test_client_dies_mid_command(control: ControlServer, hard: bool) -> None:
    victim = LineClient(control.port)
    victim.expect("NFO")
    victim.answer("INIT {ClassName hummingbird} {Location 0,0,-1}", "INIT")
    # A long STEP is running on the engine when the client goes away.
    victim.send("STEP {Count 3000}")
    victim.send("DRIVE {LinearVelocity 1}")
    _abort(victim.sock) if hard else victim.close()
    assert wait_for(lambda: control.client_count == 0, timeout_s=20)
    assert wait_for(lambda: _robots(control) == [], timeout_s=30)
    witness = LineClient(control.port)
    witness.expect("NFO")
    assert witness.answer("INIT {ClassName hummingbird} {Location 0,0,-1}", "INIT").type == "RES"
    witness.close()
    assert wait_for(lambda: _robots(control) == [])


def test_control_client_that_never_reads(
    control: ControlServer, monkeypatch: pytest.MonkeyPatch
) -> None:
    bound = 300_000  # small, so the test fills it quickly
    monkeypatch.setattr(session_module, "OUTBOX_BYTES", bound)
    sleeper = socket.socket()
    sleeper.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sleeper.connect(("127.0.0.1", control.port))
    sleeper.sendall(b"INIT {ClassName hummingbird} {Location 0,0,-1}\r\n")
    driver = LineClient(control.port)
    driver.expect("NFO")
    assert wait_for(lambda: len(_robots(control)) == 1)
    # ~300 lines/s for 80 s of sim time: more than the socket buffers and the outbox hold.
    start = time.monotonic()
    for _ in range(8):
        driver.step(10_000)
        ping_start = time.monotonic()
        assert driver.answer("PING {Id p}", "PING").type == "RES"
        assert time.monotonic() - ping_start < 1.0
    elapsed = time.monotonic() - start
    sessions = list(control._sessions)
    slow = next(s for s in sessions if s.robot_name is not None)
    # Its stream waits in its own byte-bounded queue and socket (its writer thread is blocked
    # in sendall), never in the engine: the driver's 80 s of sim time ran at full speed, and
    # what did not fit was dropped and counted.
    assert slow._queued_bytes <= bound + 400_000  # at most one oversized chunk on top
    assert slow.dropped > 0
    assert slow._writer.is_alive()
    assert elapsed < 60
    sleeper.close()
    driver.close()
    assert wait_for(lambda: control.client_count == 0 and _robots(control) == [], timeout_s=10)


def test_a_client_that_hangs_up_has_its_socket_closed_at_once(control: ControlServer) -> None:
    """With the collector off: the server closes a session's socket when its threads end, not
    when a reference cycle happens to be collected (it used to hold every one until then)."""
    gc.collect()
    fds = open_fds()
    gc.disable()
    try:
        for _ in range(20):
            sock = socket.create_connection(("127.0.0.1", control.port))
            assert sock.recv(4096).startswith(b"NFO")
            sock.close()
        assert wait_for(lambda: control.client_count == 0 and open_fds() <= fds,
                        timeout_s=10), f"{open_fds() - fds} descriptors still open"
    finally:
        gc.enable()


def test_1000_connect_disconnect_cycles_leak_nothing(control: ControlServer) -> None:
    def cycle(n: int) -> None:
        for _ in range(n):
            sock = socket.create_connection(("127.0.0.1", control.port))
            assert sock.recv(4096).startswith(b"NFO")
            sock.close()
        assert wait_for(lambda: control.client_count == 0, timeout_s=10)

    cycle(50)  # warm up caches, logging, the allocator
    gc.collect()
    threads, fds = thread_count(), open_fds()
    tracemalloc.start()
    before = tracemalloc.take_snapshot()
    cycle(1000)
    assert wait_for(lambda: thread_count() <= threads, timeout_s=10), thread_count() - threads
    gc.collect()
    after = tracemalloc.take_snapshot()
    tracemalloc.stop()
    diffs = after.compare_to(before, "filename")
    growth = sum(s.size_diff for s in diffs)
    assert open_fds() <= fds
    top = [f"{d.traceback[0].filename}: {d.size_diff}" for d in diffs[:5]]
    assert growth < MEMORY_BOUND_BYTES, f"grew {growth} bytes; top: {top}"


# ---------------------------------------------------------------------------- image server


@pytest.fixture(scope="module")
def images() -> Iterator[ImageServer]:
    buffer = FrameBuffer()
    buffer.register_camera("R1/Down", 1)
    rng = np.random.default_rng(1)
    buffer.publish(Frame("R1/Down", 1, 1, 0.0, rng.integers(0, 255, (600, 800, 3), np.uint8)))
    with ImageServer(buffer, port=0) as server:
        yield server


def test_image_client_dies_mid_frame(images: ImageServer) -> None:
    for hard in (False, True):
        sock = socket.create_connection(("127.0.0.1", images.port))
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.sendall(b"OK")
        assert len(sock.recv(1000)) > 0  # the 1.44 MB RAW frame has started
        _abort(sock) if hard else sock.close()
        assert wait_for(lambda: images.client_count() == 0)
    with ImageClient("127.0.0.1", images.port) as client:
        assert frame_image_rgb(client.get_frame()).shape == (600, 800, 3)


def test_image_client_that_never_reads(images: ImageServer) -> None:
    sleeper = socket.create_connection(("127.0.0.1", images.port))
    sleeper.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sleeper.sendall(b"SKEYE STREAM 1000\n" + b"OK" * 1000)
    buffer = images.buffer
    stop = time.monotonic() + 1.5
    number = 1
    with ImageClient("127.0.0.1", images.port) as client:
        got = 0
        while time.monotonic() < stop:
            number += 1
            rgb = np.full((600, 800, 3), number % 255, np.uint8)
            buffer.publish(Frame("R1/Down", 1, number, number * 0.03, rgb))
            client.get_frame()
            got += 1
        assert got > 10  # the healthy client is served at a normal rate
    stats = {s.address: s for s in images.stats()}
    stuck = [s for s in stats.values() if s.frames_sent <= 2]
    assert stuck  # the sleeper is held back by TCP, not buffered in the server
    sleeper.close()
    assert wait_for(lambda: images.client_count() == 0)


def test_image_connect_close_cycles_leave_no_client_behind(images: ImageServer) -> None:
    """A client gone is gone: its handler (its sockets, parser, and the frame it was sending)
    is freed, and the frame buffer no longer calls it on every publish. Nothing of a client
    must persist once its connection has ended, so the bound is zero handlers."""

    def cycle(n: int) -> None:
        for i in range(n):
            sock = socket.create_connection(("127.0.0.1", images.port))
            sock.sendall(b"SKEYE STREAM 30\nOK" if i % 2 else b"OK")
            assert len(sock.recv(1000)) > 0  # the 1.44 MB RAW frame has started
            _abort(sock) if i % 3 == 0 else sock.close()
        assert wait_for(lambda: images.client_count() == 0)

    cycle(5)  # warm up
    gc.collect()
    threads, fds = thread_count(), open_fds()
    cycle(30)
    assert wait_for(lambda: thread_count() <= threads, timeout_s=10), thread_count() - threads
    gc.collect()
    left = [o for o in gc.get_objects()  # this server's (another test's are not counted)
            if isinstance(o, _ClientHandler) and o._server is images]
    assert not left, f"{len(left)} image client handlers outlived their 30 connections"
    assert open_fds() <= fds
