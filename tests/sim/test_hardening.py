"""The simulator never stops silently (issue 15, points 4, 5, 9), over real loopback sockets.

- Every wind parameter and every INIT value has a physical range, checked before it is accepted.
- If the engine thread dies anyway, every client gets ``ERR {Command ENGINE}`` naming the
  failure at once, later connections too, and ``skeye sim`` exits with status 3.
- Idle and handshake-less connections are closed; one peer address cannot take every slot.

Waits are on events with generous deadlines, never on how fast a busy machine runs.
"""

from __future__ import annotations

import logging
import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable

import pytest

from skeye.errors import ConfigError, LocalProtocolError
from skeye.processes import die_with_parent
from skeye.sim.image_server import FrameBuffer, ImageServer
from skeye.sim.server import ControlServer
from skeye.wire.images import FrameDecoder, RemoteError
from skeye.wire.sim_lines import Message
from skeye.wire.wind import PARAM_RANGES
from tests.sim.conftest import LineClient, running_sim

ENGINE_ERR_WAIT_S = 10.0  # "at once": far below the 30 s call timeout a client used to wait


def _is_err(command: str) -> Callable[[Message], bool]:
    return lambda m: m.type == "ERR" and (m.get("Command") or "").upper() == command


def _closed(client: LineClient, timeout_s: float = 30.0) -> None:
    """Read until the server closes the connection."""
    with pytest.raises(ConnectionError):
        client.read_until(lambda m: False, timeout_s=timeout_s)


def _ping_time(client: LineClient) -> float:
    return float(client.answer("PING {Id t}", "PING").require("Time"))


# -- point 4: ranges ------------------------------------------------------------------------

OUT_OF_RANGE = [
    ("random_force", "f_max_n=0.3,tick_s=1e-320", "tick_s"),  # the engine killer
    ("constant", "speed_m_s=1e6", "speed_m_s"),  # the world emptier
    ("constant", "speed_m_s=41", "speed_m_s"),
    ("constant", "from_deg=1e300", "from_deg"),
    ("turbulence", "sigma_m_s=1e9", "sigma_m_s"),
    ("turbulence", "sigma_m_s=-1", "sigma_m_s"),
    ("random_force", "f_max_n=1e12", "f_max_n"),
    ("random_force", "tick_s=0", "tick_s"),
    ("random_force", "tick_s=1e300", "tick_s"),
    ("random_force", "tick_s=inf", "tick_s"),
]


def test_out_of_range_values_are_refused_and_the_engine_keeps_running() -> None:
    with running_sim(mode="realtime") as server:
        c = LineClient(server.port)
        c.expect("NFO")
        err = c.answer("INIT {ClassName hummingbird} {Name R2} {Location 0,0,-1} "
                       "{Rotation 1e300,0,0}", "INIT")
        assert err.type == "ERR" and "2pi" in (err.get("Reason") or ""), err
        assert c.answer("INIT {ClassName hummingbird} {Name R1} {Start Pad1}", "INIT").type == "RES"
        for mode, params, key in OUT_OF_RANGE:
            err = c.answer(f"SET {{Type Wind}} {{Mode {mode}}} {{Params {params}}}", "SET")
            reason = err.get("Reason") or ""
            low, high = PARAM_RANGES[key]
            assert err.type == "ERR", (params, err)
            assert key in reason and f"[{low:g}, {high:g}]" in reason, (params, err)
        for line, words in [
            ("DRIVE {LinearVelocity 1e300}", ("LinearVelocity",)),
            ("DRIVE {Thrust -1}", ("Thrust",)),
            ("SET {Type Camera} {Name Down} {Opcode FOV} {Params 1e300}", ("Params",)),
            ("STEP {Count 99999999999}", ("STEP",)),
        ]:
            c.send(line)
            err = c.read_until(lambda m: m.type == "ERR")[1]
            assert all(w.lower() in str(err).lower() for w in words), (line, err)
        # A value at the edge of its range is accepted; the engine is alive and time runs.
        ok = c.answer("SET {Type Wind} {Mode random_force} {Params f_max_n=0.3,tick_s=0.001}",
                      "SET")
        assert ok.type == "RES", ok
        t0 = _ping_time(c)
        c.read_until(lambda m: m.type == "SEN" and float(m.require("Time")) > t0 + 0.2,
                     timeout_s=60)
        assert server.runner.alive and server.runner.error is None
        assert server.runner.call(lambda sim: list(sim.robots)) == ["R1"]
        c.close()


# -- point 5: a dead engine is announced at once -----------------------------------------------


def _kill_engine(server: ControlServer) -> None:
    def boom(sim: object) -> None:
        raise OverflowError("math range error (test)")

    server.runner.call(lambda sim: sim.step_hooks.append(boom))


def test_realtime_engine_death_reaches_every_client_at_once() -> None:
    with running_sim(mode="realtime") as server:
        pilot = LineClient(server.port)
        pilot.expect("NFO")
        assert pilot.answer("INIT {ClassName hummingbird} {Name R1} {Start Pad1}",
                            "INIT").type == "RES"
        watcher = LineClient(server.port)
        watcher.expect("NFO")
        assert watcher.answer("PING {Id 1}", "PING").type == "RES"
        _kill_engine(server)
        for client in (pilot, watcher):
            err = client.read_until(_is_err("ENGINE"), timeout_s=ENGINE_ERR_WAIT_S)[1]
            assert "OverflowError" in (err.get("Reason") or ""), err
            _closed(client)
        assert server.runner.error is not None and not server.runner.alive
        # A later connection is told too, instead of a PING with frozen time.
        late = LineClient(server.port)
        err = late.read_until(_is_err("ENGINE"), timeout_s=ENGINE_ERR_WAIT_S)[1]
        assert "OverflowError" in (err.get("Reason") or "")
        _closed(late)
        for c in (pilot, watcher, late):
            c.close()


def test_python_client_gets_link_closed_naming_the_engine_failure() -> None:
    from skeye.control.connection import LinkClosed, connect

    with running_sim(mode="realtime") as server, connect(f"127.0.0.1:{server.port}") as sim:
        closed: list[BaseException] = []
        sim.add_close_hook(closed.append)
        _kill_engine(server)
        deadline = time.monotonic() + ENGINE_ERR_WAIT_S
        while not closed and time.monotonic() < deadline:
            time.sleep(0.05)
        assert closed and isinstance(sim.error, LinkClosed), sim.error
        assert "its engine failed" in str(sim.error) and "OverflowError" in str(sim.error)


def test_lockstep_step_that_breaks_the_engine_is_fatal_for_everyone() -> None:
    with running_sim(mode="lockstep") as server:
        stepper = LineClient(server.port)
        stepper.expect("NFO")
        other = LineClient(server.port)
        other.expect("NFO")
        assert other.answer("PING {Id 1}", "PING").type == "RES"
        _kill_engine(server)
        stepper.send("STEP {Count 10}")
        # Its STEP's own ERR, or the ENGINE one that closes the session (whichever goes first).
        err = stepper.read_until(lambda m: m.type == "ERR" and m.get("Command") in
                                 ("STEP", "ENGINE"), timeout_s=ENGINE_ERR_WAIT_S)[1]
        assert "OverflowError" in (err.get("Reason") or ""), err
        err = other.read_until(_is_err("ENGINE"), timeout_s=ENGINE_ERR_WAIT_S)[1]
        assert "OverflowError" in (err.get("Reason") or "")
        _closed(other)
        assert server.runner.error is not None
        stepper.close()
        other.close()


def test_skeye_sim_process_exits_nonzero_when_its_engine_dies() -> None:
    env = dict(os.environ, SKEYE_SIM_FAULT_AT_S="0.5", PYTHONUNBUFFERED="1")
    env.setdefault("MUJOCO_GL", "egl")
    proc = subprocess.Popen([sys.executable, "-m", "skeye.cli", "sim", "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                            preexec_fn=die_with_parent())
    try:
        assert proc.stdout is not None
        port = None
        lines = []
        deadline = time.monotonic() + 120
        while port is None and time.monotonic() < deadline:
            line = proc.stdout.readline()
            assert line, f"skeye sim ended: {lines}"
            lines.append(line)
            if "control protocol on" in line:
                port = int(line.split("127.0.0.1:")[1].split()[0])
        assert port is not None
        try:
            client = LineClient(port, timeout_s=30)
        except OSError:
            client = None  # it may already be gone: the exit status below still tells
        if client is not None:
            try:
                try:
                    _, err = client.read_until(_is_err("ENGINE"), timeout_s=120)
                    assert "injected engine fault" in (err.get("Reason") or "")
                except ConnectionError:
                    pass  # connected after the failure was announced and the server closed
            finally:
                client.close()
        assert proc.wait(120) == 3
        rest = proc.stdout.read()
        assert "error: the simulation engine failed: RuntimeError" in rest, rest
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        proc.stdout.close()


# -- point 9: idle and handshake-less connections, slots per peer -------------------------------


def test_control_server_closes_idle_connections_and_limits_slots_per_peer() -> None:
    with running_sim(mode="realtime") as base:
        server = ControlServer(base.runner, port=0, max_clients_per_peer=3,
                               handshake_timeout_s=1.0, idle_timeout_s=2.0)
        with server:
            silent = LineClient(server.port)  # connects, sends nothing
            silent.expect("NFO")
            talker = LineClient(server.port)  # one PING, then quiet, no robot
            talker.expect("NFO")
            assert talker.answer("PING {Id 1}", "PING").type == "RES"
            pilot = LineClient(server.port)  # drives a robot, then quiet: kept
            pilot.expect("NFO")
            assert pilot.answer("INIT {ClassName hummingbird} {Name R1} {Start Pad1}",
                                "INIT").type == "RES"
            # A fourth connection of the same user takes the slot of its quietest connection
            # without a robot (the silent one), which is told why and closed.
            extra = LineClient(server.port)
            extra.expect("NFO")
            err = silent.read_until(_is_err("CONNECT"), timeout_s=30)[1]
            assert "replaced by a newer connection" in (err.get("Reason") or ""), err
            assert "per user or address" in (err.get("Reason") or ""), err
            _closed(silent)
            err = talker.read_until(_is_err("CONNECT"), timeout_s=30)[1]
            assert "idle for 2 s" in (err.get("Reason") or ""), err
            _closed(talker)
            err = extra.read_until(_is_err("CONNECT"), timeout_s=30)[1]
            assert "no command within 1 s" in (err.get("Reason") or ""), err
            _closed(extra)
            # The robot's connection outlives both timeouts and keeps streaming.
            t_closed = _ping_time(pilot)
            pilot.read_until(lambda m: m.type == "SEN" and float(m.require("Time")) > t_closed + 3,
                             timeout_s=120)
            assert pilot.answer("PING {Id 2}", "PING").type == "RES"
            # The freed slots are usable again.
            again = LineClient(server.port)
            again.expect("NFO")
            assert again.answer("PING {Id 3}", "PING").type == "RES"
            for c in (silent, talker, pilot, extra, again):
                c.close()
        # When every connection of the user drives a robot, a new one is refused.
        with ControlServer(base.runner, port=0, max_clients_per_peer=1) as server:
            flying = LineClient(server.port)
            flying.expect("NFO")
            assert flying.answer("INIT {ClassName hummingbird} {Name R2} {Start Pad1}",
                                 "INIT").type == "RES"
            refused = LineClient(server.port)
            err = refused.read_until(_is_err("CONNECT"), timeout_s=30)[1]
            assert "all driving robots" in (err.get("Reason") or ""), err
            _closed(refused)
            assert flying.answer("PING {Id 4}", "PING").type == "RES"
            for c in (flying, refused):
                c.close()


class _RawImage:
    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=30)
        self.decoder = FrameDecoder()

    def error_then_eof(self, timeout_s: float = 30.0) -> str:
        """The reason of the next error frame; asserts the server then closes."""
        self.sock.settimeout(timeout_s)
        events: list[object] = []
        while True:
            data = self.sock.recv(1 << 20)
            if not data:
                break
            events += self.decoder.feed(data)
        errors = [e for e in events if isinstance(e, RemoteError)]
        assert errors, events
        return errors[-1].reason

    def close(self) -> None:
        self.sock.close()


def test_image_server_closes_idle_connections_and_limits_slots_per_peer() -> None:
    with ImageServer(FrameBuffer(), port=0, max_clients_per_peer=2, handshake_timeout_s=1.0,
                     idle_timeout_s=2.0) as server:
        silent = _RawImage(server.port)
        half = _RawImage(server.port)
        half.sock.sendall(b"SKEYE FORM")  # half a request, never finished
        # A third connection of the same user takes the slot of its quietest one (silent).
        newer = _RawImage(server.port)
        assert "replaced by a newer connection" in silent.error_then_eof()
        assert "no request within 1 s" in half.error_then_eof()
        assert "no request within 1 s" in newer.error_then_eof()
        deadline = time.monotonic() + 30
        while server.client_count() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert server.client_count() == 0
        # A client that asked once and then sits there is closed after the idle timeout.
        once = _RawImage(server.port)
        once.sock.sendall(b"SKEYE META on\n")
        assert "idle for 2 s" in once.error_then_eof()
        for c in (silent, half, newer, once):
            c.close()
    # When every connection of the user streams, a new one is refused.
    with ImageServer(FrameBuffer(), port=0, max_clients_per_peer=1) as server:
        streaming = _RawImage(server.port)
        streaming.sock.sendall(b"SKEYE STREAM 5\n")
        deadline = time.monotonic() + 30  # until the server has read its request
        while not any(h.streaming for h in server._handlers) and time.monotonic() < deadline:
            time.sleep(0.01)
        refused = _RawImage(server.port)
        assert "all streaming" in refused.error_then_eof()
        for c in (streaming, refused):
            c.close()


def test_a_web_page_post_to_the_control_port_is_refused_before_its_body() -> None:
    """A browser can POST text/plain to any port (no preflight); its body would be protocol
    lines. The server closes the connection at the request line: the body is never run."""
    with running_sim(mode="realtime") as server:
        request = (b"POST / HTTP/1.1\r\nHost: 127.0.0.1:3000\r\nOrigin: http://evil.example\r\n"
                   b"Content-Type: text/plain\r\nContent-Length: 56\r\n\r\n"
                   b"SET {Type Wind} {Mode constant} {Params speed_m_s=30}\r\n")
        c = LineClient(server.port)
        c.expect("NFO")
        c.sock.sendall(request)
        err = c.read_until(_is_err("CONNECT"), timeout_s=30)[1]
        assert "not HTTP" in (err.get("Reason") or "")
        _closed(c)
        assert server.runner.call(lambda sim: sim.wind.settings.mode) == "none"
        c.close()


@pytest.mark.parametrize("limit, value", [("max_clients", 0), ("max_clients_per_peer", -1),
                                          ("handshake_timeout_s", float("nan")),
                                          ("idle_timeout_s", float("inf"))])
def test_both_servers_refuse_a_bad_connection_limit_the_same_way(limit: str, value: float) -> None:
    """A limit that is not a finite number above zero is a ConfigError naming the server, the
    limit and the value, from the control server and the image server alike; nothing binds."""
    with pytest.raises(ConfigError, match=rf"control server: {limit} must be > 0, got {value!r}"):
        ControlServer(None, port=0, **{limit: value})  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=rf"image server: {limit} must be > 0, got {value!r}"):
        ImageServer(FrameBuffer(), port=0, **{limit: value})  # type: ignore[arg-type]


def _pipes() -> set[int]:
    """This process's open descriptors that are pipes."""
    fds = set()
    for name in os.listdir("/proc/self/fd"):
        try:
            if os.readlink(f"/proc/self/fd/{name}").startswith("pipe:"):
                fds.add(int(name))
        except OSError:  # closed since listed
            pass
    return fds


@pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="reads /proc/self/fd (Linux)")
def test_a_step_answered_past_its_limit_closes_its_watch_and_writes_nothing(
        monkeypatch, caplog) -> None:
    """A STEP still running after twice its limit is answered with an error at once. Its
    watch's wake-up pipe is closed then (the old code left it open for good: two descriptors
    per such STEP), and when the STEP ends later its wake-up writes to no descriptor: not to
    the closed one (EBADF in the future's callback), nor to whatever has taken its numbers
    since (here a pipe opened just after, as a socket of another client could)."""
    import select
    import threading

    import skeye.sim.session

    monkeypatch.setattr(skeye.sim.session, "STEP_TIMEOUT_S", 0.2)
    caplog.set_level(logging.ERROR, logger="concurrent.futures")
    release = threading.Event()
    with running_sim(mode="lockstep") as server:
        server.runner.call(lambda sim: sim.step_hooks.append(lambda _: release.wait(60)))
        client = LineClient(server.port)
        client.expect("NFO")
        try:
            pipes_before = _pipes()
            client.send("STEP {Count 1}")
            err = client.read_until(_is_err("STEP"), timeout_s=60)[1]
            assert "still at it" in (err.get("Reason") or ""), err
            taker_r, taker_w = os.pipe()
            try:
                left_open = _pipes() - pipes_before - {taker_r, taker_w}
                release.set()
                # The engine runs a task's callbacks before it takes up the next task.
                server.runner.call(lambda sim: sim.step_hooks.clear())
                assert select.select([taker_r], [], [], 0.0)[0] == []
            finally:
                os.close(taker_r)
                os.close(taker_w)
        finally:
            release.set()
            client.close()
    assert not left_open, f"the watch's pipe is still open: descriptors {sorted(left_open)}"
    assert not [r for r in caplog.records if r.name == "concurrent.futures"], caplog.text


def test_a_fault_in_greeting_one_client_leaves_the_server_accepting_the_next(
        monkeypatch, caplog) -> None:
    """Anything but an OSError raised while a client was admitted (its NFO line, as a world
    named with a line break once made it) ended the accept thread: the simulator served no
    other client, without a word. The fault is logged, that connection closed, its slot
    freed, and the next client served."""
    caplog.set_level(logging.ERROR, logger="skeye.sim.server")
    with running_sim() as server:
        nfo = server.nfo_line
        calls = [0]

        def faulty_once() -> bytes:
            calls[0] += 1
            if calls[0] == 1:
                raise LocalProtocolError("injected: an NFO line that cannot be written")
            return nfo()

        monkeypatch.setattr(server, "nfo_line", faulty_once)
        first = LineClient(server.port)
        _closed(first)
        first.close()
        second = LineClient(server.port)
        try:
            second.expect("NFO")
            assert second.answer("PING {Id 1}", "PING").type == "RES"
        finally:
            second.close()
        assert server.client_count <= 1
    assert any("could not admit client" in r.getMessage() for r in caplog.records), caplog.text
