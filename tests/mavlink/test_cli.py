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


def test_skeye_pilot_refuses_one_port_given_to_two_of_its_links():
    """A fleet's pilots each get their own ports; a copy-paste slip that gives one port twice
    (``--port`` and a MAVLink TCP link, or one ``--mavlink udp://`` twice) is said at start,
    exit 2, naming both, before the simulator is reached (``--sim`` is nobody here): until
    2026-11-27 each check passed on its own, the robot was spawned and the pilot died with a
    traceback when the second bind failed."""
    with socket.create_server(("127.0.0.1", 0)) as probe:
        port = probe.getsockname()[1]
    tcp = _skeye("pilot", "--sim", "127.0.0.1:1", "--port", str(port),
                 "--mavlink", f"tcp://127.0.0.1:{port}")
    assert tcp.returncode == 2, tcp
    assert f"TCP port {port} is given to both the pilot (--port)" in tcp.stderr, tcp.stderr
    assert f"tcp://127.0.0.1:{port}" in tcp.stderr and "Traceback" not in tcp.stderr
    udp = _skeye("pilot", "--sim", "127.0.0.1:1", "--port", "0",
                 "--mavlink", f"udp://127.0.0.1:{port}", "--mavlink", f"udp://0.0.0.0:{port}")
    assert udp.returncode == 2, udp
    assert f"UDP port {port} is given to both" in udp.stderr, udp.stderr
    # a UDP link beside a TCP port of the same number is no clash (two name spaces): it gets
    # as far as the simulator, which is not there (exit 4)
    apart = _skeye("pilot", "--sim", "127.0.0.1:1", "--port", str(port), "--timeout", "1",
                   "--mavlink", f"udp://127.0.0.1:{port}")
    assert apart.returncode == 4, apart


def test_one_port_under_two_names_of_one_address_is_refused_too():
    """``localhost`` and ``127.0.0.1`` are one address to the bind: a pilot on ``--port P``
    beside ``--mavlink tcp://localhost:P`` (or two ``udp://`` links naming the address two ways)
    is the same clash as one port written twice, said at start, exit 2, naming both. Until
    2026-11-28 the check compared the hosts as written: the robot was spawned and the pilot
    exited 1 when the second link failed to bind (here, with no simulator at ``--sim``, exit 4
    after the wait)."""
    with socket.create_server(("127.0.0.1", 0)) as probe:
        port = probe.getsockname()[1]
    tcp = _skeye("pilot", "--sim", "127.0.0.1:1", "--timeout", "1", "--port", str(port),
                 "--mavlink", f"tcp://localhost:{port}")
    assert tcp.returncode == 2, tcp
    assert f"TCP port {port} is given to both the pilot (--port)" in tcp.stderr, tcp.stderr
    assert f"tcp://localhost:{port}" in tcp.stderr and "Traceback" not in tcp.stderr
    udp = _skeye("pilot", "--sim", "127.0.0.1:1", "--timeout", "1", "--port", "0",
                 "--mavlink", f"udp://localhost:{port}", "--mavlink", f"udp://127.0.0.1:{port}")
    assert udp.returncode == 2, udp
    assert f"UDP port {port} is given to both" in udp.stderr, udp.stderr
    # two loopback addresses are two addresses: each link binds its own (exit 4: no simulator)
    apart = _skeye("pilot", "--sim", "127.0.0.1:1", "--timeout", "1", "--port", "0",
                   "--mavlink", f"udp://127.0.0.1:{port}", "--mavlink", f"udp://127.0.0.2:{port}")
    assert apart.returncode == 4, apart


def test_a_mavlink_endpoint_that_cannot_bind_says_why():
    """``MavlinkServer`` with a link whose port is taken raises the ConfigError naming it (it
    raised AttributeError from its own clean-up, hiding the cause, until 2026-11-27)."""
    import threading

    import pytest

    from skeye.errors import ConfigError
    from skeye.pilot.boards import OnboardBoards
    from skeye.pilot.mavlink_server import MavlinkServer
    from tests.pilot.fake_airframe import FakeAirframe

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        with pytest.raises(ConfigError, match=f"127.0.0.1:{port}"):
            MavlinkServer(OnboardBoards(FakeAirframe()), threading.Lock(),
                          ["udp://127.0.0.1:0", f"udp://127.0.0.1:{port}"])
