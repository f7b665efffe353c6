"""The pilot keeps its ground station: a client that stops reading, a connection that sends
nothing and a silent station never cost the vehicle or the control loop, and never hold the
one client slot for good; the failsafe still applies to a flying vehicle."""

from __future__ import annotations

import socket
import time
from contextlib import ExitStack

from skeye.control.connection import connect
from skeye.errors import CommandRejected
from skeye.link.transport import LinkClosed, TcpLink
from skeye.link.vehicle import Vehicle
from skeye.pilot.boards import BoardSettings
from skeye.pilot.outbox import Outbox
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.wire.packets import (
    PD,
    Hold,
    NavState,
    Poll,
    PollMask,
    SkeyeMask,
    Stream,
    TakeOff,
    encode,
)
from tests.ground.conftest import wait_until
from tests.pilot.fake_airframe import FakeAirframe
from tests.sim.conftest import running_sim

ALL_POLLS = sum(int(b) for b in PollMask)


def _raw_client(port: int, rcvbuf: int | None = None) -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    if rcvbuf is not None:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    sock.settimeout(30.0)
    sock.connect(("127.0.0.1", port))
    return sock


def test_a_ground_client_that_stops_reading_never_loses_the_vehicle() -> None:
    """Lockstep, unpaced: a client asks for every structure at 1 ms and never reads. The pilot
    drops its telemetry, then closes it; the vehicle is not lost and sim time keeps going."""
    with ExitStack() as stack:
        server = stack.enter_context(running_sim(mode="lockstep", seed=4))
        sim = stack.enter_context(connect(f"127.0.0.1:{server.port}", timeout_s=10.0))
        robot = sim.spawn("hummingbird", start="Pad1")
        pilot = stack.enter_context(
            PilotServer(SimAirframe(sim, robot), port=0, lockstep=True, lockstep_rate=0.0,
                        tick_s=0.05)
        )
        assert pilot.port is not None
        stalled = stack.enter_context(_raw_client(pilot.port, rcvbuf=4096))
        mask = int(SkeyeMask.NAV_STATUS | SkeyeMask.PAD)
        stalled.sendall(encode(Stream(poll_mask=ALL_POLLS, skeye_mask=mask, period=1)))
        session = wait_until(lambda: pilot.session, 30, "the client to be served")
        # On a loaded machine the loop may not fill the 64 KiB outbox before the 5 s send
        # timeout closes the client; either way the loop never waited on the socket.
        wait_until(lambda: pilot.client is None, 120, "the pilot to close the stalled client")
        assert "stopped reading" in session.outbox.close_reason
        assert pilot.vehicle_lost is None and pilot.loop_error is None
        t1 = sim.time_s
        wait_until(lambda: sim.time_s > t1 + 2.0, 120, "sim time to keep advancing")
        with Vehicle.open(pilot.address, timeout_s=10.0) as v:  # the next station is served
            v.stream(0, int(SkeyeMask.NAV_STATUS), 0.05)
            v.take_off(1.0)
            v.wait_state(NavState.HOLDING, timeout_s=120)
        assert pilot.vehicle_lost is None


def test_an_outbox_drops_telemetry_for_a_slow_reader_and_keeps_answers() -> None:
    """A real loopback socket whose peer does not read: telemetry beyond the bound is dropped
    (counted), answers are kept and arrive in order once the peer reads again."""
    listener = socket.create_server(("127.0.0.1", 0))
    with listener, _raw_client(listener.getsockname()[1], rcvbuf=4096) as peer:
        sock, _ = listener.accept()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
        with TcpLink(sock, send_timeout_s=30.0) as link, Outbox(link, max_bytes=2000) as box:
            chunk = b"t" * 500
            wait_until(lambda: not box.put(chunk, droppable=True), 30, "a telemetry drop",
                       poll_s=0.001)
            assert box.dropped >= 1 and box.dropped_bytes >= 500
            assert box.put(b"ANSWER", droppable=False)  # answers are not dropped
            received = b""
            while not received.endswith(b"ANSWER"):
                data = peer.recv(65536)
                assert data, "the link closed"
                received += data
            assert set(received[:-6]) == {ord("t")} and not box.close_reason


def test_a_connection_that_sends_nothing_is_freed_and_the_failsafe_applies() -> None:
    air = FakeAirframe()
    settings = BoardSettings(link_timeout_s=2.0, land_timeout_s=60.0)
    with PilotServer(air, port=0, settings=settings) as pilot:
        assert pilot.port is not None
        with Vehicle.open(pilot.address, keepalive_s=0.2) as first:
            first.take_off(1.0)
            air.finish(landed=False, armed=True)
            wait_until(lambda: pilot.boards.state is NavState.HOLDING, 30, "holding")
        wait_until(lambda: pilot.client is None, 30, "the first station to be gone")
        with _raw_client(pilot.port) as idle:  # connects, sends nothing
            # It waits for its first packet, and never holds the one client slot meanwhile.
            wait_until(lambda: pilot.pending, 30, "the idle connection to be accepted")
            assert pilot.client is None
            assert idle.recv(4096) == b""  # the pilot closes it (the socket timeout is 30 s)
        assert pilot.closed_idle == 1
        wait_until(lambda: pilot.boards.state is NavState.FAILSAFE, 30, "the failsafe")
        with Vehicle.open(pilot.address) as station:  # the slot is free again
            assert PD.LL_STATUS in station.poll(int(PollMask.LL_STATUS))
            station.hold()
            wait_until(lambda: pilot.boards.state is NavState.HOLDING, 30, "holding again")
        assert pilot.turned_away == 0


def test_an_http_request_from_a_web_page_is_closed_unread() -> None:
    """A web page can make the browser POST any bytes to port 7000 (text/plain, no preflight):
    valid packets in the body must not fly the vehicle."""
    air = FakeAirframe()
    with PilotServer(air, port=0) as pilot:
        assert pilot.port is not None
        body = encode(TakeOff(height=2000)) + encode(Stream(poll_mask=1, skeye_mask=0, period=50))
        request = (
            b"POST / HTTP/1.1\r\nHost: 127.0.0.1\r\nOrigin: http://evil.example\r\n"
            b"Content-Type: text/plain\r\nContent-Length: " + str(len(body)).encode()
            + b"\r\n\r\n" + body
        )
        with _raw_client(pilot.port) as page:
            try:
                for i in range(0, len(request), 3):  # however the bytes arrive
                    page.sendall(request[i : i + 3])
            except (BrokenPipeError, ConnectionResetError):
                pass  # closed on the request line, while the rest was still being sent
            try:
                assert page.recv(4096) == b""  # closed, nothing answered
            except ConnectionResetError:
                pass  # closed with unread bytes pending: a reset, still nothing answered
        assert pilot.refused_http == 1 and air.calls == []
        with Vehicle.open(pilot.address, timeout_s=30.0) as station:  # a real station is served
            assert PD.LL_STATUS in station.poll(int(PollMask.LL_STATUS))


def test_a_silent_station_is_replaced_by_the_next_one() -> None:
    """The pilot's clock is the test's: on the wall clock the first station was "still fresh"
    only if the second's handover check (after its 0.5 s grace) came within the 1 s link
    timeout of the first's last packet, half a second of wall time for a loaded machine to
    start and connect the second. Here the link timeout passes when the test says so."""
    air = FakeAirframe()
    now_s = [1000.0]
    with PilotServer(air, port=0, settings=BoardSettings(link_timeout_s=1.0),
                     clock=lambda: now_s[0]) as pilot:
        with Vehicle.open(pilot.address, keepalive_s=None) as silent:
            silent.poll(int(PollMask.LL_STATUS))
            with Vehicle.open(pilot.address) as busy_try:  # the first is still fresh: busy
                try:
                    busy_try.poll(1, timeout_s=2.0)
                    answered = True
                except (CommandRejected, LinkClosed):  # turned away (code 5)
                    answered = False
            assert not answered and pilot.turned_away == 1
            first_session = pilot.session
            assert first_session is not None
            now_s[0] += 0.75
            assert not pilot._silent(first_session)
            now_s[0] += 0.25  # the link timeout since its last packet
            assert pilot._silent(first_session)
            with Vehicle.open(pilot.address) as station:
                assert PD.LL_STATUS in station.poll(int(PollMask.LL_STATUS))
            assert pilot.replaced_silent == 1 and first_session.link.closed


def test_a_station_sending_only_corrupt_frames_is_replaced_by_the_next_one() -> None:
    """Frames that fail their CRC or checksum may be line noise: a station that polled once and
    then sent nothing intact is silent for the link timeout, however many it sends, and a new
    station takes the slot (each corrupt frame still gets its RESULT)."""
    air = FakeAirframe()
    hold = bytearray(encode(Hold()))
    hold[-5] ^= 0xFF  # the CRC's low byte
    with PilotServer(air, port=0, settings=BoardSettings(link_timeout_s=1.0)) as pilot:
        with _raw_client(pilot.port) as noisy:
            noisy.sendall(encode(Poll(int(PollMask.LL_STATUS))))
            wait_until(lambda: pilot.session is not None and pilot.session.packets == 1, 30,
                       "the first station served")
            session = pilot.session
            assert session is not None
            deadline = time.monotonic() + 30.0
            while not pilot._silent(session):
                assert time.monotonic() < deadline, "corrupt frames kept the station's slot"
                noisy.sendall(bytes(hold))
                time.sleep(0.05)
            assert session.packets == 1 and pilot.boards.errors["bad_checksum"] >= 1
            with Vehicle.open(pilot.address) as station:
                assert PD.LL_STATUS in station.poll(int(PollMask.LL_STATUS))
            assert pilot.replaced_silent == 1
