"""Tests of the vehicle packet codec (docs/protocols/packets.md): one table both ways, fuzz."""

from __future__ import annotations

import dataclasses
import itertools
import struct
from dataclasses import fields
from enum import IntEnum
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from skeye.errors import LocalProtocolError
from skeye.wire.crc import command_checksum, crc16
from skeye.wire.packet_defs import LAYOUTS, FrameKind
from skeye.wire.packets import (
    ACK_PDS,
    PD,
    Ack,
    Clock,
    ComeHome,
    CommandError,
    CommandStreamParser,
    ControllerOutput,
    CtrlInput,
    CurrentWay,
    EndFlight,
    ErrorKind,
    FrameError,
    GotoGps,
    GpsData,
    GpsDataAdvanced,
    Health,
    HealthStatus,
    Hold,
    ImuCalcData,
    ImuRawData,
    Land,
    Launch,
    LlStatus,
    Message,
    MoveBy,
    MoveFrame,
    NavState,
    NavStatus,
    PadAction,
    PadMode,
    PadReport,
    Poll,
    PollMask,
    RcData,
    Reset,
    Result,
    ResultCode,
    SkeyeMask,
    Stream,
    TakeOff,
    Truth,
    VehicleInfo,
    VehicleStreamParser,
    Velocity,
    Waypoint,
    WaypointGoto,
    arrived_intact,
    encode,
)

# --- independent wire builders (the test's own packing, not the codec's table) --------------


def crc_reference(data: bytes) -> int:
    """Bit-by-bit reflected CCITT (0x8408), init 0x00FF: independent of the byte-wise form."""
    crc = 0x00FF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
    return crc


def raw_vframe(pd: int, payload: bytes, start: bytes = b">*>") -> bytes:
    return (
        start
        + struct.pack("<HB", len(payload), pd)
        + payload
        + struct.pack("<H", crc_reference(payload))
        + b"<#<"
    )


def vframe(pd: int, fmt: str, *values: Any, start: bytes = b">*>") -> bytes:
    return raw_vframe(pd, struct.pack("<" + fmt, *values), start)


def sframe(pd: int, fmt: str, *values: Any) -> bytes:
    return vframe(pd, fmt, *values, start=b">*>s")


IMU_CALC = ImuCalcData(
    angle_nick=-5000, angle_roll=10000, angle_yaw=270000,
    angvel_nick=-100, angvel_roll=200, angvel_yaw=-300,
    acc_x_calib=-123, acc_y_calib=45, acc_z_calib=-10000,
    acc_x=1, acc_y=-2, acc_z=3,
    acc_angle_nick=-4900, acc_angle_roll=10100, acc_absolute_value=10010,
    Hx=100, Hy=-200, Hz=300, mag_heading=269000,
    speed_x=1500, speed_y=-250, speed_z=-100,
    height=2500, dheight=100, dheight_reference=90, height_reference=2450,
)  # fmt: skip
GPS_VALUES = (473977400, 85455900, 480000, -120, 340, 90000, 2500, 4000, 300, 9, 3)
GPS = GpsData(*GPS_VALUES)
GPS_ADV = GpsDataAdvanced(*GPS_VALUES, 473977410, 85455910, -118, 338)
WAYPOINT = Waypoint(
    properties=0x01 | 0x02 | 0x04, max_speed=50, time=300, pos_acc=2500,
    X=85455900, Y=473977400, yaw=90000, height=10000,
)  # fmt: skip
WAYPOINT_SUM = (0xAAAA + 90000 + 10000 + 300 + 85455900 + 473977400 + 50 + 2500 + 7 + 1) & 0xFFFF

# (message, expected wire bytes). The first four are written out by hand.
CASES: list[tuple[Message, bytes]] = [
    (Poll(PollMask.LL_STATUS | PollMask.IMU_CALCDATA), b">*>p\x05\x00"),
    (
        CtrlInput(pitch=100, roll=-200, yaw=0, thrust=2000, ctrl=0x0F),
        # 100 + -200 + 0 + 2000 + 15 + 0xAAAA = 0xB225
        bytes.fromhex("3e2a3e6469 6400 38ff 0000 d007 0f00 25b2"),
    ),
    (Ack(PD.WAYPOINT), b">a$a<"),
    (
        Result(0x83, ResultCode.REFUSED, "no"),
        bytes.fromhex("3e2a3e 0400 92 83046e6f a4ca 3c233c"),
    ),
    (Land(), bytes.fromhex("3e2a3e73 0000 84 ff00 3c233c")),  # CRC of nothing = init 0x00FF
    (Hold(), bytes.fromhex("3e2a3e73 0000 85 ff00 3c233c")),
    (Reset(), bytes.fromhex("3e2a3e73 0000 88 ff00 3c233c")),
    (WaypointGoto(), b">*>wg"),
    (Launch(), b">*>wl"),
    (EndFlight(), b">*>we"),
    (ComeHome(), b">*>wh"),
    (
        Waypoint(properties=0, max_speed=100, time=0, pos_acc=0, X=0, Y=0, yaw=0, height=0),
        b">*>ws" + struct.pack("<BBHBBHHHiiii", 1, 0, 0, 0, 100, 0, 0, 0xAAAA + 101, 0, 0, 0, 0),
    ),
    (
        WAYPOINT,
        b">*>ws"
        + struct.pack(
            "<BBHBBHHHiiii",
            1,
            0,
            0,
            7,
            50,
            300,
            2500,
            WAYPOINT_SUM,
            85455900,
            473977400,
            90000,
            10000,
        ),
    ),
    (
        LlStatus(12100, 0, 3, 1002, 1, 0, 1, 1, 7, 345),
        vframe(0x02, "hhhhBBBBhh", 12100, 0, 3, 1002, 1, 0, 1, 1, 7, 345),
    ),
    (
        ImuRawData(101325, 1, -2, 3, 400, -500, 600, -7, 8, -9, 2500, 70000),
        vframe(0x01, "ihhhhhhhhhHI", 101325, 1, -2, 3, 400, -500, 600, -7, 8, -9, 2500, 70000),
    ),
    (
        IMU_CALC,
        vframe(
            0x03,
            "iiiiiihhhhhhiiiiiiiiiiiiii",
            *(getattr(IMU_CALC, f.name) for f in fields(IMU_CALC)),
        ),
    ),
    (
        RcData(tuple(range(2000, 2008)), (0, 4095, 1, 2, 3, 4, 5, 6), 1),
        vframe(0x15, "8H8HB", *range(2000, 2008), 0, 4095, 1, 2, 3, 4, 5, 6, 1),
    ),
    (ControllerOutput(-10, 20, -30, 200), vframe(0x11, "iiii", -10, 20, -30, 200)),
    (GPS, vframe(0x23, "iiiiiiIIIIi", *GPS_VALUES)),
    (GPS_ADV, vframe(0x29, "iiiiiiIIIIiiiii", *GPS_VALUES, 473977410, 85455910, -118, 338)),
    (
        CurrentWay(0, 7, 1, 1, 0, 2, 0, 0x05, 123),
        vframe(0x21, "BBHBBBBHH", 0, 7, 1, 1, 0, 2, 0, 0x05, 123),
    ),
    (Velocity(500, -250, -100, 300, 2000), sframe(0x80, "hhhhH", 500, -250, -100, 300, 2000)),
    (
        MoveBy(1000, -2000, 300, 45000, MoveFrame.WORLD_NED, 500),
        sframe(0x81, "iiiiBH", 1000, -2000, 300, 45000, 1, 500),
    ),
    (
        GotoGps(473977400, 85455900, 5000, 1500),
        sframe(0x82, "iiiH", 473977400, 85455900, 5000, 1500),
    ),
    (TakeOff(1500), sframe(0x83, "i", 1500)),
    (PadMode(PadAction.LAND, 100, 300), sframe(0x86, "BHH", 2, 100, 300)),
    (Clock(123456), sframe(0x8E, "I", 123456)),
    (
        Stream(PollMask.IMU_CALCDATA | PollMask.GPS_DATA, SkeyeMask.NAV_STATUS | SkeyeMask.PAD, 50),
        sframe(0x87, "HHH", 0x84, 3, 50),
    ),
    (
        NavStatus(
            NavState.FLYING, PadAction.HOLD, 1000, -2000, -1500, 90000, 10, -20, 30, 11800, 123456
        ),
        vframe(0x90, "BBiiiihhhHIHH", 2, 1, 1000, -2000, -1500, 90000, 10, -20, 30, 11800, 123456,
               0, 0),
    ),
    (  # with the estimate's 1-sigma: 45 mm horizontal, 12 mm vertical
        NavStatus(NavState.LANDED, PadAction.OFF, 1, 2, 3, 4, 0, 0, 0, 11800, 7000, 45, 12),
        vframe(0x90, "BBiiiihhhHIHH", 0, 0, 1, 2, 3, 4, 0, 0, 0, 11800, 7000, 45, 12),
    ),
    (
        VehicleInfo(1, "R1 in pad at sim://127.0.0.1:3000 (lockstep)"),
        raw_vframe(0x94, bytes((1,)) + b"R1 in pad at sim://127.0.0.1:3000 (lockstep)"),
    ),
    (VehicleInfo(0), raw_vframe(0x94, bytes((0,)))),
    (
        Truth(1500, -250, -1200, 359999, 123456),
        vframe(0x95, "iiiiI", 1500, -250, -1200, 359999, 123456),
    ),
    (
        PadReport(1, 0b101, -120, 40, 1800, 870, 98765),
        vframe(0x91, "BBiiiHIB", 1, 5, -120, 40, 1800, 870, 98765, 0),
    ),
    (
        PadReport(0, 0, 0, 0, 0, 0, 98765, vision=1),  # vision too slow to hold
        vframe(0x91, "BBiiiHIB", 0, 0, 0, 0, 0, 0, 98765, 1),
    ),
    (
        Result(PD.TAKE_OFF, ResultCode.OK, "taking off to 1.5 m ✓"),
        raw_vframe(0x92, bytes((0x83, 0)) + "taking off to 1.5 m ✓".encode()),
    ),
    (
        Health(HealthStatus.CRASHED, "crashed: tumbled"),
        raw_vframe(0x93, bytes((1,)) + b"crashed: tumbled"),
    ),
    (Health(HealthStatus.OK), raw_vframe(0x93, bytes((0,)))),
    (
        NavStatus(NavState.CRASHED, PadAction.OFF, 0, 0, 0, 0, 0, 0, 0, 11800, 5000),
        vframe(0x90, "BBiiiihhhHIHH", 7, 0, 0, 0, 0, 0, 0, 0, 0, 11800, 5000, 0, 0),
    ),
    (Ack(PD.CTRL_INPUT), b">a\x17a<"),
]


def to_vehicle(msg: Message) -> bool:
    """True if ``msg`` travels ground -> vehicle (parsed by CommandStreamParser)."""
    return LAYOUTS[type(msg)].kind in (FrameKind.ASCTEC, FrameKind.SKEYE)


def parser_for(msg: Message) -> VehicleStreamParser | CommandStreamParser:
    return CommandStreamParser() if to_vehicle(msg) else VehicleStreamParser()


CASE_IDS = [f"{i}-{type(m).__name__}" for i, (m, _) in enumerate(CASES)]

# --- checksums -------------------------------------------------------------------------------


def test_crc16_check_value() -> None:
    assert crc16(b"123456789") == 0x9DB8
    assert crc16(b"") == 0x00FF


@given(st.binary(max_size=64))
def test_crc16_matches_bitwise_reference(data: bytes) -> None:
    assert crc16(data) == crc_reference(data)


def test_command_checksum_sums_and_wraps() -> None:
    assert command_checksum() == 0xAAAA
    assert command_checksum(100, -200, 0, 2000, 15) == 0xB225
    assert command_checksum(0x5556) == 0x0000  # wraps
    assert command_checksum(-0xAAAA - 1) == 0xFFFF  # negative sums wrap too


# --- the table, both ways --------------------------------------------------------------------


SPEC_SIZES = {
    LlStatus: 16,
    ImuRawData: 28,
    ImuCalcData: 92,
    RcData: 33,
    ControllerOutput: 16,
    GpsData: 44,
    GpsDataAdvanced: 60,
    CurrentWay: 12,
    CtrlInput: 12,
    Waypoint: 28,
    Velocity: 10,
    MoveBy: 19,
    GotoGps: 14,
    TakeOff: 4,
    Land: 0,
    Hold: 0,
    Reset: 0,
    PadMode: 5,
    Stream: 6,
    Clock: 4,
    NavStatus: 34,
    PadReport: 21,
    Health: 1,
    VehicleInfo: 1,
    Truth: 20,
}


@pytest.mark.parametrize(
    ("cls", "size"), SPEC_SIZES.items(), ids=lambda v: getattr(v, "__name__", "")
)
def test_payload_sizes_match_spec(cls: type[Message], size: int) -> None:
    assert LAYOUTS[cls].size == size


def test_table_covers_every_message_type() -> None:
    assert {type(m) for m, _ in CASES} == set(LAYOUTS)


@pytest.mark.parametrize(("msg", "wire"), CASES, ids=CASE_IDS)
def test_encode_gives_expected_bytes(msg: Message, wire: bytes) -> None:
    assert encode(msg) == wire


@pytest.mark.parametrize(("msg", "wire"), CASES, ids=CASE_IDS)
def test_parsing_expected_bytes_gives_message(msg: Message, wire: bytes) -> None:
    parser = parser_for(msg)
    assert parser.feed(wire) == [msg]
    assert not parser.errors
    assert parser.garbage_bytes == 0
    assert parser.buffered == 0


def test_wrong_direction_is_not_understood() -> None:
    """A vehicle frame fed to the vehicle's own parser is not a command, and vice versa."""
    cmd = CommandStreamParser()
    events: list[Any] = cmd.feed(
        encode(NavStatus(NavState.LANDED, PadAction.OFF, 0, 0, 0, 0, 0, 0, 0, 0, 0))
    )
    assert all(not isinstance(e, Message) for e in events)
    ground = VehicleStreamParser()
    events = ground.feed(encode(TakeOff(1000)))
    assert all(not isinstance(e, Message) for e in events)


@pytest.mark.parametrize("to_vehicle_side", [False, True])
def test_one_byte_at_a_time_with_garbage_between(to_vehicle_side: bool) -> None:
    cases = [(m, w) for m, w in CASES if to_vehicle(m) == to_vehicle_side]
    garbage = [b"", b"\x00", b"hello", b"<#<", b"\xff\xfe*", b"a<", b"#"]
    stream = b"".join(garbage[i % len(garbage)] + w for i, (_, w) in enumerate(cases))
    n_garbage = sum(len(garbage[i % len(garbage)]) for i in range(len(cases)))
    parser = CommandStreamParser() if to_vehicle_side else VehicleStreamParser()
    events: list[Any] = []
    for k in range(len(stream)):
        events += parser.feed(stream[k : k + 1])
    assert events == [m for m, _ in cases]
    assert parser.garbage_bytes == n_garbage
    assert not parser.errors
    assert parser.messages == len(cases)


def test_lone_start_characters_are_garbage() -> None:
    parser = CommandStreamParser()
    events = parser.feed(b">x>*x" + encode(Hold()) + b">" + encode(Land()))
    assert events == [Hold(), Land()]
    assert parser.garbage_bytes == 6
    ground = VehicleStreamParser()
    assert ground.feed(b">x>*x" + encode(Ack(PD.LAUNCH))) == [Ack(PD.LAUNCH)]
    assert ground.garbage_bytes == 5


# --- Hypothesis round trips ------------------------------------------------------------------


def masked_ints(bits: int) -> st.SearchStrategy[int]:
    return st.integers(0, bits).map(lambda v: v & bits)


@st.composite
def messages(draw: st.DrawFn, cls: type[Message]) -> Message:
    """Any valid ``cls``, each field drawn within the range its layout allows."""
    layout = LAYOUTS[cls]
    kwargs: dict[str, Any] = {}
    for f in layout.fields:
        if f.computed:
            continue
        lo, hi = f.limits
        ints = st.integers(lo, hi)
        if f.bits is not None:
            ints = masked_ints(f.bits)
        if cls is Ack:
            ints = st.sampled_from(sorted(ACK_PDS))
        elif f.enum is not None:
            enum: type[IntEnum] = f.enum
            ints = st.sampled_from(list(enum))
        kwargs[f.name] = draw(st.lists(ints, min_size=f.count, max_size=f.count).map(tuple)
                              if f.count > 1 else ints)  # fmt: skip
    if layout.tail is not None:
        cap = getattr(cls, "MAX_DESCRIPTION_BYTES", Result.MAX_REASON_BYTES)
        reason = draw(st.text(max_size=40) | st.text(min_size=cap // 2, max_size=cap // 2 + 40))
        assume(len(reason.encode("utf-8")) <= cap)
        kwargs[layout.tail] = reason
    try:
        return cls(**kwargs)
    except LocalProtocolError:  # cross-field rules (absolute waypoint coordinates)
        assume(False)
        raise


ALL_TYPES = sorted(LAYOUTS, key=lambda c: c.__name__)
any_message = st.sampled_from(ALL_TYPES).flatmap(messages)


def chunked(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    edges = [0, *points, len(data)]
    return [data[a:b] for a, b in itertools.pairwise(edges)]


@pytest.mark.parametrize("cls", ALL_TYPES, ids=[c.__name__ for c in ALL_TYPES])
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(data=st.data())
def test_round_trip_every_type(cls: type[Message], data: st.DataObject) -> None:
    msg = data.draw(messages(cls))
    wire = encode(msg)
    parser = parser_for(msg)
    cuts = data.draw(st.lists(st.integers(0, 2000), max_size=6))
    events: list[Any] = []
    for chunk in chunked(wire, cuts):
        events += parser.feed(chunk)
    assert events == [msg]
    assert not parser.errors


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(
    msgs=st.lists(any_message, min_size=1, max_size=8),
    cuts=st.lists(st.integers(0, 10_000), max_size=10),
)
def test_mixed_streams_round_trip(msgs: list[Message], cuts: list[int]) -> None:
    for side in (True, False):
        mine = [m for m in msgs if to_vehicle(m) == side]
        parser = CommandStreamParser() if side else VehicleStreamParser()
        events: list[Any] = []
        for chunk in chunked(b"".join(encode(m) for m in mine), cuts):
            events += parser.feed(chunk)
        assert events == mine


# --- fuzz ------------------------------------------------------------------------------------

_EVENT_TYPES = (Message, FrameError, CommandError)


@settings(max_examples=300, deadline=None)
@given(
    data=st.binary(max_size=400)
    | st.lists(
        st.sampled_from([b">*>", b">*>s", b">a", b"a<", b"<#<", b">*>d", b">*>w", b"\x04\x00"])
        | st.binary(max_size=6),
        max_size=40,
    ).map(b"".join),
    cuts=st.lists(st.integers(0, 2000), max_size=12),
)
def test_fuzz_gives_only_events_and_is_chunk_invariant(data: bytes, cuts: list[int]) -> None:
    for make in (VehicleStreamParser, CommandStreamParser):
        whole = make().feed(data)
        parser = make()
        events: list[Any] = []
        for chunk in chunked(data, cuts):
            events += parser.feed(chunk)
        assert events == whole
        assert all(isinstance(e, _EVENT_TYPES) for e in events)
        errors = [e for e in events if not isinstance(e, Message)]
        assert sum(parser.errors.values()) == len(errors)
        # After any prefix, a maximal frame's worth of filler brings the parser back in sync.
        follow_ground = Result(0x85, ResultCode.BUSY, "busy")
        follow = Hold() if make is CommandStreamParser else follow_ground
        tail = parser.feed(bytes(1040) + encode(follow))
        assert tail[-1] == follow
        assert parser.buffered == 0


@settings(max_examples=100, deadline=None)
@given(st.binary(min_size=1, max_size=60), st.integers(0, 2**16 - 1))
def test_corrupted_skeye_frames_give_errors_not_exceptions(payload: bytes, pd: int) -> None:
    parser = CommandStreamParser()
    events = parser.feed(raw_vframe(pd & 0xFF, payload, start=b">*>s"))
    assert len(events) == 1
    assert isinstance(events[0], Message | CommandError)


# --- error events and their result codes -----------------------------------------------------


def _only(events: list[Any]) -> Any:
    assert len(events) == 1, events
    return events[0]


def test_ctrl_input_bad_checksum() -> None:
    wire = bytearray(encode(CtrlInput(10, 20, 30, 40, 0x0F)))
    wire[-1] ^= 0x01
    parser = CommandStreamParser()
    events: list[Any] = parser.feed(bytes(wire) + encode(Launch()))
    assert events[0] == CommandError(PD.CTRL_INPUT, ResultCode.BAD_CHECKSUM, events[0].reason)
    assert "checksum" in events[0].reason
    assert events[-1] == Launch()
    assert parser.errors == {ErrorKind.BAD_CHECKSUM: 1}


def test_waypoint_bad_checksum() -> None:
    wire = bytearray(encode(WAYPOINT))
    wire[-4] ^= 0x40  # height changes, checksum does not
    err = _only(CommandStreamParser().feed(bytes(wire)))
    assert (err.pd, err.code) == (PD.WAYPOINT, ResultCode.BAD_CHECKSUM)


def test_ctrl_input_value_out_of_range_with_good_checksum() -> None:
    payload = struct.pack("<hhhhh", 3000, 0, 0, 100, 0x0F)
    wire = b">*>di" + payload + struct.pack("<H", (3000 + 100 + 0x0F + 0xAAAA) & 0xFFFF)
    parser = CommandStreamParser()
    err = _only(parser.feed(wire))
    assert (err.pd, err.code) == (PD.CTRL_INPUT, ResultCode.BAD_VALUE)
    assert "pitch" in err.reason
    assert parser.errors == {ErrorKind.BAD_VALUE: 1}
    assert parser.buffered == 0


def test_skeye_bad_crc() -> None:
    wire = bytearray(encode(TakeOff(1000)))
    wire[-5] ^= 0xFF
    parser = CommandStreamParser()
    err = _only(parser.feed(bytes(wire)))
    assert err == CommandError(PD.TAKE_OFF, ResultCode.BAD_CHECKSUM, err.reason)
    assert parser.errors == {ErrorKind.BAD_CRC: 1}


@pytest.mark.parametrize(
    ("pd", "payload"),
    [(0x83, b"\x01\x02\x03"), (0x84, b"\x00"), (0x80, bytes(11)), (0x87, bytes(5))],
)
def test_skeye_bad_length(pd: int, payload: bytes) -> None:
    parser = CommandStreamParser()
    err = _only(parser.feed(raw_vframe(pd, payload, start=b">*>s")))
    assert (err.pd, err.code) == (pd, ResultCode.BAD_LENGTH)
    assert parser.errors == {ErrorKind.BAD_LENGTH: 1}


@pytest.mark.parametrize(
    ("pd", "fmt", "values", "field"),
    [
        (0x86, "BHH", (3, 0, 0), "mode"),
        (0x83, "i", (0,), "height"),
        (0x81, "iiiiBH", (0, 0, 0, 0, 2, 0), "frame"),
        (0x82, "iiiH", (900_000_001, 0, 0, 0), "latitude"),
        (0x87, "HHH", (0x0020, 0, 10), "poll_mask"),
        (0x87, "HHH", (0, 0x0008, 10), "skeye_mask"),
    ],
)
def test_skeye_bad_value(pd: int, fmt: str, values: tuple[int, ...], field: str) -> None:
    err = _only(CommandStreamParser().feed(sframe(pd, fmt, *values)))
    assert (err.pd, err.code) == (pd, ResultCode.BAD_VALUE)
    assert field in err.reason


@pytest.mark.parametrize("pd", [0x89, 0x8F, 0x90, 0x02, 0x00, 0xFF])
def test_skeye_unknown_pd_is_bad_value(pd: int) -> None:
    parser = CommandStreamParser()
    err = _only(parser.feed(raw_vframe(pd, b"", start=b">*>s")))
    assert (err.pd, err.code) == (pd, ResultCode.BAD_VALUE)
    assert parser.errors == {ErrorKind.UNKNOWN_PD: 1}


def test_command_error_answers_with_result() -> None:
    err = CommandError(PD.PAD_MODE, ResultCode.BAD_VALUE, "x" * 2000)
    result = err.result()
    assert (result.command_pd, result.code) == (PD.PAD_MODE, ResultCode.BAD_VALUE)
    assert VehicleStreamParser().feed(encode(result)) == [result]


def test_unknown_asctec_command_resyncs() -> None:
    parser = CommandStreamParser()
    events: list[Any] = parser.feed(b">*>x" + b">*>dq" + b">*>wz" + encode(Poll(1)))
    kinds = [e.kind for e in events[:-1]]
    assert kinds == [ErrorKind.UNKNOWN_PD] * 3
    assert all(isinstance(e, FrameError) for e in events[:-1])
    assert events[-1] == Poll(1)


def test_over_long_length_resyncs() -> None:
    for parser, good, start in (
        (VehicleStreamParser(), Ack(PD.COME_HOME), b">*>"),
        (CommandStreamParser(), Hold(), b">*>s"),
    ):
        events: list[Any] = parser.feed(start + struct.pack("<HB", 1025, 0x84) + encode(good))
        assert events == [FrameError(events[0].reason, ErrorKind.TOO_LONG), good]
        assert parser.errors == {ErrorKind.TOO_LONG: 1}


def test_longest_payload_is_accepted() -> None:
    result = Result(0x80, ResultCode.REFUSED, "r" * Result.MAX_REASON_BYTES)
    wire = encode(result)
    assert struct.unpack_from("<H", wire, 3)[0] == 1024
    assert VehicleStreamParser().feed(wire) == [result]


def test_corrupt_length_hides_no_later_frame() -> None:
    """A length field bumped up is a bad frame at once (it disagrees with NAV_STATUS's size),
    and the frames behind it are read as they come: it used to swallow them until 200 bytes
    more had come and the stop check failed, which on a line of answers never came."""
    first = bytearray(encode(NavStatus(NavState.FLYING, PadAction.OFF, 1, 2, 3, 4, 5, 6, 7, 8, 9)))
    first[3] = 200  # claims 200 bytes
    later = [Ack(PD.LAUNCH), PadReport(1, 3, 10, 20, 30, 500, 40)] * 4
    parser = VehicleStreamParser()
    events: list[Any] = parser.feed(bytes(first) + b"".join(encode(m) for m in later))
    assert events[0].kind is ErrorKind.BAD_LENGTH
    assert events[1:] == later and parser.buffered == 0


def test_corrupt_length_of_a_command_hides_no_later_command() -> None:
    """The vehicle side too: a skeye command whose length field disagrees with its PD's
    payload (a LAND claiming 1000 bytes) is answered RESULT BAD_LENGTH at once, and the
    commands behind it (sticks, polls) are read as they come. It used to wait for the 1000
    bytes: on a ground link sending a 6-byte poll every 0.5 s that is minutes of commands
    swallowed, the vehicle hearing nothing intact and going to FAILSAFE."""
    first = bytearray(encode(Land()))
    first[4:6] = struct.pack("<H", 1000)
    later = [CtrlInput(100, -100, 0, 2000, 0x0F), Poll(int(PollMask.LL_STATUS))] * 3
    parser = CommandStreamParser()
    events: list[Any] = parser.feed(bytes(first) + b"".join(encode(m) for m in later))
    assert events[0] == CommandError(PD.LAND, ResultCode.BAD_LENGTH, events[0].reason, False)
    assert "1000" in events[0].reason and "0 bytes" in events[0].reason
    assert events[1:] == later and parser.buffered == 0
    # Its CRC never came: no packet for the link timeout (line noise may look like this).
    assert not arrived_intact(events[0]) and all(map(arrived_intact, events[1:]))


def test_corrupt_length_of_an_unknown_pd_still_rescans_at_the_stop_check() -> None:
    """A frame whose PD names no structure has no size to check: its length is waited for,
    then the stop check fails and the bytes are rescanned (the residual case)."""
    first = bytearray(raw_vframe(0x45, b"abc"))
    first[3] = 200
    later = [PadReport(1, 3, 10, 20, 30, 500, 40)] * 2
    parser = VehicleStreamParser()
    events: list[Any] = parser.feed(bytes(first) + b"".join(encode(m) for m in later) + bytes(200))
    assert events[0].kind is ErrorKind.BAD_STOP
    assert [e for e in events[1:] if not isinstance(e, FrameError)] == later


def test_vehicle_side_error_kinds() -> None:
    parser = VehicleStreamParser()
    bad_crc = bytearray(encode(PadReport(0, 0, 0, 0, 0, 0, 0)))
    bad_crc[8] ^= 0x10
    streams = [
        (bytes(bad_crc), ErrorKind.BAD_CRC),
        (raw_vframe(0x45, b"abc"), ErrorKind.UNKNOWN_PD),
        (raw_vframe(0x80, b""), ErrorKind.UNKNOWN_PD),  # a command is not a vehicle frame
        (raw_vframe(0x02, bytes(15)), ErrorKind.BAD_LENGTH),
        (raw_vframe(0x92, b"\x80"), ErrorKind.BAD_LENGTH),
        (raw_vframe(0x92, b"\x80\x09"), ErrorKind.BAD_VALUE),  # result code 9
        (raw_vframe(0x92, b"\x80\x00\xff\xfe"), ErrorKind.BAD_VALUE),  # not UTF-8
        (vframe(0x90, "BBiiiihhhHIHH", 255, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0),
         ErrorKind.BAD_VALUE),
        (vframe(0x11, "iiii", 0, 0, 0, 201), ErrorKind.BAD_VALUE),
        (encode(Ack(PD.LAUNCH))[:4] + b"x", ErrorKind.BAD_STOP),
        (b">a\x02a<", ErrorKind.UNKNOWN_PD),
        (encode(Result(0x84, ResultCode.OK))[:-1] + b"!", ErrorKind.BAD_STOP),
    ]
    for wire, kind in streams:
        events = parser.feed(wire + encode(Ack(PD.CTRL_INPUT)))
        assert isinstance(events[0], FrameError), (wire, events)
        assert events[0].kind is kind, (wire, events)
        assert events[-1] == Ack(PD.CTRL_INPUT)
    assert sum(parser.errors.values()) == len(streams)
    assert parser.errors[ErrorKind.BAD_VALUE] == 4


def test_skeye_bad_stop_is_a_frame_error() -> None:
    wire = encode(PadMode(PadAction.HOLD, 10, 10))[:-3] + b"<#>"
    parser = CommandStreamParser()
    events: list[Any] = parser.feed(wire + encode(Land()))
    assert events[0].kind is ErrorKind.BAD_STOP
    assert isinstance(events[0], FrameError)
    assert events[-1] == Land()


# --- building messages -----------------------------------------------------------------------


@pytest.mark.parametrize(
    "build",
    [
        lambda: CtrlInput(2048, 0, 0, 0, 0),
        lambda: CtrlInput(0, -2048, 0, 0, 0),
        lambda: CtrlInput(0, 0, 0, 4096, 0),
        lambda: CtrlInput(0, 0, 0, -1, 0),
        lambda: CtrlInput(0, 0, 0, 0, 0x40),
        lambda: CtrlInput(1.5, 0, 0, 0, 0),  # type: ignore[arg-type]
        lambda: PadMode(3, 0, 0),  # type: ignore[arg-type]
        lambda: PadMode(0, -1, 0),  # type: ignore[arg-type]
        lambda: TakeOff(0),
        lambda: Velocity(40_000, 0, 0, 0, 0),
        lambda: MoveBy(0, 0, 0, 0, 2, 0),  # type: ignore[arg-type]
        lambda: GotoGps(0, 1_800_000_001, 0, 0),
        lambda: Stream(0x0040, 0, 0),
        lambda: Stream(0, 0x0008, 0),
        lambda: NavStatus(255, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0),  # type: ignore[arg-type]
        lambda: PadReport(2, 0, 0, 0, 0, 0, 0),
        lambda: PadReport(1, 0, 0, 0, 0, 1001, 0),
        lambda: PadReport(1, 0, 0, 0, 0, 0, 0, 2),
        lambda: Result(0x80, 6, ""),  # type: ignore[arg-type]
        lambda: Result(0x80, 0, "x" * 1023),  # type: ignore[arg-type]
        lambda: Result(0x80, 0, "\ud800"),  # type: ignore[arg-type]
        lambda: Result(0x100, 0, ""),  # type: ignore[arg-type]
        lambda: Ack(PD.LL_STATUS),
        lambda: Ack(0x99),  # type: ignore[arg-type]
        lambda: Waypoint(0, 0, 0, 0, 0, 0, 0, 0, wp_number=2),
        lambda: Waypoint(0x08, 0, 0, 0, 0, 0, 0, 0),
        lambda: Waypoint(0, 101, 0, 0, 0, 0, 0, 0),
        lambda: Waypoint(0x01, 0, 0, 0, 1_800_000_001, 0, 0, 0),
        lambda: Waypoint(0x01, 0, 0, 0, 0, 900_000_001, 0, 0),
        lambda: dataclasses.replace(IMU_CALC, angle_yaw=360_001),
        lambda: RcData((0,) * 7, (0,) * 8, 0),
        lambda: RcData((0,) * 8, (4096,) + (0,) * 7, 0),
        lambda: RcData(5, (0,) * 8, 0),  # type: ignore[arg-type]
        lambda: ControllerOutput(0, 0, 0, -1),
        lambda: LlStatus(0, 0, 0, 0, 256, 0, 0, 0, 0, 0),
        lambda: GpsData(900_000_001, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0),
        lambda: CurrentWay(0, 0, 0, 0, 0, 0, 0, 0, 70_000),
        lambda: Poll(0x10000),
        lambda: Poll(-1),
    ],
)
def test_invalid_messages_are_refused(build: Any) -> None:
    with pytest.raises(LocalProtocolError):
        build()


def test_relative_waypoint_allows_any_int32() -> None:
    wp = Waypoint(0, 0, 0, 0, -(2**31), 2**31 - 1, 0, 0)
    assert CommandStreamParser().feed(encode(wp)) == [wp]


def test_numpy_integers_are_normalised() -> None:
    msg = CtrlInput(np.int16(5), np.int64(-5), np.int32(0), np.uint16(100), 0x0F)  # type: ignore[arg-type]
    assert type(msg.pitch) is int
    assert encode(msg) == encode(CtrlInput(5, -5, 0, 100, 0x0F))
    nav = NavStatus(2, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0)  # type: ignore[arg-type]
    assert nav.state is NavState.FLYING and nav.pad_mode is PadAction.HOLD


def test_poll_keeps_unknown_bits_and_lists_known_structures() -> None:
    poll = Poll(0xFFFF)
    assert CommandStreamParser().feed(encode(poll)) == [poll]
    assert Poll(0x0201).requested() == [PD.LL_STATUS, PD.GPS_DATA_ADVANCED]
    assert len(poll.requested()) == len(PollMask)


def test_encode_refuses_non_messages() -> None:
    with pytest.raises(LocalProtocolError):
        encode("not a message")  # type: ignore[arg-type]


def test_messages_are_frozen() -> None:
    msg = TakeOff(100)
    with pytest.raises(AttributeError):
        msg.height = 5  # type: ignore[misc]


def test_feeding_something_other_than_bytes_is_a_protocol_error() -> None:
    for parser in (VehicleStreamParser(), CommandStreamParser()):
        with pytest.raises(LocalProtocolError, match="feed takes bytes, got str"):
            parser.feed(">*>p")  # type: ignore[arg-type]
        assert parser.feed(bytearray(b"xx")) == [] and parser.garbage_bytes == 2


def test_a_nav_state_the_table_lacks_is_a_bad_value() -> None:
    """CRASHED is 7; 6 is MANUAL's (issue 30), and until this table has it, a NAV_STATUS that
    carries 6 is refused, never read as some other state."""
    wire = vframe(0x90, "BBiiiihhhHIHH", 6, 0, 0, 0, 0, 0, 0, 0, 0, 11800, 5000, 0, 0)
    events = VehicleStreamParser().feed(wire)
    if 6 in {int(s) for s in NavState}:
        assert isinstance(events[0], NavStatus)
    else:
        assert isinstance(events[0], FrameError) and "state" in events[0].reason
