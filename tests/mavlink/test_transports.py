"""The endpoint on each kind of link: a serial line (two pseudo-terminals back to back) and a TCP
server, with pymavlink on the other end; the vehicle is the boards on a scripted airframe."""

from __future__ import annotations

import contextlib
import gc
import os
import select
import socket
import subprocess
import sys
import time

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as dialect

from skeye.link.transport import pty_null_modem
from skeye.mavlink.transport import PEER_TIMEOUT_S, UdpTransport
from skeye.pilot.mavlink_server import MAX_PARSERS
from tests.mavlink.conftest import scripted_endpoint as endpoint
from tests.mavlink.conftest import wait_for

M = mavutil.mavlink


def _params(conn) -> set[str]:
    conn.mav.param_request_list_send(1, 1)
    names = set()
    first = wait_for(conn, "PARAM_VALUE")
    names.add(first.param_id)
    while len(names) < first.param_count:
        names.add(wait_for(conn, "PARAM_VALUE").param_id)
    return names


def test_the_vehicle_answers_over_a_serial_line():
    with pty_null_modem() as (vehicle_end, ground_end), \
            endpoint(f"serial://{vehicle_end}?baud=57600") as server:
        conn = mavutil.mavlink_connection(ground_end, baud=57600, source_system=255,
                                          source_component=190)
        try:
            hb = wait_for(conn, "HEARTBEAT")
            assert hb.autopilot == M.MAV_AUTOPILOT_PX4
            assert {"MIS_TAKEOFF_ALT", "COM_DL_LOSS_T", "GF_MAX_VER_DIST"} <= _params(conn)
            assert server.addresses == [f"serial://{vehicle_end}?baud=57600"]
        finally:
            conn.close()


def test_the_vehicle_serves_tcp_clients():
    with endpoint("tcp://127.0.0.1:0") as server:
        port = int(server.addresses[0].rsplit(":", 1)[1])
        conns = [mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=s,
                                            source_component=190) for s in (255, 254)]
        try:
            for conn in conns:
                wait_for(conn, "HEARTBEAT")
                assert "RTL_RETURN_ALT" in _params(conn)
        finally:
            for conn in conns:
                conn.close()


def test_a_listening_udp_link_frees_the_place_of_a_ground_station_gone_silent():
    """Eight ground stations that each sent a HEARTBEAT and went away (a QGroundControl or
    pymavlink restart comes from a new source port) fill the link: a ninth is told "too many
    ground stations". Once the eight have been silent for PEER_TIMEOUT_S the link drops them
    and serves the ninth. (The link once kept every sender for good: after eight, no new
    ground station was ever served.) The link's expiry runs on a clock the test advances, so
    no station expires before the test says (however slow the machine) and none waits ten
    real seconds; waits are on what arrives, with stuck guards only."""
    clock = _FakeClock()
    with endpoint("udp://127.0.0.1:0") as server:
        port = int(server.addresses[0].rsplit(":", 1)[1])
        link = server.transports[0]
        link.clock = clock

        def station(n: int):
            return mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=200 + n,
                                              source_component=190)

        for n in range(8):
            gone = station(n)
            try:
                wait_for(gone, "HEARTBEAT")  # served: the vehicle's telemetry reaches it
            finally:
                gone.close()
        assert len(link.peers) == 8
        ninth = station(8)
        try:
            note = wait_for(ninth, "STATUSTEXT", timeout_s=30.0)
            assert "too many ground stations" in note.text
            assert len(link.peers) == 8 and link.expired_peers == 0
            clock.now_s += PEER_TIMEOUT_S + 1.0  # the eight have been silent that long
            # wait_for keeps sending the ninth's heartbeat: the eight expire and it is served
            # as the only peer.
            wait_for(ninth, "HEARTBEAT", lambda m: len(link.peers) == 1, timeout_s=30.0)
            assert link.expired_peers == 8 and link.refused_peers >= 1
        finally:
            ninth.close()


class _FakeClock:
    """A monotonic clock the test moves by hand (read from the endpoint's thread)."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def _poll_one(link: UdpTransport) -> tuple[bytes, object]:
    """The next datagram the link reads (stuck guard 5 s)."""
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        select.select(link.fileobjs(), [], [], 0.1)
        got = link.poll()
        if got:
            assert len(got) == 1
            return got[0]
    raise AssertionError("no datagram within 5 s")


def test_a_listening_udp_link_s_peers_are_those_heard_within_the_timeout():
    """Unit level, on a fake clock: peers in the order first heard, a sender over
    ``max_peers`` refused, silent ones dropped after ``peer_timeout_s`` (one that keeps sending
    stays); a sending link's remote is never dropped."""
    clock = _FakeClock()
    senders = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(3)]
    with contextlib.ExitStack() as stack:
        for s in senders:
            stack.enter_context(s)
            s.bind(("127.0.0.1", 0))
        a, b, c = (s.getsockname() for s in senders)
        link = UdpTransport("127.0.0.1", 0, max_peers=2, peer_timeout_s=10.0, clock=clock)
        stack.callback(link.close)
        for s in senders:
            s.sendto(b"x", ("127.0.0.1", link.port))
            _poll_one(link)
        assert link.peers == [a, b] and link.refused_peers == 1
        clock.now_s = 6.0
        senders[1].sendto(b"x", ("127.0.0.1", link.port))
        assert _poll_one(link)[1] == b
        clock.now_s = 10.5  # a silent for 10.5 s, b for 4.5 s
        assert link.peers == [b] and link.expired_peers == 1
        senders[2].sendto(b"x", ("127.0.0.1", link.port))
        assert _poll_one(link)[1] == c
        assert link.peers == [b, c]
        out = UdpTransport("127.0.0.1", 0, remote=a, clock=clock)
        stack.callback(out.close)
        clock.now_s = 1e6
        assert out.peers == [a] and out.expired_peers == 0


def _tcp_station(port: int):
    return mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=255,
                                      source_component=190)


def test_idle_tcp_connections_keep_no_ground_station_out():
    """Ten connections that never send a byte, then a ground station: it is served (the
    vehicle's HEARTBEAT and a parameter's answer reach it) and the link holds at most its four
    clients. A connection of a user at its cap (all but one of the clients) takes the place of
    that user's connection heard from longest ago. (Before, four idle connections held every
    TCP client slot for good: each later one was closed at once, a ground station included.)"""
    with endpoint("tcp://127.0.0.1:0") as server:
        port = int(server.addresses[0].rsplit(":", 1)[1])
        link = server.transports[0]
        idle = [socket.create_connection(("127.0.0.1", port)) for _ in range(10)]
        conn = _tcp_station(port)
        try:
            wait_for(conn, "HEARTBEAT", timeout_s=20.0)
            assert "RTL_RETURN_ALT" in _params(conn)
            assert len(link.clients) <= 4
            assert link.refused_clients == 0
        finally:
            conn.close()
            for s in idle:
                s.close()


_OTHER_USER_HOLDS = """
import os, socket, sys
os.setuid(65534)  # nobody: another local user
socks = [socket.socket() for _ in range(8)]
for s in socks:
    s.connect(("127.0.0.1", int(sys.argv[1])))
print("connected", flush=True)
sys.stdin.readline()
"""


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="needs root to act as another local user (setuid nobody)")
def test_another_user_holding_tcp_connections_keeps_no_ground_station_out():
    """Another local user (uid 65534) opens eight idle connections and keeps them: it holds at
    most three of the four clients, and this user's ground station is served beside them.
    (Before, the first four held every slot and the station was closed at once.)"""
    with endpoint("tcp://127.0.0.1:0") as server:
        port = int(server.addresses[0].rsplit(":", 1)[1])
        other = subprocess.Popen([sys.executable, "-c", _OTHER_USER_HOLDS, str(port)],
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        conn = None
        try:
            assert other.stdout is not None and other.stdout.readline().strip() == "connected"
            conn = _tcp_station(port)
            wait_for(conn, "HEARTBEAT", timeout_s=20.0)
            assert "RTL_RETURN_ALT" in _params(conn)
            assert len(server.transports[0].clients) <= 4
        finally:
            if conn is not None:
                conn.close()
            other.kill()
            other.wait(10)


def _heartbeat_frame() -> bytes:
    mav = dialect.MAVLink(None, 255, 190)
    return bytes(mav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(mav))


def _closed_sockets() -> int:
    gc.collect()
    return sum(1 for o in gc.get_objects() if isinstance(o, socket.socket) and o.fileno() == -1)


def test_the_vehicle_keeps_nothing_of_tcp_clients_gone():
    """300 ground stations that each connect, send a HEARTBEAT and close: the vehicle keeps at
    most the parsers of the last ``MAX_PARSERS`` peers a link remembers, with their sockets
    (before, it also noted every peer that sent a message, for good, and kept each closed
    socket with it: memory grew with every connection ever made)."""
    hb = _heartbeat_frame()
    with endpoint("tcp://127.0.0.1:0") as server:
        port = int(server.addresses[0].rsplit(":", 1)[1])
        before = _closed_sockets()
        for _ in range(300):
            with socket.create_connection(("127.0.0.1", port)) as s:
                s.sendall(hb)
                s.shutdown(socket.SHUT_WR)
                s.settimeout(10.0)
                while s.recv(65536):  # the vehicle closes its end when it has read ours
                    pass
        held = _closed_sockets() - before
        assert server.received >= 300
        assert held <= MAX_PARSERS, f"{held} closed sockets of gone clients still held"
