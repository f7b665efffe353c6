"""The sans-IO parts on their own: the mode table, the scheduler, the parameter table and the
mission protocol, driven with pymavlink messages and an injected clock."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mav

from skeye.errors import LocalProtocolError
from skeye.mavlink.codec import MavCodec, MavParser, statustext
from skeye.mavlink.mission import MissionProtocol
from skeye.mavlink.modes import MODE_TABLE, Program, Px4Mode
from skeye.mavlink.params import ParamSpec, ParamTable
from skeye.mavlink.streams import MessageScheduler
from skeye.wire.packet_defs import NavState

GCS = MavCodec(255, 190)


def _roundtrip(msg):
    """A message as the vehicle receives it (packed by one side, parsed by the other)."""
    (out,) = MavParser().feed(GCS.encode(msg))
    return out


def test_a_long_statustext_ends_with_a_chunk_shorter_than_50_bytes():
    """MAVLink marks a long STATUSTEXT's last chunk by a NUL in its text: a text of exactly 100
    bytes once went out as two full chunks, and a reader waited for a third forever."""
    for size in (51, 99, 100, 150, 350, 399, 400, 1000):
        text = "".join(chr(ord("a") + i % 26) for i in range(size))
        chunks = [_roundtrip(m) for m in statustext(GCS, mav.MAV_SEVERITY_WARNING, text)]
        assert len({c.id for c in chunks}) == 1 and chunks[0].id != 0
        assert [c.chunk_seq for c in chunks] == list(range(len(chunks)))
        assert len(chunks[-1].text.encode()) < 50
        assert all(len(c.text.encode()) == 50 for c in chunks[:-1])
        assert "".join(c.text for c in chunks) == text[:399]


def test_a_statustext_too_long_for_eight_chunks_is_cut_to_399_bytes():
    """Eight chunks carry at most 7 * 50 + 49 bytes (the last one short, to end the text): a
    longer text is cut to that, a character cut in two left out whole. (Eight full chunks once
    had their 8th replaced by an empty one: 400 bytes or more sent only 350.)"""
    sizes = {350: 8, 399: 8, 400: 8, 1000: 8, 300: 7, 349: 7}
    for size, count in sizes.items():
        text = "x" * size
        chunks = [_roundtrip(m) for m in statustext(GCS, mav.MAV_SEVERITY_WARNING, text)]
        assert len(chunks) == count, size
        assert "".join(c.text for c in chunks) == text[:399]
    text = "\u00e9" * 300  # two bytes each: byte 399 is half a character
    msgs = statustext(GCS, mav.MAV_SEVERITY_WARNING, text)
    for m in msgs:
        GCS.encode(m)
    # The bytes on the wire (pymavlink decodes a char field as ASCII): severity, then text.
    sent = b"".join(m.get_payload()[1:51].rstrip(b"\0") for m in msgs)
    assert len(msgs) == 8 and sent == ("\u00e9" * 199).encode()


def test_every_flight_state_and_program_has_a_mode():
    assert {(s, p) for s in NavState for p in Program} == set(MODE_TABLE)
    assert MODE_TABLE[(NavState.HOLDING, Program.NONE)] is Px4Mode.HOLD
    assert MODE_TABLE[(NavState.FLYING, Program.MISSION)] is Px4Mode.MISSION
    assert MODE_TABLE[(NavState.LANDING, Program.RTL)] is Px4Mode.RTL
    assert MODE_TABLE[(NavState.FAILSAFE, Program.OFFBOARD)] is Px4Mode.HOLD
    # PX4's layout: main mode in byte 2, sub mode in byte 3 (px4_custom_mode.h).
    assert Px4Mode.MISSION.custom_mode == (4 << 16) | (4 << 24)
    assert Px4Mode.from_custom(4, 5) is Px4Mode.RTL
    assert Px4Mode.from_custom(6, 0) is Px4Mode.OFFBOARD
    assert Px4Mode.from_custom(42, 0) is None


def test_the_scheduler_streams_at_the_asked_interval_without_catching_up():
    s = MessageScheduler(0.0)
    hb = mav.MAVLINK_MSG_ID_HEARTBEAT
    assert hb in s.due(0.0) and hb not in s.due(0.5) and hb in s.due(1.0)
    s.set_interval(hb, 0.25, 1.0)
    times = [t / 100 for t in range(100, 201) if hb in s.due(t / 100)]
    assert len(times) == 5 and times[0] == 1.0
    assert hb in s.due(10.0) and hb not in s.due(10.01)  # late: once, then on from there
    s.set_interval(hb, None, 11.0)
    assert hb not in s.due(20.0)
    s.set_interval(hb, 0, 20.0)
    assert s.interval_s(hb) == 1.0
    with pytest.raises(LocalProtocolError, match="out of range"):
        s.set_interval(hb, 0.001, 0.0)
    with pytest.raises(LocalProtocolError, match="not streamed"):
        s.set_interval(424242, 1.0, 0.0)


def test_parameters_are_read_set_and_refused_outside_their_range():
    store = {"v": 1.0}
    table = ParamTable([ParamSpec("SKY_TEST", 0.5, 2.0, "m", "a test", lambda: store["v"],
                                  lambda x: store.__setitem__("v", x))], MavCodec())
    (value,) = table.handle(_roundtrip(GCS.mav.param_request_list_encode(1, 1)))
    assert (value.param_id, value.param_value, value.param_count) == ("SKY_TEST", 1.0, 1)
    (value,) = table.handle(_roundtrip(GCS.mav.param_set_encode(1, 1, b"SKY_TEST", 1.5, 9)))
    assert value.param_value == 1.5 and store["v"] == 1.5
    for bad in (7.0, math.nan, math.inf):
        value, text = table.handle(_roundtrip(GCS.mav.param_set_encode(1, 1, b"SKY_TEST", bad,
                                                                       9)))
        assert value.param_value == 1.5 and text.get_type() == "STATUSTEXT"
    (text,) = table.handle(_roundtrip(GCS.mav.param_request_read_encode(1, 1, b"NOPE", -1)))
    assert "no parameter 'NOPE'" in text.text
    assert table.refused == 4


def _item(seq: int, **fields):
    f = dict(frame=mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, command=mav.MAV_CMD_NAV_WAYPOINT,
             current=0, autocontinue=1, param1=0, param2=0, param3=0, param4=0,
             x=490000000, y=80000000, z=10.0)
    f.update(fields)
    return _roundtrip(GCS.mav.mission_item_int_encode(1, 1, seq, *f.values(), 0))


def test_a_mission_upload_is_pulled_item_by_item_retried_and_checked():
    proto = MissionProtocol(MavCodec(), item_timeout_s=1.0, retries=2)
    (req,) = proto.handle(_roundtrip(GCS.mav.mission_count_encode(1, 1, 2, 0)), 0.0)
    assert (req.get_type(), req.seq, req.target_system) == ("MISSION_REQUEST_INT", 0, 255)
    assert proto.tick(0.5) == []
    (again,) = proto.tick(1.0)  # no item within the timeout: asked again
    assert again.seq == 0
    (req,) = proto.handle(_item(0), 1.1)
    assert req.seq == 1
    assert proto.handle(_item(0), 1.2) == []  # a duplicate of the last item: ignored
    (ack,) = proto.handle(_item(1), 1.3)
    assert ack.type == mav.MAV_MISSION_ACCEPTED and len(proto.items) == 2
    # A bad item ends the upload; the stored mission stays.
    proto.handle(_roundtrip(GCS.mav.mission_count_encode(1, 1, 1, 0)), 2.0)
    (ack,) = proto.handle(_item(0, x=1_900_000_000), 2.1)
    assert ack.type == mav.MAV_MISSION_INVALID_PARAM5_X and len(proto.items) == 2
    assert "latitude" in proto.rejections[-1]
    # An upload nobody finishes is cancelled after the retries.
    proto.handle(_roundtrip(GCS.mav.mission_count_encode(1, 1, 3, 0)), 3.0)
    assert [m.get_type() for m in proto.tick(4.0) + proto.tick(5.0)] == ["MISSION_REQUEST_INT"] * 2
    (ack,) = proto.tick(6.0)
    assert ack.type == mav.MAV_MISSION_OPERATION_CANCELLED
    # Download.
    (count,) = proto.handle(_roundtrip(GCS.mav.mission_request_list_encode(1, 1, 0)), 7.0)
    assert count.count == 2
    (item,) = proto.handle(_roundtrip(GCS.mav.mission_request_int_encode(1, 1, 1, 0)), 7.1)
    assert (item.seq, item.x, item.z) == (1, 490000000, 10.0)
    (ack,) = proto.handle(_roundtrip(GCS.mav.mission_count_encode(1, 1, 1, 1)), 8.0)
    assert ack.type == mav.MAV_MISSION_UNSUPPORTED  # fences are not kept
