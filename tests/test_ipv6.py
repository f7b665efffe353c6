"""Servers bound to an IPv6 address: ``--host ::1`` (or ``::``) was refused by every server of
skeye with socket.create_server's "[Errno -9] Address family for hostname not supported",
after ``port_in_use`` had probed that address as IPv6 and found it free. They now bind through
:func:`skeye.peers.listen`, in the host's own family, and say where as a URL does
(``[::1]:3000``)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from skeye.peers import listen
from skeye.recording.records import SENT, Record, format_header, format_record
from skeye.recording.replay import ReplayServer
from tests.ports import free_port


def _ipv6_loopback() -> bool:
    try:
        with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as probe:
            probe.bind(("::1", 0))
        return True
    except OSError:
        return False


pytestmark = pytest.mark.skipif(not _ipv6_loopback(), reason="no IPv6 loopback (::1) here")


def _first_line(port: int, timeout_s: float = 120.0) -> bytes:
    """The first line a server on [::1]:port sends, once it listens (a child starting)."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with socket.create_connection(("::1", port), timeout=30) as sock:
                return sock.makefile("rb").readline()
        except ConnectionRefusedError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def test_listen_binds_each_host_in_its_own_family() -> None:
    with listen("::1", 0) as server:
        assert server.family == socket.AF_INET6
        with socket.create_connection(("::1", server.getsockname()[1]), timeout=10):
            pass
    with listen("127.0.0.1", 0, backlog=4) as server:
        assert server.family == socket.AF_INET


def test_skeye_sim_serves_its_control_and_image_ports_on_ipv6() -> None:
    control, image = free_port(), free_port()
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.Popen(
        [sys.executable, "-m", "skeye.cli", "sim", "--host", "::1", "--port", str(control),
         "--image-port", str(image)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    try:
        assert _first_line(control).startswith(b"NFO "), "no NFO on [::1]"
        with socket.create_connection(("::1", image), timeout=30):
            pass
    finally:
        proc.terminate()
        out = proc.communicate(timeout=60)[0]
    assert f"control protocol on [::1]:{control} (::1)" in out, out
    assert f"image server on [::1]:{image} " in out, out


def test_a_replay_serves_on_ipv6(tmp_path: Path) -> None:
    path = tmp_path / "flight.rec"
    path.write_bytes(format_header({"world": "pad"})
                     + format_record(Record(1.0, 0.0, 1, SENT, "RES {Command INIT} {Name R1}"))
                     + format_record(Record(1.0, 0.0, 1, SENT, "STA {Name R1} {Time 0}")))
    with ReplayServer(path, host="::1", port=0) as replay:
        assert _first_line(replay.port).startswith(b"NFO ")
