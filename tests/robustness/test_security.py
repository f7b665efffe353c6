"""Security: loopback by default, size limits, and no command reaches files outside its folders."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import numpy as np
import pytest

from skeye.recording.records import Recorder
from skeye.robots.config import BUILTIN_ROBOTS
from skeye.sim.image_server import Frame, FrameBuffer, ImageServer
from skeye.wire.images import FrameDecoder, RemoteError
from skeye.wire.packets import (
    SKEYE_START,
    START,
    CommandStreamParser,
    ErrorKind,
    FrameError,
    VehicleStreamParser,
)
from tests.robustness.helpers import wait_for
from tests.sim.conftest import LineClient, running_sim

ROBOT_TOML = (Path(__file__).resolve().parents[2] / "skeye/robots/hummingbird.toml").read_text()


def test_servers_bind_loopback_by_default() -> None:
    buffer = FrameBuffer()
    with running_sim() as control, ImageServer(buffer, port=0) as images:
        for server in (control, images):
            assert server.host == "127.0.0.1"
            assert server._listener.getsockname()[0] == "127.0.0.1"


@pytest.fixture
def folders(tmp_path: Path) -> tuple[Path, Path]:
    """A robot folder with ok.toml, and a secret valid robot file beside (outside) it."""
    robots = tmp_path / "robots"
    robots.mkdir()
    (robots / "ok.toml").write_text(ROBOT_TOML)
    secret = tmp_path / "secret.toml"
    secret.write_text(ROBOT_TOML.replace('name = "hummingbird"', 'name = "TOPSECRET"'))
    return robots, secret


def test_init_class_name_is_never_a_path(folders: tuple[Path, Path]) -> None:
    robots, secret = folders
    attempts = [
        str(secret),
        str(secret.with_suffix("")),
        "../secret",
        "../secret.toml",
        "ok/../../secret",
        "USARBot.../secret",
        "./ok.toml",
        str(robots / "ok.toml"),
        "/etc/passwd",
        "..\\secret",
        "%2e%2e/secret",
        "ok\x00",
    ]
    with running_sim(robot_dirs=(robots,)) as server:
        client = LineClient(server.port)
        client.expect("NFO")
        for name in attempts:
            answer = client.answer(f"INIT {{ClassName {name}}} {{Location 0,0,-1}}", "INIT")
            reason = answer.get("Reason") or ""
            assert answer.type == "ERR", name
            # a NUL is no value's: refused before any robot class is looked for
            refusal = ("INIT: ClassName holds the control character \\x00" if "\x00" in name
                       else "unknown robot class")
            assert refusal in reason, (name, reason)
            assert "TOPSECRET" not in reason and "TOML" not in reason
        assert server.runner.call(lambda sim: list(sim.robots)) == []
        for bad_name in ("../x", "a/b", "x.toml"):
            answer = client.answer(
                f"INIT {{ClassName ok}} {{Name {bad_name}}} {{Location 0,0,-1}}", "INIT"
            )
            assert answer.type == "ERR" and "robot name" in (answer.get("Reason") or "")
        ok = client.answer("INIT {ClassName ok} {Location 0,0,-1}", "INIT")
        assert ok.type == "RES" and ok.get("Status") == "OK"
        client.close()
    assert "ok" not in BUILTIN_ROBOTS


def test_recorder_writes_only_its_file(tmp_path: Path) -> None:
    path = tmp_path / "only.rec"
    with running_sim() as server, Recorder(path) as recorder:
        recorder.attach(server, server.runner)
        client = LineClient(server.port)
        client.expect("NFO")
        client.answer("INIT {ClassName hummingbird} {Name evil-..} {Location 0,0,-1}", "INIT")
        client.answer(f"INIT {{ClassName {tmp_path / 'x.toml'}}} {{Location 0,0,-1}}", "INIT")
        client.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["only.rec"]


def test_control_line_limit_closes_only_that_connection() -> None:
    with running_sim() as server:
        other = LineClient(server.port)
        other.expect("NFO")
        bad = LineClient(server.port)
        bad.expect("NFO")
        bad.sock.sendall(b"PING {Id " + b"x" * 70_000)
        err = bad.expect("ERR")
        assert "longer than 65536" in (err.get("Reason") or "")
        with pytest.raises(ConnectionError):
            bad.expect("NFO", timeout_s=3)
        assert other.answer("PING {Id ok}", "PING").type == "RES"
        assert wait_for(lambda: server.client_count == 1)
        bad.close()
        other.close()


def test_image_request_line_limit() -> None:
    buffer = FrameBuffer()
    buffer.register_camera("R1/Down", 1)
    buffer.publish(Frame("R1/Down", 1, 1, 0.0, np.zeros((8, 8, 3), np.uint8)))
    with ImageServer(buffer, port=0) as server:
        sock = socket.create_connection(("127.0.0.1", server.port), timeout=5)
        sock.sendall(b"SKEYE CAMERA " + b"x" * 5000 + b"\nOK")
        decoder = FrameDecoder()
        events: list[object] = []
        deadline = time.monotonic() + 5
        while len(events) < 2 and time.monotonic() < deadline:
            events.extend(decoder.feed(sock.recv(65536)))
        assert isinstance(events[0], RemoteError) and "longer than 1024" in events[0].reason
        assert not isinstance(events[1], RemoteError)  # the OK after it is served
        sock.close()


@pytest.mark.parametrize(
    ("parser_cls", "start"), [(VehicleStreamParser, START), (CommandStreamParser, SKEYE_START)]
)
def test_packet_length_limit_and_bounded_buffer(parser_cls: type, start: bytes) -> None:
    parser = parser_cls()
    events = parser.feed(start + (1025).to_bytes(2, "little") + b"\x01" + b"\0" * 2000)
    errors = [e for e in events if isinstance(e, FrameError)]
    assert errors and errors[0].kind is ErrorKind.TOO_LONG
    rng = np.random.default_rng(5)
    for _ in range(50):
        parser.feed(rng.integers(0, 256, 20_000, dtype=np.uint8).tobytes())
    assert parser.buffered <= 1024 + 16
