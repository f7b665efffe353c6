"""Slot caps count a local user once, however many loopback addresses it binds (issue 31, item
3), against a real ``skeye sim`` process and a real pilot server on loopback.

Before: one user held 127 of 128 simulator control slots, or 63 of 64 image slots, by binding
127.0.0.2, 127.0.0.3, ...; idle connections to the pilot (each one held its accept thread for
0.5 s, and the first held the one client slot) kept a real ground station out."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import pytest

from skeye.link.vehicle import Vehicle
from skeye.peers import own_key
from skeye.pilot.server import PilotServer
from skeye.wire.packets import PD, PollMask
from tests.pilot.fake_airframe import FakeAirframe
from tests.robustness.helpers import sim_process


def loopback_address(i: int) -> str:
    """The i-th loopback address after 127.0.0.1 (127.0.0.2, 127.0.0.3, ...)."""
    return f"127.0.{(i + 2) // 250}.{(i + 2) % 250 + 1}"


def connect_from(i: int, port: int, timeout_s: float = 30.0) -> socket.socket:
    sock = socket.socket()
    sock.settimeout(timeout_s)
    sock.bind((loopback_address(i), 0))
    sock.connect(("127.0.0.1", port))
    return sock


def read_line(sock: socket.socket) -> bytes:
    data = b""
    while not data.endswith(b"\n"):
        chunk = sock.recv(1)
        if not chunk:
            break
        data += chunk
    return data


def still_open(sock: socket.socket) -> bool:
    """True while the server has sent nothing more and not closed (non-blocking peek)."""
    sock.setblocking(False)
    try:
        data = sock.recv(4096, socket.MSG_PEEK)
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        sock.setblocking(True)
    return bool(data) and b"CONNECT" not in data


@pytest.fixture(scope="module")
def sim() -> Iterator[dict[str, int]]:
    with sim_process("--image-port", "0") as (_proc, ports, _banner):
        yield ports


def test_the_simulator_counts_one_user_once_across_loopback_addresses(sim) -> None:
    """100 connections from 100 loopback addresses, each with a PING as the probe's were: the
    user keeps at most its 64 (default, half the 128 slots); a newer one replaces its
    quietest."""
    socks = []
    try:
        for i in range(100):
            s = connect_from(i, sim["control"])
            assert read_line(s).startswith(b"NFO"), i
            s.sendall(f"PING {{Id {i}}}\r\n".encode())
            assert read_line(s).startswith(b"RES"), i  # served: its PING answered
            socks.append(s)
        deadline = time.monotonic() + 30
        while sum(still_open(s) for s in socks) > 64 and time.monotonic() < deadline:
            time.sleep(0.05)
        kept = sum(still_open(s) for s in socks)
        assert kept <= 64, f"one user holds {kept} control slots"
        assert kept >= 60  # the newest are the ones kept
        told = b"".join(s.recv(4096) for s in socks[:10])
        assert b"replaced by a newer connection" in told
    finally:
        for s in socks:
            s.close()


def test_the_image_server_counts_one_user_once_across_loopback_addresses(sim) -> None:
    socks = []
    try:
        for i in range(50):
            s = connect_from(i, sim["image"])
            s.sendall(b"SKEYE META on\n")  # a request: no longer a handshake-less connection
            socks.append(s)
        deadline = time.monotonic() + 30
        kept = len(socks)
        while time.monotonic() < deadline:
            kept = sum(1 for s in socks if _image_open(s))
            if kept <= 32:
                break
            time.sleep(0.05)
        assert kept <= 32, f"one user holds {kept} image slots"
    finally:
        for s in socks:
            s.close()


def _image_open(sock: socket.socket) -> bool:
    sock.setblocking(False)
    try:
        return not sock.recv(1 << 16, socket.MSG_PEEK)  # an error frame or EOF: closed
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        sock.setblocking(True)


_OTHER_USER = """
import os, socket, sys
os.setuid(65534)  # nobody: another local user
s = socket.socket()
s.settimeout(30)
s.connect(("127.0.0.1", int(sys.argv[1])))
f = s.makefile("rb")
print(f.readline().decode().strip(), flush=True)
s.sendall(b"PING {Id other}\\r\\n")
print(f.readline().decode().strip(), flush=True)
"""


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="needs root to act as another local user (setuid nobody)")
def test_another_local_user_is_served_while_one_user_holds_every_address(sim) -> None:
    socks = []
    try:
        for i in range(128):  # as many connections as there are slots
            s = connect_from(i, sim["control"])
            s.sendall(f"PING {{Id {i}}}\r\n".encode())
            socks.append(s)
        other = subprocess.run([sys.executable, "-c", _OTHER_USER, str(sim["control"])],
                               capture_output=True, text=True, timeout=120)
        lines = other.stdout.splitlines()
        assert other.returncode == 0, other.stderr
        assert lines[0].startswith("NFO") and lines[1].startswith("RES {Command PING}"), lines
    finally:
        for s in socks:
            s.close()


def test_idle_connections_from_many_addresses_never_keep_a_ground_station_out() -> None:
    """An attacker opens idle connections to the pilot, 20 a second from 128 loopback
    addresses, and keeps them open; real stations connect meanwhile and are served at once."""
    air = FakeAirframe()
    stop = threading.Event()
    held: list[socket.socket] = []

    def attack(port: int) -> None:
        i = 0
        while not stop.wait(0.05):
            try:
                held.append(connect_from(i % 128, port, timeout_s=5.0))
            except OSError:
                pass
            i += 1

    with PilotServer(air, port=0) as pilot:
        assert pilot.port is not None
        attacker = threading.Thread(target=attack, args=(pilot.port,), daemon=True)
        attacker.start()
        try:
            time.sleep(1.0)  # the attack under way: about 20 idle connections so far
            for _ in range(5):
                with Vehicle.open(pilot.address, timeout_s=10.0) as station:
                    assert PD.LL_STATUS in station.poll(int(PollMask.LL_STATUS))
                # The attacker's idle connections were never served, and it holds only its
                # MAX_PENDING_PER_PEER of them (its own newer ones replace its older).
                assert pilot.pending <= 4 + 1
            assert pilot.turned_away == 0
        finally:
            stop.set()
            attacker.join(10)
            for s in held:
                s.close()
    assert own_key().startswith("uid ") or own_key() == "loopback"
