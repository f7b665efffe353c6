"""Tests of the simulator protocol's line syntax (skeye.wire.sim_lines)."""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skeye.errors import LocalProtocolError, RemoteProtocolError
from skeye.wire.sim_lines import (
    FREE_TEXT_KEYS,
    LineDecoder,
    LineError,
    Message,
    format_error,
    format_message,
    parse_line,
)


def msg(type_: str, *fields: tuple[str, str], blocks: tuple[str, ...] | None = None) -> Message:
    """A Message whose blocks are its fields, one per block (the canonical layout)."""
    if blocks is None:
        blocks = tuple(f"{k} {v}" if v else k for k, v in fields)
    return Message(type_, tuple(fields), blocks)


# (line, expected message, canonical): canonical lines are exactly what format_message writes
# for the message's type and fields, so the table is checked both ways.
TABLE: list[tuple[str, Message, bool]] = [
    ("PING", msg("PING"), True),
    ("PING {Id 7}", msg("PING", ("Id", "7")), True),
    (
        "DRIVE {AltitudeVelocity 0.5} {LinearVelocity -1.25} {RotationalVelocity 0.1}",
        msg(
            "DRIVE",
            ("AltitudeVelocity", "0.5"),
            ("LinearVelocity", "-1.25"),
            ("RotationalVelocity", "0.1"),
        ),
        True,
    ),
    (
        "INIT {ClassName USARBot.AirRobot} {Name R1} {Location 1.5,0,-2.25}",
        msg("INIT", ("ClassName", "USARBot.AirRobot"), ("Name", "R1"), ("Location", "1.5,0,-2.25")),
        True,
    ),
    (
        "ERR {Command DRIVE} {Reason LinearVelocity: 'abc' is not a number}",
        msg("ERR", ("Command", "DRIVE"), ("Reason", "LinearVelocity: 'abc' is not a number")),
        True,
    ),
    ("SET {Type Wind} {Mode none}", msg("SET", ("Type", "Wind"), ("Mode", "none")), True),
    ("RES {Command SET} {Key}", msg("RES", ("Command", "SET"), ("Key", "")), True),
    (
        "STA {Type AerialVehicle} {Armed true} {Landed false}",
        msg("STA", ("Type", "AerialVehicle"), ("Armed", "true"), ("Landed", "false")),
        True,
    ),
    # Not canonical: lower-case type, odd spacing, no space before a block, tabs.
    ("drive {LinearVelocity 1}", msg("DRIVE", ("LinearVelocity", "1")), False),
    ("  PING   {Id   a  b }  ", msg("PING", ("Id", "a  b"), blocks=("Id   a  b",)), False),
    ("PING{Id 1}{Time 2}", msg("PING", ("Id", "1"), ("Time", "2")), False),
    ("PING\t{Id\t1}", msg("PING", ("Id", "1"), blocks=("Id\t1",)), False),
    ("PING {Id 1}\r\n", msg("PING", ("Id", "1")), False),
    # UT2004 multi-field block.
    (
        "SEN {Time 1.5} {Type Sonar Name F1 Range 2.5}",
        msg(
            "SEN",
            ("Time", "1.5"),
            ("Type", "Sonar"),
            ("Name", "F1"),
            ("Range", "2.5"),
            blocks=("Time 1.5", "Type Sonar Name F1 Range 2.5"),
        ),
        False,
    ),
]


@pytest.mark.parametrize(("line", "expected", "canonical"), TABLE)
def test_table_parses(line: str, expected: Message, canonical: bool) -> None:
    assert parse_line(line) == expected


@pytest.mark.parametrize(
    ("line", "expected"), [(line, expected) for line, expected, canonical in TABLE if canonical]
)
def test_table_formats(line: str, expected: Message) -> None:
    assert format_message(expected.type, *expected.fields) == line.encode() + b"\r\n"
    assert expected.to_bytes() == line.encode() + b"\r\n"


@pytest.mark.parametrize(("line", "expected", "canonical"), TABLE)
def test_table_through_decoder_byte_at_a_time(
    line: str, expected: Message, canonical: bool
) -> None:
    decoder = LineDecoder()
    data = line.encode() + b"\r\n"
    out: list[Message | LineError] = []
    for i in range(len(data)):
        out += decoder.feed(data[i : i + 1])
    assert out == [expected]


def test_type_and_keys_are_case_insensitive() -> None:
    m = parse_line("dRiVe {linearvelocity 1.5} {NORMALIZED TRUE}")
    assert m.type == "DRIVE"
    assert m.fields[0] == ("linearvelocity", "1.5")  # keys keep their spelling
    assert m.get("LinearVelocity") == "1.5"
    assert m.get("LINEARVELOCITY") == "1.5"
    assert m.has("Normalized")
    assert m.get_bool("normalized") is True
    assert m.get_float("LinearVelocity") == 1.5


def test_first_occurrence_wins() -> None:
    m = parse_line("X {A 1} {a 2}")
    assert m.get("A") == "1"
    assert m.get_int("a") == 1


def test_multi_field_block_splits() -> None:
    m = parse_line("GEO {Name F1 Range 2.5 Fov 0.5}")
    assert m.fields == (("Name", "F1"), ("Range", "2.5"), ("Fov", "0.5"))
    assert m.blocks == ("Name F1 Range 2.5 Fov 0.5",)
    assert m.get_float("range") == 2.5


@pytest.mark.parametrize(
    ("block", "value"),
    [
        ("Name F1 Range", "F1 Range"),  # odd token count
        ("Location 1 2 3", "1 2 3"),  # key-position token "2" is not a key
        ("Name F1 2x 2.5", "F1 2x 2.5"),  # "2x" does not start with a letter
        ("Name F1 Ra-nge 2.5", "F1 Ra-nge 2.5"),  # '-' not allowed in a key
        ("Pad1 1,2,3 0,0,0 Pad2 4,5,6 0,0,1", "1,2,3 0,0,0 Pad2 4,5,6 0,0,1"),
    ],
)
def test_blocks_that_do_not_split(block: str, value: str) -> None:
    key = block.split()[0]
    assert parse_line(f"X {{{block}}}").fields == ((key, value),)


@pytest.mark.parametrize("key", [*sorted(FREE_TEXT_KEYS), "REASON", "Params", "tExT"])
def test_free_text_keys_are_not_split(key: str) -> None:
    m = parse_line(f"ERR {{{key} Name F1 Range 2.5}}")
    assert m.fields == ((key, "Name F1 Range 2.5"),)


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        ("", "empty line"),
        ("   \t ", "empty line"),
        ("{Id 1}", "empty type word"),
        ("} PING", "unbalanced braces"),
        ("PING {Id 1", "unbalanced braces"),
        ("PING {Id 1}}", "unbalanced braces"),
        ("PING} {Id 1}", "unbalanced braces"),
        ("PING {Id {1}}", "nested '{'"),
        ("PING {Id {1", "nested '{'"),
        ("PING xyz", "text outside a {...} block: 'xyz'"),
        ("PING {Id 1} xyz {Time 2}", "text outside a {...} block: 'xyz'"),
        ("PING {Id 1} xyz}", "text outside a {...} block: 'xyz'"),
        ("PING {}", "empty block"),
        ("PING {   }", "empty block"),
        ("PING {Id 1}\nPING", "line break inside a line"),
    ],
)
def test_parse_errors_are_clear(line: str, reason: str) -> None:
    with pytest.raises(RemoteProtocolError) as info:
        parse_line(line)
    assert reason in str(info.value)


def test_long_stray_text_is_shortened_in_the_reason() -> None:
    with pytest.raises(RemoteProtocolError) as info:
        parse_line("PING " + "x" * 500)
    assert len(str(info.value)) < 100


# --- typed accessors -------------------------------------------------------------------------

M = parse_line(
    "T {F 1.5} {Neg -2e-3} {I 42} {B FALSE} {V 1.5,0,-2.25} {V2 1,2} {Nan nan} {Inf inf} "
    "{Big 1e999} {Word abc} {Empty} {Spaced 1, 2, 3} {Under 1_0} {Arabic ١٢}"
)


def test_get_float() -> None:
    assert M.get_float("F") == 1.5
    assert M.get_float("Neg") == -0.002
    assert M.get_float("I") == 42.0
    assert M.get_float("F", min_value=1.5, max_value=1.5) == 1.5
    assert M.get_float("Absent", default=-1.0) == -1.0


@pytest.mark.parametrize(
    ("key", "kwargs", "reason"),
    [
        ("Word", {}, "Word: 'abc' is not a number"),
        ("Nan", {}, "Nan: 'nan' is not a number"),
        ("Inf", {}, "Inf: 'inf' is not a number"),
        ("Big", {}, "Big: '1e999' is not a finite number"),
        ("Empty", {}, "Empty: '' is not a number"),
        ("Under", {}, "Under: '1_0' is not a number"),
        ("Arabic", {}, "is not a number"),
        ("F", {"min_value": 0.0, "max_value": 1.0}, "F: '1.5' is out of range [0.0, 1.0]"),
        ("Neg", {"min_value": 0.0}, "Neg: '-2e-3' is below the minimum 0.0"),
        ("F", {"max_value": 1.0}, "F: '1.5' is above the maximum 1.0"),
        ("Absent", {}, "missing {Absent ...}"),
    ],
)
def test_get_float_errors(key: str, kwargs: dict[str, float], reason: str) -> None:
    with pytest.raises(RemoteProtocolError) as info:
        M.get_float(key, **kwargs)
    assert reason in str(info.value)


def test_get_int() -> None:
    assert M.get_int("I") == 42
    assert M.get_int("I", min_value=42, max_value=42) == 42
    assert M.get_int("Absent", default=3) == 3
    for key, reason in [
        ("F", "F: '1.5' is not an integer"),
        ("Word", "Word: 'abc' is not an integer"),
        ("Absent", "missing {Absent ...}"),
    ]:
        with pytest.raises(
            RemoteProtocolError, match=reason.replace("{", r"\{").replace(".", r"\.")
        ):
            M.get_int(key)
    with pytest.raises(RemoteProtocolError, match="out of range"):
        M.get_int("I", min_value=0, max_value=10)


def test_get_int_within_the_interpreters_own_lower_digit_limit() -> None:
    """``PYTHONINTMAXSTRDIGITS`` (or ``sys.set_int_max_str_digits``) may set Python's limit
    below the 4300 the codec assumed: a 1000-digit count then raised ``ValueError`` from
    ``int()``. The codec now takes the lower of the two."""
    limit = sys.get_int_max_str_digits()
    sys.set_int_max_str_digits(640)
    try:
        line = parse_line(f"STEP {{Count {'9' * 1000}}} {{Small {'0' * 1000}7}}")
        with pytest.raises(RemoteProtocolError, match="out of range"):
            line.get_int("Count", min_value=1, max_value=10)
        with pytest.raises(RemoteProtocolError, match="more than 640 digits"):
            line.get_int("Count")
        assert line.get_int("Small") == 7
    finally:
        sys.set_int_max_str_digits(limit)


def test_get_bool() -> None:
    assert M.get_bool("B") is False
    assert parse_line("X {A tRuE}").get_bool("a") is True
    assert M.get_bool("Absent", default=True) is True
    with pytest.raises(RemoteProtocolError, match="Word: 'abc' is not true or false"):
        M.get_bool("Word")
    with pytest.raises(RemoteProtocolError, match="missing"):
        M.get_bool("Absent")


def test_get_vector() -> None:
    assert M.get_vector("V") == (1.5, 0.0, -2.25)
    assert M.get_vector("V2", 2) == (1.0, 2.0)
    assert M.get_vector("V2", None) == (1.0, 2.0)
    assert M.get_vector("Absent", default=(0.0, 0.0, 0.0)) == (0.0, 0.0, 0.0)
    cases = [
        ("V2", "V2: '1,2' has 2 components, expected 3"),
        ("Spaced", "component 1 (' 2') is not a number"),
        ("Word", "Word: 'abc' has 1 components"),
        ("Absent", "missing {Absent ...}"),
    ]
    for key, reason in cases:
        with pytest.raises(RemoteProtocolError) as info:
            M.get_vector(key)
        assert reason in str(info.value)
    with pytest.raises(RemoteProtocolError, match="is not a finite number"):
        parse_line("X {V 1,1e999,0}").get_vector("V")
    with pytest.raises(RemoteProtocolError, match="is not a number"):
        parse_line("X {V 1,nan,0}").get_vector("V")


def test_require() -> None:
    assert M.require("word") == "abc"
    assert M.require("Empty") == ""
    with pytest.raises(RemoteProtocolError) as info:
        M.require("Name")
    assert str(info.value) == "missing {Name ...}"
    assert M.get("Name") is None
    assert M.get("Name", "x") == "x"
    assert not M.has("Name")


# --- formatting ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (True, "true"),
        (False, "false"),
        (np.bool_(True), "true"),
        (7, "7"),
        (-12345678901234567890, "-12345678901234567890"),
        (np.int64(-3), "-3"),
        (1.5, "1.500000"),
        (-0.0, "-0.000000"),
        (1e-7, "0.000000"),
        (np.float32(0.25), "0.250000"),
        (np.array(2.5), "2.500000"),
        ((1.5, 0, -2.25), "1.500000,0,-2.250000"),
        ([1, 2], "1,2"),
        (np.array([0.5, -1.0, 3.0]), "0.500000,-1.000000,3.000000"),
        (np.array([1, 2, 3]), "1,2,3"),
        ("R1", "R1"),
        ("a  b", "a  b"),
    ],
)
def test_format_values(value: object, text: str) -> None:
    assert format_message("X", ("K", value)) == f"X {{K {text}}}\r\n".encode()


def test_format_empty_string_value() -> None:
    assert format_message("X", ("K", "")) == b"X {K}\r\n"
    assert parse_line("X {K}").get("K") == ""


@pytest.mark.parametrize(
    ("type_", "field", "reason"),
    [
        ("X", ("K", "a{b"), "contains '{'"),
        ("X", ("K", "a}b"), "contains '}'"),
        ("X", ("K", "a\rb"), "contains '\\r'"),
        ("X", ("K", "a\nb"), "contains '\\n'"),
        ("X", ("", 1), "empty key"),
        ("X", ("A B", 1), "contains a brace or whitespace"),
        ("X", ("A{", 1), "contains a brace or whitespace"),
        ("X", ("A\n", 1), "contains a brace or whitespace"),
        ("X", ("K", math.nan), "not a finite number"),
        ("X", ("K", math.inf), "not a finite number"),
        ("X", ("K", (1.0, -math.inf)), "not a finite number"),
        ("X", ("K", np.array([1.0, np.nan])), "not a finite number"),
        ("X", ("K", ()), "empty vector"),
        ("X", ("K", ("a", "b")), "is not a number"),
        ("X", ("K", (True, 1)), "is not a number"),
        ("X", ("K", np.zeros((2, 2))), "is not a vector"),
        ("X", ("K", None), "cannot format a NoneType value"),
        ("X", ("K", {"a": 1}), "cannot format a dict value"),
        ("X", ("Name", "F1 Range 2.5"), "would read back as several fields"),
        ("", ("K", 1), "empty type word"),
        ("A B", ("K", 1), "contains a brace or whitespace"),
        ("A{", ("K", 1), "contains a brace or whitespace"),
    ],
)
def test_format_errors(type_: str, field: tuple[str, object], reason: str) -> None:
    with pytest.raises(LocalProtocolError) as info:
        format_message(type_, field)
    assert reason in str(info.value)


def test_format_rejects_a_non_pair_field() -> None:
    with pytest.raises(LocalProtocolError, match="not a"):
        format_message("X", ("K", 1, 2))  # type: ignore[arg-type]


def test_free_text_value_that_looks_like_fields_is_allowed() -> None:
    line = format_message("ERR", ("Command", "X"), ("Reason", "Name F1 Range 2.5"))
    assert parse_line(line.decode()).get("Reason") == "Name F1 Range 2.5"


def test_format_error_sanitises() -> None:
    line = format_error("DRIVE", "missing {Name ...}\r\nsecond line")
    assert line == b"ERR {Command DRIVE} {Reason missing (Name ...) second line}\r\n"
    assert format_error("", "") == b"ERR {Command UNKNOWN} {Reason unspecified}\r\n"
    assert format_error("A B{", "x") == b"ERR {Command A_B(} {Reason x}\r\n"
    assert len(format_error("X", "y" * 100_000)) < 1100


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=60), st.text(max_size=300))
def test_format_error_never_fails_and_parses(command: str, reason: str) -> None:
    line = format_error(command, reason)
    assert line.endswith(b"\r\n")
    out = LineDecoder().feed(line)
    assert len(out) == 1
    m = out[0]
    assert isinstance(m, Message), m
    assert m.type == "ERR"
    assert m.require("Command")
    assert m.require("Reason")


# --- the decoder -----------------------------------------------------------------------------


def _feed_all(decoder: LineDecoder, chunks: list[bytes]) -> list[Message | LineError]:
    out: list[Message | LineError] = []
    for chunk in chunks:
        out += decoder.feed(chunk)
    return out


@pytest.mark.parametrize("ending", [b"\r\n", b"\n", b"\r", b"\n\r", b"\r\n\r\n", b"\n\n\n"])
def test_line_endings(ending: bytes) -> None:
    data = b"PING {Id 1}" + ending + b"PING {Id 2}" + ending
    expected = [msg("PING", ("Id", "1")), msg("PING", ("Id", "2"))]
    assert LineDecoder().feed(data) == expected
    assert _feed_all(LineDecoder(), [data[i : i + 1] for i in range(len(data))]) == expected


def test_crlf_split_across_feeds_is_harmless() -> None:
    decoder = LineDecoder()
    assert decoder.feed(b"PING {Id 1}\r") == [msg("PING", ("Id", "1"))]
    assert decoder.feed(b"\n") == []
    assert decoder.feed(b"PING") == []
    assert decoder.buffered_bytes == 4
    assert decoder.feed(b"\r\n") == [msg("PING")]


def test_empty_and_blank_lines_are_skipped() -> None:
    assert LineDecoder().feed(b"\r\n\n \t \r\nPING\r\n\r\n") == [msg("PING")]


def test_malformed_line_is_reported_and_the_stream_goes_on() -> None:
    decoder = LineDecoder()
    out = decoder.feed(b"drive {Linear 1\r\nPING\r\n")
    assert out[0] == LineError(
        "unbalanced braces: '{' at column 6 is never closed", "drive {Linear 1"
    )
    assert isinstance(out[0], LineError)
    assert out[0].command == "DRIVE"
    assert not out[0].fatal
    assert out[1] == msg("PING")
    assert not decoder.failed


def test_invalid_utf8_is_a_line_error() -> None:
    out = LineDecoder().feed(b"PING {Id \xff\xfe}\r\nPING\r\n")
    assert isinstance(out[0], LineError)
    assert out[0].reason == "invalid UTF-8 at byte 9"
    assert out[0].command == "PING"
    assert not out[0].fatal
    assert out[1] == msg("PING")


def test_utf8_split_across_feeds_decodes() -> None:
    data = "PING {Id café}\n".encode()
    out = _feed_all(LineDecoder(), [data[i : i + 1] for i in range(len(data))])
    assert out == [msg("PING", ("Id", "café"))]


def test_line_error_command() -> None:
    assert LineError("r", "drive {x").command == "DRIVE"
    assert LineError("r", "  sen{x").command == "SEN"
    assert LineError("r", "{Id 1}").command == "UNKNOWN"
    assert LineError("r", "").command == "UNKNOWN"


def test_line_error_line_is_truncated() -> None:
    out = LineDecoder().feed(b"PING " + b"x" * 1000 + b"\n")
    assert isinstance(out[0], LineError)
    assert len(out[0].line) == 200


def test_line_at_the_limit_is_accepted() -> None:
    line = b"PING {Id " + b"x" * 91 + b"}"
    assert len(line) == 101
    assert LineDecoder(max_line_bytes=101).feed(line + b"\r\n")[0] == msg("PING", ("Id", "x" * 91))
    out = LineDecoder(max_line_bytes=100).feed(line + b"\r\n")
    assert len(out) == 1 and isinstance(out[0], LineError) and out[0].fatal


def test_over_long_line_is_fatal_before_its_end_arrives() -> None:
    decoder = LineDecoder(max_line_bytes=50)
    out = decoder.feed(b"PING {Id 1}\r\nDRIVE {Name " + b"x" * 100)
    assert out[0] == msg("PING", ("Id", "1"))
    error = out[1]
    assert isinstance(error, LineError)
    assert error.fatal
    assert error.reason == "line longer than 50 bytes"
    assert error.command == "DRIVE"
    assert decoder.failed
    assert decoder.feed(b"}\r\nPING\r\n") == []
    assert decoder.buffered_bytes == 0


def test_over_long_line_byte_at_a_time() -> None:
    decoder = LineDecoder(max_line_bytes=20)
    out = _feed_all(decoder, [b"x"] * 20)
    assert out == []
    out = decoder.feed(b"x")
    assert len(out) == 1 and isinstance(out[0], LineError) and out[0].fatal
    assert decoder.feed(b"\nPING\n") == []


def test_over_long_line_stops_later_lines_in_the_same_feed() -> None:
    decoder = LineDecoder(max_line_bytes=20)
    out = decoder.feed(b"PING\n" + b"y" * 30 + b"\nPING\n")
    assert out[0] == msg("PING")
    assert isinstance(out[1], LineError) and out[1].fatal
    assert len(out) == 2


def test_bad_max_line_bytes() -> None:
    with pytest.raises(LocalProtocolError):
        LineDecoder(0)
    with pytest.raises(LocalProtocolError):
        LineDecoder(True)


def test_garbage_around_frames() -> None:
    data = b"\x00\x01}{ garbage\r\nPING {Id 1}\n\xff\xff\nzz yy\nPING {Id 2}\r"
    out = LineDecoder().feed(data)
    messages = [item for item in out if isinstance(item, Message)]
    errors = [item for item in out if isinstance(item, LineError)]
    assert messages == [msg("PING", ("Id", "1")), msg("PING", ("Id", "2"))]
    assert len(errors) == 3
    assert not any(e.fatal for e in errors)
