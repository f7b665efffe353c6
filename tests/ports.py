"""Free loopback ports for tests that must name a port before a server binds it.

A port the kernel handed out for ``bind(("127.0.0.1", 0))`` and that was closed again is free
only until the kernel hands it out once more: for another test's server bound to port 0, or as
the local port of any outgoing connection. ``skeye up`` binds its ports after calibrating a
camera (12 s and more), and in CI the simulator found its port taken by then.

So the ports given here lie *below* the kernel's ephemeral range
(``/proc/sys/net/ipv4/ip_local_port_range``), which the kernel never hands out by itself, and each
pytest-xdist worker takes its own slice of them, going round it in turn from a place of its own
process's (two test runs at once start apart): another test can take one only by naming it, and
no test of another worker names it. Each port is checked free (bound and closed) before it is
given. Where the ephemeral range leaves too few ports below it, the kernel's port-0 choice is
used, as before.
"""

from __future__ import annotations

import itertools
import os
import random
import socket
from pathlib import Path

_LOWEST = 20000  # above the well-known and registered ports our tools use (3000, 5003, 14550)


def _ephemeral_low() -> int:
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768  # Linux's default, and IANA's dynamic range starts higher still (49152)


def _slice() -> range:
    """This worker's ports; empty where the ephemeral range leaves too few below it."""
    workers = max(1, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1))
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    index = int(worker[2:]) if worker[2:].isdigit() else 0
    size = (_ephemeral_low() - _LOWEST) // workers
    if size < 64:
        return range(0)
    start = _LOWEST + (index % workers) * size
    return range(start, start + size)


_PORTS = _slice()
_FIRST = random.Random(os.getpid()).randrange(len(_PORTS)) if _PORTS else 0
_NEXT = itertools.cycle([*_PORTS[_FIRST:], *_PORTS[:_FIRST]])


def _is_free(port: int, kind: int) -> bool:
    with socket.socket(socket.AF_INET, kind) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A loopback port nothing is bound to (TCP by default, ``socket.SOCK_DGRAM`` for UDP)."""
    if not _PORTS:
        with socket.socket(socket.AF_INET, kind) as s:
            s.bind(("127.0.0.1", 0))
            return int(s.getsockname()[1])
    for _ in range(len(_PORTS)):
        port = next(_NEXT)
        if _is_free(port, kind):
            return port
    raise RuntimeError("no free loopback port in this test worker's slice")


def free_ports(n: int, kind: int = socket.SOCK_STREAM) -> list[int]:
    """``n`` different free loopback ports."""
    return [free_port(kind) for _ in range(n)]
