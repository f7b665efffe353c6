"""Tests of the precompiled line shapes and the start-pose layout (skeye.wire.sim_format)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skeye.errors import LocalProtocolError, RemoteProtocolError
from skeye.wire.sim_format import (
    BOOL,
    FLOAT,
    INT,
    WORD,
    LineFormat,
    Slot,
    floats,
    format_start_poses,
    ints,
    parse_start_poses,
)
from skeye.wire.sim_lines import LineDecoder, Message, format_message, parse_line

FLOATS = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e9, max_value=1e9)


# --- start poses -----------------------------------------------------------------------------


def test_start_poses_layout() -> None:
    data = format_start_poses([("Pad1", (1, 2, -0.5), (0, 0, 1.5)), ("Pad2", (3, 4, 0), (0, 0, 0))])
    assert data == (
        b"NFO {StartPoses 2} {Pad1 1.000000,2.000000,-0.500000 0.000000,0.000000,1.500000"
        b" Pad2 3.000000,4.000000,0.000000 0.000000,0.000000,0.000000}\r\n"
    )
    assert format_start_poses([]) == b"NFO {StartPoses 0}\r\n"
    assert parse_start_poses(parse_line("NFO {StartPoses 0}")) == {}


def test_start_poses_other_layouts() -> None:
    one_per_block = parse_line("NFO {StartPoses 2} {Pad1 1,2,3 0,0,0} {Pad2 4,5,6 0,0,1} {Ext 1}")
    assert parse_start_poses(one_per_block) == {
        "Pad1": ((1.0, 2.0, 3.0), (0.0, 0.0, 0.0)),
        "Pad2": ((4.0, 5.0, 6.0), (0.0, 0.0, 1.0)),
    }
    usarsim = parse_line("NFO {StartPoses 1} {PlayerStart 0.5,-1,2 0,0,3.14} {Level x}")
    assert parse_start_poses(usarsim) == {"PlayerStart": ((0.5, -1.0, 2.0), (0.0, 0.0, 3.14))}


POSE_NAMES = st.from_regex(r"[A-Za-z][A-Za-z0-9_.\-]{0,9}", fullmatch=True)
VEC3 = st.tuples(FLOATS, FLOATS, FLOATS)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(POSE_NAMES, VEC3, VEC3), max_size=6, unique_by=lambda p: p[0].lower()))
def test_start_poses_round_trip(
    poses: list[tuple[str, tuple[float, ...], tuple[float, ...]]],
) -> None:
    data = format_start_poses(poses)
    (m,) = LineDecoder().feed(data)
    assert isinstance(m, Message)
    assert m.get_int("StartPoses") == len(poses)
    parsed = parse_start_poses(m)
    assert list(parsed) == [name for name, _, _ in poses]
    for name, location, rotation in poses:
        assert parsed[name] == (
            tuple(float(f"{v:.6f}") for v in location),
            tuple(float(f"{v:.6f}") for v in rotation),
        )


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        ("NFO {Level x}", "missing {StartPoses ...}"),
        ("NFO {StartPoses -1}", "below the minimum 0"),
        ("NFO {StartPoses two}", "is not an integer"),
        ("NFO {StartPoses 2} {Pad1 1,2,3 0,0,0}", "needs 6 tokens"),
        ("NFO {StartPoses 1}", "needs 3 tokens"),
        ("NFO {StartPoses 1} {Pad1 1,2,3 0,0,0 Pad2}", "needs 3 tokens"),
        (
            "NFO {StartPoses 1} {Pad1 1,2 0,0,0}",
            "start pose Pad1: location: '1,2' has 2 components",
        ),
        ("NFO {StartPoses 1} {Pad1 1,2,3 0,x,0}", "start pose Pad1: rotation"),
        ("NFO {StartPoses 2} {Pad1 1,2,3 0,0,0 pad1 1,2,3 0,0,0}", "'pad1' is repeated"),
        ("NFO {Level x StartPoses 1}", "has no pose block"),
    ],
)
def test_start_poses_malformed(line: str, reason: str) -> None:
    with pytest.raises(RemoteProtocolError) as info:
        parse_start_poses(parse_line(line))
    assert reason in str(info.value)


@pytest.mark.parametrize(
    ("poses", "reason"),
    [
        ([("", (0, 0, 0), (0, 0, 0))], "empty start pose name"),
        ([("Pad 1", (0, 0, 0), (0, 0, 0))], "contains a brace or whitespace"),
        ([("P,1", (0, 0, 0), (0, 0, 0))], "contains a comma"),
        ([("P", (0, 0, 0), (0, 0, 0)), ("p", (0, 0, 0), (0, 0, 0))], "is repeated"),
        ([("P", (0, 0), (0, 0, 0))], "location must be 3 numbers"),
        ([("P", (0, 0, 0), (0, math.nan, 0))], "rotation: nan is not finite"),
        ([("P", (0, 0, 0), (0, "a", 0))], "is not a number"),
        ([("P", (0, 0, 0))], "is not (name, location, rotation)"),
    ],
)
def test_start_poses_format_errors(poses: list, reason: str) -> None:
    with pytest.raises(LocalProtocolError) as info:
        format_start_poses(poses)
    assert reason in str(info.value)


# --- LineFormat: the precompiled stream lines ---------------------------------------------

_SLOTS = st.sampled_from([FLOAT, floats(3), floats(4), INT, ints(2), BOOL, WORD])
_KEYS = st.from_regex(r"[A-Z][A-Za-z0-9_]{0,11}", fullmatch=True)
_WORDS = st.from_regex(r"[A-Za-z0-9_.,%-]{1,12}", fullmatch=True)
_FINITE = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e9, max_value=1e9)


def _values_for(slot: Slot) -> st.SearchStrategy[list[object]]:
    element: st.SearchStrategy[object] = {
        "f": _FINITE,
        "d": st.integers(-(2**40), 2**40),
        "b": st.booleans(),
        "s": _WORDS,
    }[slot.kind]
    return st.lists(element, min_size=slot.count, max_size=slot.count)


@st.composite
def _shapes(draw: st.DrawFn) -> tuple[list[tuple[str, object]], list[object], list[tuple]]:
    """A layout (fixed words and slots), values for it, and the same fields as pairs."""
    layout: list[tuple[str, object]] = []
    values: list[object] = []
    pairs: list[tuple[str, object]] = []
    for key in draw(st.lists(_KEYS, max_size=8)):
        if draw(st.booleans()):
            word = draw(_WORDS)
            layout.append((key, word))
            pairs.append((key, word))
            continue
        slot = draw(_SLOTS)
        vals = draw(_values_for(slot))
        layout.append((key, slot))
        values.extend(vals)
        pairs.append((key, vals[0] if slot.count == 1 else tuple(vals)))
    return layout, values, pairs


@settings(max_examples=300, deadline=None)
@given(shape=_shapes(), type_=st.sampled_from(["SEN", "STA", "X%d"]))
def test_line_format_writes_what_format_message_writes(shape: tuple, type_: str) -> None:
    layout, values, pairs = shape
    fmt = LineFormat(type_, layout)
    line = fmt.format(values)
    assert line == format_message(type_, *pairs)
    parsed = parse_line(line.decode().rstrip("\r\n"))
    assert parsed.type == type_.upper()


def test_line_format_a_sensor_line() -> None:
    fmt = LineFormat("SEN", [("Time", FLOAT), ("Type", "INS"), ("Location", floats(3)),
                             ("Armed", BOOL), ("Delta", ints(2))])
    assert fmt.size == 7
    assert fmt.format((1.5, 1.0, -2.0, 0.25, True, 3, -4)) == (
        b"SEN {Time 1.500000} {Type INS} {Location 1.000000,-2.000000,0.250000} {Armed true} "
        b"{Delta 3,-4}\r\n"
    )


@pytest.mark.parametrize(
    ("values", "reason"),
    [
        ((1.0, float("nan")), "Location: nan is not a finite number"),
        ((1.0, float("inf")), "Location: inf is not a finite number"),
        ((1.0,), "takes 2 values, got 1"),
        ((1.0, "x"), "Location: 'x' is not a number"),
        ((1.0, None), "Location: None is not a number"),
    ],
)
def test_line_format_refuses_bad_values(values: tuple, reason: str) -> None:
    fmt = LineFormat("SEN", [("Time", FLOAT), ("Location", FLOAT)])
    with pytest.raises(LocalProtocolError, match=reason):
        fmt.format(values)


def test_line_format_refuses_bad_words_and_layouts() -> None:
    with pytest.raises(LocalProtocolError, match="not a word"):
        LineFormat("STA", [("Name", WORD)]).format(("two words",))
    with pytest.raises(LocalProtocolError, match="brace or whitespace"):
        LineFormat("STA", [("Name", "a b")])
    with pytest.raises(LocalProtocolError, match="brace or whitespace"):
        LineFormat("STA", [("Bad Key", FLOAT)])
    with pytest.raises(LocalProtocolError, match="slot kind"):
        Slot(1, "x")
    with pytest.raises(LocalProtocolError, match="bad slot size"):
        Slot(2, "b")
