"""Server-level fuzzing: random bytes to a real control server and image server over loopback.

Invariant: every byte string gets protocol answers (ERR lines, error frames) or valid replies,
never a broken stream, and the server keeps serving a well-behaved client beside it.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skeye.sim.image_server import Frame, FrameBuffer, ImageServer
from skeye.sim.server import ControlServer
from skeye.wire.images import DecodedFrame, FrameDecoder, ProtocolViolation, RemoteError
from skeye.wire.sim_lines import LineDecoder, LineError
from tests.sim.conftest import LineClient, running_sim

FUZZ = settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
WORDS = st.sampled_from(
    [b"INIT", b"DRIVE", b"PING", b"SET", b"STEP", b"GETGEO", b"GETCONF", b"GETSTARTPOSES", b"X"]
)
SHAPED = st.lists(
    st.one_of(
        WORDS,
        st.sampled_from([b" ", b"{", b"}", b"\r\n", b"\n", b"{Type Wind}", b"{Count 1}"]),
        st.binary(max_size=12),
    ),
    max_size=40,
).map(b"".join)


@pytest.fixture(scope="module")
def control() -> Iterator[ControlServer]:
    with running_sim() as server:
        yield server


@pytest.fixture(scope="module")
def witness(control: ControlServer) -> Iterator[LineClient]:
    client = LineClient(control.port)
    client.expect("NFO")
    yield client
    client.close()


@FUZZ
@given(st.one_of(st.binary(max_size=3000), SHAPED))
def test_control_server_answers_random_bytes(
    control: ControlServer, witness: LineClient, data: bytes
) -> None:
    sock = socket.create_connection(("127.0.0.1", control.port), timeout=10)
    try:
        sock.sendall(data + b"\r\nPING {Id end-of-fuzz}\r\n")
        decoder = LineDecoder()
        types: list[str] = []
        buf = b""
        while b"end-of-fuzz" not in buf:
            chunk = sock.recv(65536)
            assert chunk, "server closed the connection"
            buf += chunk
        for event in decoder.feed(buf):
            assert not isinstance(event, LineError), event
            types.append(event.type)
        assert types[0] == "NFO" and types[-1] == "RES"
    finally:
        sock.close()
    assert witness.answer("PING {Id alive}", "PING").get("Id") == "alive"


@pytest.fixture(scope="module")
def images() -> Iterator[ImageServer]:
    buffer = FrameBuffer()
    buffer.register_camera("R1/Down", 1)
    buffer.register_camera("R1/Marker", 2)
    buffer.publish(Frame("R1/Down", 1, 1, 0.0, np.zeros((48, 64, 3), np.uint8)))
    buffer.publish(Frame("R1/Marker", 2, 1, 0.0, np.full((24, 32, 3), 200, np.uint8)))
    with ImageServer(buffer, port=0) as server:
        yield server


IMAGE_SHAPED = st.lists(
    st.one_of(
        st.sampled_from(
            [b"OK", b"U", b"SKEYE ", b"FORMAT ", b"JPEG 50", b"PNG", b"RAW", b"META on", b"\n"]
        ),
        st.sampled_from([b"STREAM 30", b"CAMERA R1/Down", b"CAMERA nope", b"STREAM -1"]),
        st.binary(max_size=20),
    ),
    max_size=30,
).map(b"".join)
# Ends any half request: 17 newlines close a SubRect's 16 bytes and any SKEYE line.
MARKER = b"\n" * 17 + b"SKEYE STREAM 0\nSKEYE FORMAT RAW\nSKEYE META on\nSKEYE CAMERA R1/Marker\nOK"


def _image_roundtrip(port: int, data: bytes) -> list[object]:
    sock = socket.create_connection(("127.0.0.1", port), timeout=10)
    decoder = FrameDecoder()
    events: list[object] = []
    try:
        sock.sendall(data + MARKER)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            chunk = sock.recv(1 << 20)
            assert chunk, "server closed the connection"
            new = decoder.feed(chunk)
            events.extend(new)
            if any(
                isinstance(e, DecodedFrame) and e.meta is not None and e.meta.camera_id == 2
                for e in new
            ):
                return events
        raise AssertionError("no marker frame")
    finally:
        sock.close()


@FUZZ
@given(st.one_of(st.binary(max_size=3000), IMAGE_SHAPED))
def test_image_server_answers_random_bytes(images: ImageServer, data: bytes) -> None:
    events = _image_roundtrip(images.port, data)
    assert not any(isinstance(e, ProtocolViolation) for e in events)
    assert all(isinstance(e, DecodedFrame | RemoteError) for e in events)
    witness = _image_roundtrip(images.port, b"")
    assert len(witness) == 1
