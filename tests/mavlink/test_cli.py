"""``skeye up`` and ``skeye pilot``: MAVLink links checked before anything starts."""

from __future__ import annotations

import socket
import subprocess
import sys

from skeye.ground.cli import DEFAULT_MAVLINK


def _skeye(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "skeye.cli", *args], capture_output=True,
                          text=True, timeout=120)


def test_skeye_up_serves_qgroundcontrol_and_mavsdk_ports_by_default():
    assert DEFAULT_MAVLINK == ("udpout://127.0.0.1:14550", "udpout://127.0.0.1:14540")


def test_skeye_up_refuses_a_bad_or_taken_mavlink_link_before_starting_anything():
    bad = _skeye("up", "--mavlink", "http://127.0.0.1:1")
    assert bad.returncode == 1 and "MAVLink links are udp://" in bad.stderr
    assert "open http" not in bad.stdout
    bracket = _skeye("up", "--mavlink", "udpin://[::1:14540")  # urllib's ValueError escaped
    assert bracket.returncode == 1, bracket
    assert "'udpin://[::1:14540': Invalid IPv6 URL" in bracket.stderr, bracket.stderr
    assert "Traceback" not in bracket.stderr and "open http" not in bracket.stdout
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        done = _skeye("up", "--mavlink", f"udp://127.0.0.1:{port}")
    assert done.returncode == 1, done
    assert f"UDP port {port}" in done.stderr and "already in use" in done.stderr
    assert "--mavlink" in done.stderr


def test_skeye_pilot_refuses_a_taken_mavlink_port_before_reaching_the_simulator():
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        done = _skeye("pilot", "--sim", "127.0.0.1:1", "--mavlink", f"tcp://127.0.0.1:{port}")
    assert done.returncode == 2 and f"TCP port {port}" in done.stderr, done
    assert "--rtp-video" not in done.stderr
    rtp = _skeye("pilot", "--sim", "127.0.0.1:1", "--rtp-video", "udp://127.0.0.1:5600")
    assert rtp.returncode == 2 and "needs --images" in rtp.stderr
