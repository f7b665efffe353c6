"""The sans-IO image protocol codec: requests both ways, frames both ways, fuzzing."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skeye.errors import LocalProtocolError, RemoteProtocolError
from skeye.pixels import (
    encode_image,
    frame_image,
    frame_image_rgb,
    jpeg_payload,
    png_payload,
    raw_payload,
)
from skeye.wire.image_requests import (
    NewestFrame,
    NewestInfo,
    Request,
    RequestError,
    RequestParser,
    SelectCamera,
    SetFormat,
    SetMeta,
    SetPrerender,
    Stream,
    SubRect,
    encode_request,
)
from skeye.wire.images import (
    META_OFFSET,
    DecodedFrame,
    FrameDecoder,
    FrameType,
    ImageFormat,
    InfoFrame,
    MetaHeader,
    ProtocolViolation,
    RemoteError,
    encode_error_frame,
    encode_frame,
    encode_info_frame,
    jpeg_type_for_quality,
    meta_header,
)

# ------------------------------------------------------------------ requests, one table both ways

REQUEST_TABLE: list[tuple[Request, bytes]] = [
    (NewestFrame(), b"OK"),
    (SubRect(1, 2, 300, 400), b"U" + struct.pack(">IIII", 1, 2, 300, 400)),
    (SubRect(0, 0, 0xFFFFFFFF, 1), b"U\0\0\0\0\0\0\0\0\xff\xff\xff\xff\0\0\0\x01"),
    (SelectCamera("R1/Down"), b"SKEYE CAMERA R1/Down\n"),
    (SetFormat(ImageFormat.RAW), b"SKEYE FORMAT RAW\n"),
    (SetFormat(ImageFormat.JPEG, 85), b"SKEYE FORMAT JPEG 85\n"),
    (SetFormat(ImageFormat.PNG), b"SKEYE FORMAT PNG\n"),
    (SetMeta(True), b"SKEYE META on\n"),
    (SetMeta(False), b"SKEYE META off\n"),
    (SetPrerender(True), b"SKEYE PRERENDER on\n"),
    (SetPrerender(False), b"SKEYE PRERENDER off\n"),
    (NewestInfo(), b"SKEYE INFO\n"),
    (Stream(30.0), b"SKEYE STREAM 30.0\n"),
    (Stream(0.0), b"SKEYE STREAM 0.0\n"),
]


@pytest.mark.parametrize(("request_", "wire"), REQUEST_TABLE)
def test_request_table_both_ways(request_: Request, wire: bytes) -> None:
    assert encode_request(request_) == wire
    assert RequestParser().feed(wire) == [request_]
    parser = RequestParser()
    got: list[Request] = []
    for i in range(len(wire)):
        got += parser.feed(wire[i : i + 1])
    assert got == [request_]
    assert parser.buffered_bytes == 0


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        (b"SKEYE format jpeg 10\r\n", SetFormat(ImageFormat.JPEG, 10)),
        (b"SKEYE META ON\n", SetMeta(True)),
        (b"SKEYE prerender Off\r\n", SetPrerender(False)),
        (b"SKEYE info \r\n", NewestInfo()),
        (b"SKEYE STREAM 15\n", Stream(15.0)),
        (b"SKEYE  CAMERA   R2/Front \n", SelectCamera("R2/Front")),
    ],
)
def test_extension_lines_are_lenient_about_case_and_spacing(line: bytes, expected: Request) -> None:
    assert RequestParser().feed(line) == [expected]


@pytest.mark.parametrize(
    ("line", "reason_part"),
    [
        (b"SKEYE FROB 1\n", "unknown SKEYE command"),
        (b"SKEYE \n", "empty"),
        (b"SKEYE CAMERA\n", "CAMERA"),
        (b"SKEYE CAMERA a b\n", "CAMERA"),
        (b"SKEYE FORMAT JPEG\n", "FORMAT"),
        (b"SKEYE FORMAT JPEG 0\n", "1-100"),
        (b"SKEYE FORMAT JPEG 101\n", "1-100"),
        (b"SKEYE FORMAT JPEG x\n", "integer"),
        (b"SKEYE FORMAT RAW 5\n", "FORMAT"),
        (b"SKEYE FORMAT GIF\n", "FORMAT"),
        (b"SKEYE META maybe\n", "META"),
        (b"SKEYE PRERENDER\n", "PRERENDER on|off"),
        (b"SKEYE PRERENDER later\n", "PRERENDER on|off"),
        (b"SKEYE INFO now\n", "expected 'INFO'"),
        (b"SKEYE STREAM\n", "STREAM"),
        (b"SKEYE STREAM fast\n", "not a number"),
        (b"SKEYE STREAM -1\n", "0-1000"),
        (b"SKEYE STREAM nan\n", "0-1000"),
        (b"SKEYE STREAM inf\n", "0-1000"),
        (b"SKEYE CAMERA R\xc3\xa9/Down\n", "not ASCII"),
        (b"SKEYE CAMERA R1\x01x\n", "printable"),
    ],
)
def test_bad_extension_lines_give_request_errors(line: bytes, reason_part: str) -> None:
    (request,) = RequestParser().feed(line + b"OK")[:1]
    assert isinstance(request, RequestError)
    assert reason_part in request.reason
    assert RequestParser().feed(line + b"OK")[1:] == [NewestFrame()]


def test_bytes_forming_no_request_are_ignored() -> None:
    parser = RequestParser()
    assert parser.feed(b"hello\x00\xffOOKxK SKEYEX Sk OK") == [NewestFrame(), NewestFrame()]
    assert parser.buffered_bytes == 0


def test_partial_openings_wait_for_more_bytes() -> None:
    parser = RequestParser()
    assert parser.feed(b"O") == []
    assert parser.feed(b"K") == [NewestFrame()]
    assert parser.feed(b"SKEY") == []
    assert parser.feed(b"E META off") == []
    assert parser.feed(b"\n") == [SetMeta(False)]
    assert parser.feed(b"U\0\0\0") == []
    assert parser.feed(b"\x01" + b"\0" * 11 + b"\x02") == [SubRect(1, 0, 0, 2)]


def test_over_long_line_is_an_error_and_discarded_up_to_its_newline() -> None:
    parser = RequestParser(max_line_bytes=64)
    got = parser.feed(b"SKEYE CAMERA " + b"A" * 100)
    assert len(got) == 1 and isinstance(got[0], RequestError)
    assert "longer than 64" in got[0].reason
    assert parser.buffered_bytes <= 64
    assert parser.feed(b"OK" + b"B" * 1000) == []  # still inside the long line
    assert parser.buffered_bytes == 0
    assert parser.feed(b"\nOK") == [NewestFrame()]


def test_a_line_exactly_at_the_limit_is_accepted() -> None:
    line = b"SKEYE CAMERA " + b"x" * (64 - len(b"SKEYE CAMERA ") - 1) + b"\n"
    assert len(line) == 64
    assert RequestParser(max_line_bytes=64).feed(line) == [SelectCamera("x" * 50)]


def test_invalid_requests_cannot_be_built() -> None:
    with pytest.raises(LocalProtocolError, match="uint32"):
        SubRect(-1, 0, 1, 1)
    with pytest.raises(LocalProtocolError, match="1-100"):
        SetFormat(ImageFormat.JPEG, 0)
    with pytest.raises(LocalProtocolError, match="quality"):
        SetFormat(ImageFormat.JPEG)
    with pytest.raises(LocalProtocolError, match="no quality"):
        SetFormat(ImageFormat.PNG, 50)
    with pytest.raises(LocalProtocolError, match="frames/s"):
        Stream(-1.0)
    with pytest.raises(LocalProtocolError, match="camera name"):
        SelectCamera("R1 Down")
    with pytest.raises(LocalProtocolError):
        encode_request(RequestError("x"))


_NO_OPENINGS = st.binary(max_size=40).map(
    lambda b: bytes(c for c in b if c not in b"OUS\n")
)  # garbage that cannot start or end a request

requests_st: st.SearchStrategy[Request] = st.one_of(
    st.just(NewestFrame()),
    st.builds(SubRect, *(st.integers(0, 0xFFFFFFFF) for _ in range(4))),
    st.builds(SelectCamera, st.from_regex(r"[!-~]{1,40}", fullmatch=True)),
    st.builds(SetFormat, st.just(ImageFormat.JPEG), st.integers(1, 100)),
    st.sampled_from([SetFormat(ImageFormat.RAW), SetFormat(ImageFormat.PNG)]),
    st.builds(SetMeta, st.booleans()),
    st.builds(SetPrerender, st.booleans()),
    st.just(NewestInfo()),
    st.builds(Stream, st.floats(0.0, 1000.0)),
)


@given(st.lists(st.tuples(_NO_OPENINGS, requests_st), max_size=8), st.data())
def test_requests_round_trip_with_garbage_between(
    items: list[tuple[bytes, Request]], data: st.DataObject
) -> None:
    wire = b"".join(garbage + encode_request(req) for garbage, req in items)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(wire)), max_size=6)))
    parser = RequestParser()
    got: list[Request] = []
    for start, end in zip([0, *cuts], [*cuts, len(wire)], strict=True):
        got += parser.feed(wire[start:end])
    assert got == [req for _, req in items]


@settings(max_examples=300)
@given(st.binary(max_size=600), st.data())
def test_parser_fuzz_gives_requests_only_and_ignores_splits(
    blob: bytes, data: st.DataObject
) -> None:
    whole_parser = RequestParser(max_line_bytes=128)
    whole = whole_parser.feed(blob)
    assert all(
        isinstance(
            r, NewestFrame | SubRect | NewestInfo | SelectCamera | SetFormat | SetMeta
            | SetPrerender | Stream | RequestError
        )
        for r in whole
    )
    assert whole_parser.buffered_bytes <= 128
    cuts = sorted(data.draw(st.lists(st.integers(0, len(blob)), max_size=8)))
    parser = RequestParser(max_line_bytes=128)
    pieces: list[Request] = []
    for start, end in zip([0, *cuts], [*cuts, len(blob)], strict=True):
        pieces += parser.feed(blob[start:end])
    assert pieces == whole


# ------------------------------------------------------------------ frames


@pytest.mark.parametrize(
    ("quality", "frame_type"),
    [(100, 1), (90, 1), (89, 2), (75, 2), (74, 3), (50, 3), (49, 4), (25, 4), (24, 5), (1, 5)],
)
def test_jpeg_quality_bands(quality: int, frame_type: int) -> None:
    assert jpeg_type_for_quality(quality) == frame_type


@pytest.mark.parametrize("quality", [0, 101, -5, 50.0, True])
def test_jpeg_quality_out_of_range_is_refused(quality: object) -> None:
    with pytest.raises(LocalProtocolError, match="1-100"):
        jpeg_type_for_quality(quality)  # type: ignore[arg-type]


def test_raw_payload_layout_is_upis() -> None:
    # 2x5 image: 15 bytes per row, padded to 16. Pixels in B, G, R order, rows top to bottom.
    rgb = np.arange(2 * 5 * 3, dtype=np.uint8).reshape(2, 5, 3)
    payload = raw_payload(rgb)
    expected = struct.pack(">HH", 5, 2)
    for row in range(2):
        for col in range(5):
            r, g, b = rgb[row, col]
            expected += bytes([b, g, r])
        expected += b"\0"
    assert payload == expected
    frame = encode_frame(FrameType.RAW, payload)
    assert frame[:5] == b"\x00" + struct.pack(">I", 4 + 2 * 16)  # size counts the prefix


def test_meta_header_layout() -> None:
    head = meta_header(7, 1.25, 3, 800, 600)
    assert head == struct.pack(">IdIII", 7, 1.25, 3, 800, 600)
    assert len(head) == 24
    assert MetaHeader.unpack(head) == MetaHeader(7, 1.25, 3, 800, 600)


@pytest.mark.parametrize(
    "bad",
    [
        np.zeros((4, 4), np.uint8),
        np.zeros((4, 4, 4), np.uint8),
        np.zeros((4, 4, 3), np.float32),
        np.zeros((0, 4, 3), np.uint8),
    ],
)
def test_bad_images_are_refused(bad: np.ndarray) -> None:
    with pytest.raises(LocalProtocolError, match="image"):
        raw_payload(bad)
    with pytest.raises(LocalProtocolError, match="image"):
        png_payload(bad)


def test_raw_side_limit() -> None:
    with pytest.raises(LocalProtocolError, match="65535"):
        raw_payload(np.zeros((1, 65536, 3), np.uint8))


@pytest.mark.parametrize("frame_type", [7, 14, 23, 31, 100, 254, 256, -1])
def test_unknown_frame_types_cannot_be_encoded(frame_type: int) -> None:
    with pytest.raises(LocalProtocolError, match="frame type"):
        encode_frame(frame_type, b"")


def _image(height: int, width: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)


def _smooth(height: int, width: int, color: tuple[int, int, int]) -> np.ndarray:
    img = np.empty((height, width, 3), np.uint8)
    img[...] = color
    return img


metas = st.builds(
    MetaHeader,
    st.integers(0, 0xFFFFFFFF),
    st.floats(allow_nan=False, allow_infinity=False),  # a moment: finite (protocol)
    st.integers(0, 0xFFFFFFFF),
    st.just(0),
    st.just(0),
)


@given(
    st.integers(1, 12),
    st.integers(1, 12),
    st.integers(0, 2**32 - 1),
    st.sampled_from([ImageFormat.RAW, ImageFormat.PNG]),
    st.none() | metas,
)
def test_lossless_frames_round_trip(
    height: int, width: int, seed: int, kind: ImageFormat, meta: MetaHeader | None
) -> None:
    rgb = _image(height, width, seed)
    base, payload = encode_image(rgb, kind, None)
    wire_type, body = int(base), payload
    if meta is not None:
        meta = MetaHeader(meta.frame_number, meta.sim_time_s, meta.camera_id, width, height)
        wire_type += META_OFFSET
        body = meta.pack() + payload
    (event,) = FrameDecoder().feed(encode_frame(wire_type, body))
    assert isinstance(event, DecodedFrame)
    assert event.frame_type == base and event.wire_type == wire_type
    assert event.meta == meta
    assert event.data == payload
    assert np.array_equal(frame_image_rgb(event), rgb)
    assert np.array_equal(frame_image(event), rgb[:, :, ::-1])


@given(
    st.integers(8, 40),
    st.integers(8, 40),
    st.tuples(st.integers(0, 255), st.integers(0, 255), st.integers(0, 255)),
    st.integers(1, 100),
    st.booleans(),
)
def test_jpeg_frames_round_trip_close(
    height: int, width: int, color: tuple[int, int, int], quality: int, with_meta: bool
) -> None:
    rgb = _smooth(height, width, color)
    base, payload = encode_image(rgb, ImageFormat.JPEG, quality)
    assert base == jpeg_type_for_quality(quality)
    wire_type, body = int(base), payload
    if with_meta:
        wire_type += META_OFFSET
        body = meta_header(1, 0.5, 2, width, height) + payload
    (event,) = FrameDecoder().feed(encode_frame(wire_type, body))
    assert isinstance(event, DecodedFrame)
    assert event.frame_type == base
    decoded = frame_image_rgb(event).astype(int)
    assert decoded.shape == rgb.shape
    # Flat colours survive JPEG closely at usable qualities (chroma subsampling, quantisation).
    tolerance = 12 if quality >= 50 else 48
    assert np.abs(decoded - rgb.astype(int)).max() <= tolerance


@given(st.text(max_size=200))
def test_error_frames_round_trip(reason: str) -> None:
    assert FrameDecoder().feed(encode_error_frame(reason)) == [RemoteError(reason)]


def test_error_frame_with_bad_utf8_is_still_an_event() -> None:
    (event,) = FrameDecoder().feed(encode_frame(FrameType.ERROR, b"bad \xff"))
    assert isinstance(event, RemoteError) and event.reason.startswith("bad ")


def test_frames_decode_one_byte_at_a_time() -> None:
    rgb = _image(3, 5, 1)
    wire = (
        encode_frame(FrameType.RAW, raw_payload(rgb))
        + encode_error_frame("nope")
        + encode_frame(FrameType.PNG + META_OFFSET, meta_header(4, 2.0, 1, 5, 3) + png_payload(rgb))
        + encode_info_frame(MetaHeader(5, 2.5, 1, 5, 3))
    )
    decoder = FrameDecoder()
    events = []
    for i in range(len(wire)):
        events += decoder.feed(wire[i : i + 1])
    assert [type(e) for e in events] == [DecodedFrame, RemoteError, DecodedFrame, InfoFrame]
    assert isinstance(events[2], DecodedFrame) and events[2].meta == MetaHeader(4, 2.0, 1, 5, 3)
    assert events[3] == InfoFrame(MetaHeader(5, 2.5, 1, 5, 3))


def test_an_info_frame_is_type_15_and_the_meta_header_alone() -> None:
    wire = encode_info_frame(MetaHeader(7, 1.25, 3, 800, 600))
    assert wire == b"\x0f" + struct.pack(">I", 24) + struct.pack(">IdIII", 7, 1.25, 3, 800, 600)


@pytest.mark.parametrize(
    ("wire", "reason_part"),
    [
        (b"\x07\0\0\0\0", "unknown frame type"),
        (b"NFO {Gametype skeye}", "'N': text, as the simulator's control port sends"),
        (b"\x00\x04\x00\x00\x01", "exceeds"),  # 64 MiB + 1
        (b"\x00\0\0\0\x02ab", "shorter than its 4-byte prefix"),
        (b"\x00\0\0\0\x05" + struct.pack(">HH", 1, 1) + b"x", "needs 8 bytes"),
        (b"\x10\0\0\0\x03abc", "shorter than its 24-byte header"),
        (b"\x0f\0\0\0\x17" + meta_header(1, 0.0, 0, 2, 1)[:23], "not a 24-byte META header"),
        (b"\x0f\0\0\0\x19" + meta_header(1, 0.0, 0, 2, 1) + b"x", "not a 24-byte META header"),
        (
            b"\x10\0\0\0\x20" + meta_header(1, 0.0, 0, 2, 1) + struct.pack(">HH", 1, 1) + b"\0" * 4,
            "META says 2x1",
        ),
        # A NaN or infinite sim time was passed on as a frame's capture time (the pilot's
        # sim:// camera hands it to the vision as it is).
        (b"\x10\0\0\0\x20" + meta_header(1, float("nan"), 0, 1, 1) + struct.pack(">HH", 1, 1)
         + b"\0" * 4, "META header's sim time is nan"),
        (b"\x16\0\0\0\x1b" + meta_header(1, float("inf"), 0, 1, 1) + b"png",
         "META header's sim time is inf"),
        (b"\x0f\0\0\0\x18" + meta_header(1, float("-inf"), 0, 2, 1),
         "INFO frame's sim time is -inf"),
    ],
)
def test_bad_frames_are_protocol_violations(wire: bytes, reason_part: str) -> None:
    decoder = FrameDecoder()
    (event,) = decoder.feed(wire)
    assert isinstance(event, ProtocolViolation)
    assert reason_part in event.reason
    assert decoder.failure == event.reason
    assert decoder.feed(encode_error_frame("later")) == []  # a broken stream stays broken


def test_oversized_frame_is_refused_from_its_header_alone() -> None:
    decoder = FrameDecoder(max_frame_bytes=1000)
    (event,) = decoder.feed(b"\x06" + struct.pack(">I", 1001))
    assert isinstance(event, ProtocolViolation)


def test_undecodable_image_data_raises_remote_protocol_error() -> None:
    (event,) = FrameDecoder().feed(encode_frame(FrameType.JPEG_GOOD, b"not a jpeg"))
    assert isinstance(event, DecodedFrame)
    with pytest.raises(RemoteProtocolError, match="does not decode"):
        frame_image(event)
    wrong_size = encode_frame(
        FrameType.PNG + META_OFFSET, meta_header(1, 0.0, 0, 9, 9) + png_payload(_image(2, 2, 0))
    )
    (event,) = FrameDecoder().feed(wrong_size)
    assert isinstance(event, DecodedFrame)
    with pytest.raises(RemoteProtocolError, match="META says 9x9"):
        frame_image(event)


@pytest.mark.parametrize("ext", [".png", ".jpg"])
def test_an_image_declaring_too_many_pixels_is_not_decoded(ext: str) -> None:
    """A PNG of 9000x8000 black pixels is 73 KB on the wire and 216 MB of BGR; one of
    30000x30000 (900 KB) made skeye snapshot take 5.3 GB. The size in the file's header is
    checked before decoding: over 8192x8192 (the simulator's largest camera) is refused."""
    import cv2

    ok, buf = cv2.imencode(ext, np.zeros((8000, 9000), np.uint8))
    assert ok
    base = FrameType.PNG if ext == ".png" else FrameType.JPEG_SUPER
    (event,) = FrameDecoder().feed(encode_frame(base, buf.tobytes()))
    assert isinstance(event, DecodedFrame)
    with pytest.raises(RemoteProtocolError, match=r"declares 9000x8000 px, over the 67108864"):
        frame_image(event)


def test_an_image_frame_must_hold_its_own_format() -> None:
    """A PNG frame holding a JPEG (or a BMP, a TIFF...) was decoded by whatever OpenCV
    recognised, a way around the size check; it is refused naming the format expected."""
    jpeg = jpeg_payload(_smooth(8, 8, (1, 2, 3)), 80)
    (event,) = FrameDecoder().feed(encode_frame(FrameType.PNG, jpeg))
    assert isinstance(event, DecodedFrame)
    with pytest.raises(RemoteProtocolError, match="does not decode: no PNG header"):
        frame_image(event)
    (event,) = FrameDecoder().feed(encode_frame(FrameType.JPEG_BAD, png_payload(_image(8, 8, 3))))
    assert isinstance(event, DecodedFrame)
    with pytest.raises(RemoteProtocolError, match="does not decode: no JPEG header"):
        frame_image(event)


def test_jpeg_payload_is_a_jpeg_file() -> None:
    data = jpeg_payload(_smooth(8, 8, (10, 20, 30)), 80)
    assert data[:2] == b"\xff\xd8" and data[-2:] == b"\xff\xd9"
    assert png_payload(_smooth(8, 8, (1, 2, 3)))[:8] == b"\x89PNG\r\n\x1a\n"


@settings(max_examples=300)
@given(st.binary(max_size=400), st.data())
def test_decoder_fuzz_gives_events_only_and_ignores_splits(
    blob: bytes, data: st.DataObject
) -> None:
    whole = FrameDecoder(max_frame_bytes=4096).feed(blob)
    assert all(isinstance(e, DecodedFrame | InfoFrame | RemoteError | ProtocolViolation)
               for e in whole)
    assert sum(isinstance(e, ProtocolViolation) for e in whole) <= 1
    cuts = sorted(data.draw(st.lists(st.integers(0, len(blob)), max_size=8)))
    decoder = FrameDecoder(max_frame_bytes=4096)
    pieces = []
    for start, end in zip([0, *cuts], [*cuts, len(blob)], strict=True):
        pieces += decoder.feed(blob[start:end])
    assert pieces == whole
    for event in whole:  # decoding the image may refuse, but only with our error
        if isinstance(event, DecodedFrame):
            try:
                frame_image(event)
            except RemoteProtocolError:
                pass


@given(st.sampled_from([*range(0, 7), 15, *range(16, 23), 255]), st.binary(max_size=64))
def test_frame_type_and_size_survive_any_payload(frame_type: int, payload: bytes) -> None:
    wire = encode_frame(frame_type, payload)
    assert wire[0] == frame_type
    assert struct.unpack(">I", wire[1:5])[0] == len(payload)
    events = FrameDecoder().feed(wire)
    assert len(events) == 1


def test_an_empty_compressed_frame_is_a_protocol_error():
    from skeye.errors import RemoteProtocolError
    from skeye.wire.images import FrameDecoder, FrameType, encode_frame

    for kind in (FrameType.PNG, FrameType.JPEG_GOOD):
        (frame,) = FrameDecoder().feed(encode_frame(kind, b""))
        with pytest.raises(RemoteProtocolError, match="no image data"):
            frame_image(frame)
