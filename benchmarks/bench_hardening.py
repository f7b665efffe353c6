"""Hardening figures (issue 15): how fast a dead engine is announced, how fast hoarded slots are
freed, how one address is held to its share.

- engine death: a realtime simulator with ``--clients`` connected clients (one drives a robot);
  the engine fails (an injected step-hook fault); the time from the failure to each client's
  ``ERR {Command ENGINE}`` (before: never; a PING kept answering with frozen time).
- idle slots: 128 connections that never send a line hold every control slot; a 129th of the
  same user is served in the place of one (issue 31), and the time until the handshake timeout
  has closed them all and a new client is served (before issue 15: never).
- per-user share: a 65th connection of one user is served at once, taking the place of that
  user's quietest robot-less connection (issue 31; the attack figures are bench_attack.py's).

Usage: python benchmarks/bench_hardening.py [--clients 20] [--handshake-timeout 10]
"""

from __future__ import annotations

import argparse
import json
import socket
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from skeye.cliargs import positive_float, positive_int
from skeye.sim.engine import Simulation
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.world import load_world


def _read_until(sock: socket.socket, needle: bytes, timeout_s: float) -> float | None:
    """Monotonic time at which ``needle`` arrived, or None (closed or timed out first)."""
    sock.settimeout(timeout_s)
    buf = b""
    try:
        while needle not in buf:
            data = sock.recv(65536)
            if not data:
                return None
            buf = buf[-len(needle):] + data
    except TimeoutError:
        return None
    return time.monotonic()


def engine_death(clients: int) -> dict[str, float]:
    sim = Simulation(load_world("pad"), seed=1)
    with SimulationRunner(sim, mode="realtime") as runner, ControlServer(runner, port=0) as srv:
        socks = [socket.create_connection(("127.0.0.1", srv.port)) for _ in range(clients)]
        socks[0].sendall(b"INIT {ClassName hummingbird} {Name R1} {Start Pad1}\r\n")
        for s in socks[1:]:
            s.sendall(b"PING {Id 1}\r\n")
        time.sleep(1.0)
        failed_at: list[float] = []

        def boom(s: object) -> None:
            failed_at.append(time.monotonic())
            raise OverflowError("injected")

        arrivals: list[float | None] = [None] * clients

        def wait(i: int) -> None:
            arrivals[i] = _read_until(socks[i], b"{Command ENGINE}", 30.0)

        threads = [threading.Thread(target=wait, args=(i,)) for i in range(clients)]
        for t in threads:
            t.start()
        runner.call(lambda s: s.step_hooks.append(boom))
        for t in threads:
            t.join(60)
        for s in socks:
            s.close()
    delays = [(a - failed_at[0]) * 1000 for a in arrivals if a is not None]
    return {"clients": clients, "told": len(delays), "max_ms": round(max(delays), 1),
            "median_ms": round(sorted(delays)[len(delays) // 2], 1)}


def idle_slots(handshake_timeout_s: float) -> dict[str, float]:
    sim = Simulation(load_world("pad"), seed=1)
    with (SimulationRunner(sim, mode="realtime") as runner,
          ControlServer(runner, port=0, max_clients_per_peer=128,
                        handshake_timeout_s=handshake_timeout_s) as srv):
        t0 = time.monotonic()
        hoard = [socket.create_connection(("127.0.0.1", srv.port)) for _ in range(128)]
        while srv.client_count < 128 and time.monotonic() < t0 + 60:
            time.sleep(0.01)
        full = socket.create_connection(("127.0.0.1", srv.port))  # the 129th, same user
        served_while_full = _read_until(full, b"NFO", 30.0) is not None  # replaces one
        full.close()
        while srv.client_count and time.monotonic() < t0 + 600:
            time.sleep(0.05)
        freed_s = time.monotonic() - t0
        late = socket.create_connection(("127.0.0.1", srv.port))
        late.sendall(b"PING {Id late}\r\n")
        served = _read_until(late, b"{Id late}", 30.0) is not None
        late.close()
        for s in hoard:
            s.close()
    return {"hoarders": 128, "129th_served_while_full": served_while_full,
            "all_freed_after_s": round(freed_s, 2), "new_client_served": served}


def per_peer() -> dict[str, float]:
    """64 connections of this user (its share), then a 65th: served, and the user's quietest
    robot-less connection told it was replaced (issue 31: before, refused per address)."""
    sim = Simulation(load_world("pad"), seed=1)
    with SimulationRunner(sim, mode="realtime") as runner, ControlServer(runner, port=0) as srv:
        socks = [socket.create_connection(("127.0.0.1", srv.port)) for _ in range(64)]
        for s in socks:
            s.sendall(b"PING {Id x}\r\n")
        while srv.client_count < 64:
            time.sleep(0.01)
        extra = socket.create_connection(("127.0.0.1", srv.port))
        t0 = time.monotonic()
        served = _read_until(extra, b"NFO", 30.0)
        replaced = _read_until(socks[0], b"replaced by a newer connection", 30.0)
        extra.close()
        for s in socks:
            s.close()
    return {"connections": 65,
            "65th_served_in_ms": round((served - t0) * 1000, 1) if served else -1.0,
            "quietest_replaced_in_ms": round((replaced - t0) * 1000, 1) if replaced else -1.0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--clients", type=positive_int, default=20)
    parser.add_argument("--handshake-timeout", type=positive_float, default=10.0)
    args = parser.parse_args()
    print(json.dumps({"engine_death": engine_death(args.clients),
                      "idle_slots": idle_slots(args.handshake_timeout),
                      "per_peer": per_peer()}, indent=2))


if __name__ == "__main__":
    main()
