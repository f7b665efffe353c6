"""The video protocol's codec and states (skeye.wire.video), both ways from one table."""

from __future__ import annotations

import json
import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skeye.errors import LocalProtocolError, RemoteProtocolError
from skeye.wire.video import (
    BY_CLASS,
    CODECS,
    MAGIC,
    MAX_CLIENT_HEADER_BYTES,
    PREFIX,
    TRANSITIONS,
    VERSION,
    Detection,
    Error,
    Frame,
    Hello,
    Message,
    MsgType,
    RingEllipse,
    Role,
    State,
    Subscribe,
    VideoConnection,
    VideoDecoder,
    encode,
)

finite = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6)
pairs = st.tuples(finite, finite)
angles = st.floats(min_value=-math.pi, max_value=math.pi)
ellipses = st.builds(RingEllipse, st.integers(1, 4), st.sampled_from(["outer", "inner"]), pairs,
                     pairs, finite)
found = st.builds(
    Detection, st.just(True), pairs, st.floats(0, 100), pairs, pairs,
    st.lists(st.integers(1, 4), max_size=4).map(tuple),
    st.lists(ellipses, max_size=8).map(tuple), st.floats(0, 1),
    st.none() | angles, st.none() | angles,
)
not_found = st.builds(Detection, st.just(False), quality=st.floats(0, 1))
jpegs = st.binary(max_size=200).map(lambda b: b"\xff\xd8" + b)
frames = st.builds(Frame, st.integers(0, 2**40), st.floats(0, 1e6), st.integers(1, 4000),
                   st.integers(1, 4000), found | not_found, st.floats(0, 1e4), jpegs)
texts = st.text(max_size=100)
messages: st.SearchStrategy[Message] = st.one_of(
    st.builds(Subscribe, st.floats(0.01, 1000)),
    st.builds(Hello, texts, st.floats(1e-6, math.pi), st.integers(1, 100), st.floats(0.01, 1000)),
    frames,
    st.builds(Error, st.text(max_size=500)),
)


def test_one_codec_per_message_type_and_class() -> None:
    assert {c.mtype for c in CODECS} == set(MsgType)
    assert set(BY_CLASS) == {Subscribe, Hello, Frame, Error}


@settings(deadline=None)  # a busy machine: no wall-clock deadline per example
@given(messages)
def test_every_message_round_trips(msg: Message) -> None:
    assert VideoDecoder().feed(encode(msg)) == [msg]


@settings(deadline=None)
@given(st.lists(messages, min_size=1, max_size=4), st.integers(1, 50))
def test_a_stream_in_any_pieces_gives_the_same_messages(msgs: list[Message], piece: int) -> None:
    data = b"".join(encode(m) for m in msgs)
    decoder = VideoDecoder()
    got: list[Message] = []
    for i in range(0, len(data), piece):
        got += decoder.feed(data[i:i + piece])
    assert got == msgs and decoder.buffered == 0


def test_one_byte_at_a_time() -> None:
    msg = Frame(7, 1.25, 320, 240, Detection(False), 3.5, b"\xff\xd8jpeg")
    decoder = VideoDecoder()
    data = encode(msg)
    got = [m for b in data for m in decoder.feed(bytes([b]))]
    assert got == [msg]


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_arbitrary_bytes_give_messages_or_a_protocol_error(data: bytes) -> None:
    try:
        VideoDecoder().feed(data)
    except RemoteProtocolError:
        pass


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(list(MsgType)), st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=10),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
        st.sampled_from(["found", "max_fps", "camera", "fov_h_rad", "jpeg_quality", "reason",
                         "frame_number", "time_s", "width", "height", "detect_ms", "detection",
                         "center_px", "height_m", "rings", "ellipses", "quality", "ring",
                         "border", "semi_axes_px", "angle_rad", "offset_cam_m",
                         "offset_body_m"]), inner, max_size=8),
    max_leaves=30), st.binary(max_size=20))
def test_arbitrary_json_headers_give_messages_or_a_protocol_error(
    mtype: MsgType, obj: object, payload: bytes
) -> None:
    """Well-framed garbage: every field of every type with wrong types and values."""
    header = json.dumps(obj).encode()
    data = PREFIX.pack(MAGIC, VERSION, mtype, len(header), len(payload)) + header + payload
    for role in Role:
        try:
            VideoDecoder().feed(data)
            VideoConnection(role).receive_data(data)
        except RemoteProtocolError:
            pass


def _raw(mtype: int, header: bytes, payload: bytes = b"") -> bytes:
    return PREFIX.pack(MAGIC, VERSION, mtype, len(header), len(payload)) + header + payload


@pytest.mark.parametrize("data, words", [
    (b"GET / HTTP/1.1\r\n\r\n", "not a skeye video stream"),
    (PREFIX.pack(MAGIC, 9, 1, 2, 0) + b"{}", "version 9"),
    (PREFIX.pack(MAGIC, VERSION, 99, 2, 0) + b"{}", "unknown video message type 99"),
    (PREFIX.pack(MAGIC, VERSION, 4, 2**31, 0), "header of 2147483648 bytes"),
    (PREFIX.pack(MAGIC, VERSION, 2, 2, 2**31), "payload of 2147483648 bytes"),
    (_raw(4, b"{x}"), "not UTF-8 JSON"),
    (_raw(4, b"[]"), "not a JSON object"),
    (_raw(4, b'{"max_fps":NaN}'), "NaN is not allowed"),
    (_raw(4, b'{"max_fps":"fast"}'), "max_fps must be a number"),
    (_raw(4, b'{"max_fps":0}'), "max_fps must be in"),
    (PREFIX.pack(MAGIC, VERSION, 3, 2, 1) + b"{}x", "ERROR carries no payload"),
])
def test_bad_bytes_are_named(data: bytes, words: str) -> None:
    with pytest.raises(RemoteProtocolError, match=words):
        VideoDecoder().feed(data)


def test_a_frame_must_be_jpeg_and_detections_consistent() -> None:
    with pytest.raises(LocalProtocolError, match="JPEG"):
        Frame(1, 0.0, 10, 10, Detection(False), 0.0, b"\x89PNG")
    with pytest.raises(LocalProtocolError, match="found pad needs"):
        Detection(True, center_px=(1.0, 2.0))
    with pytest.raises(LocalProtocolError, match="no figures"):
        Detection(False, height_m=1.0)
    with pytest.raises(LocalProtocolError, match="quality"):
        Detection(False, quality=2.0)
    with pytest.raises(LocalProtocolError, match="jpeg_quality"):
        Hello("R1/Down", 1.0, 101, 10.0)
    header = json.dumps({"frame_number": 1, "time_s": 0.0, "width": 4, "height": 4,
                         "detect_ms": 1.0, "detection": {"found": False}}).encode()
    data = PREFIX.pack(MAGIC, VERSION, MsgType.FRAME, len(header), 3) + header + b"GIF"
    with pytest.raises(RemoteProtocolError, match="bad FRAME: frame jpeg must be JPEG"):
        VideoDecoder().feed(data)


def test_huge_numbers_are_refused_cleanly() -> None:
    header = b'{"max_fps":' + b"9" * 400 + b"}"
    data = PREFIX.pack(MAGIC, VERSION, MsgType.SUBSCRIBE, len(header), 0) + header
    with pytest.raises(RemoteProtocolError, match="max_fps must be a finite number"):
        VideoDecoder().feed(data)


# -- states ----------------------------------------------------------------------------------
def _session() -> tuple[VideoConnection, VideoConnection]:
    return VideoConnection(Role.SERVER), VideoConnection(Role.CLIENT)


def test_a_session_goes_subscribe_hello_frames() -> None:
    server, client = _session()
    assert server.receive_data(client.send(Subscribe(5.0))) == [Subscribe(5.0)]
    assert client.state is server.state is State.WAIT_HELLO
    hello = Hello("R1/Down", 1.309, 80, 10.0)
    assert client.receive_data(server.send(hello)) == [hello]
    frame = Frame(3, 0.3, 8, 6, Detection(False), 1.0, b"\xff\xd8")
    assert client.receive_data(server.send(frame) * 2) == [frame, frame]
    assert server.receive_data(client.send(Subscribe(2.0))) == [Subscribe(2.0)]  # a new rate
    assert client.receive_data(server.send(Error("bye"))) == [Error("bye")]
    assert client.state is server.state is State.CLOSED


def test_every_pair_outside_the_table_is_refused() -> None:
    samples: dict[MsgType, Message] = {
        MsgType.SUBSCRIBE: Subscribe(1.0),
        MsgType.HELLO: Hello("c", 1.0, 80, 1.0),
        MsgType.FRAME: Frame(0, 0.0, 1, 1, Detection(False), 0.0, b"\xff\xd8"),
        MsgType.ERROR: Error("x"),
    }
    sender = {MsgType.SUBSCRIBE: Role.CLIENT, MsgType.HELLO: Role.SERVER,
              MsgType.FRAME: Role.SERVER, MsgType.ERROR: Role.SERVER}
    for state in State:
        for mtype, msg in samples.items():
            receiver = VideoConnection(Role.SERVER if sender[mtype] is Role.CLIENT
                                       else Role.CLIENT)
            receiver.state = state
            if (state, mtype) in TRANSITIONS:
                receiver.receive_data(encode(msg))
                assert receiver.state is TRANSITIONS[(state, mtype)]
            else:
                with pytest.raises(RemoteProtocolError):
                    receiver.receive_data(encode(msg))


def test_a_client_may_not_send_frames_nor_a_server_subscribe() -> None:
    server, client = _session()
    frame = Frame(0, 0.0, 1, 1, Detection(False), 0.0, b"\xff\xd8")
    with pytest.raises(LocalProtocolError, match="client does not send FRAME"):
        client.send(frame)
    with pytest.raises(RemoteProtocolError, match="payload of 2 bytes, over 0"):
        server.receive_data(encode(frame))  # refused from the prefix, before its bytes
    with pytest.raises(LocalProtocolError, match="server does not send SUBSCRIBE"):
        server.send(Subscribe(1.0))
    with pytest.raises(LocalProtocolError, match="HELLO is not allowed in state wait-subscribe"):
        server.send(Hello("c", 1.0, 80, 1.0))


def test_a_server_refuses_long_client_headers_before_reading_them() -> None:
    server = VideoConnection(Role.SERVER)
    prefix = PREFIX.pack(MAGIC, VERSION, MsgType.SUBSCRIBE, MAX_CLIENT_HEADER_BYTES + 1, 0)
    with pytest.raises(RemoteProtocolError, match="header of 1025 bytes"):
        server.receive_data(prefix)


def test_the_prefix_is_as_documented() -> None:
    data = encode(Subscribe(8.0))
    magic, version, mtype, hlen, plen = struct.unpack(">2sBBII", data[:12])
    assert (magic, version, mtype, plen) == (b"SV", 1, 4, 0)
    assert json.loads(data[12:12 + hlen]) == {"max_fps": 8.0}
