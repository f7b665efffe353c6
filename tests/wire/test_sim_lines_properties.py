"""Property tests of the simulator protocol's line syntax (skeye.wire.sim_lines): round trips
and fuzzing ("arbitrary bytes give a message or a line error, never another exception")."""

from __future__ import annotations

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from skeye.errors import LocalProtocolError
from skeye.wire.sim_lines import (
    FREE_TEXT_KEYS,
    LineDecoder,
    LineError,
    Message,
    format_error,
    format_message,
    parse_line,
)


def _feed_all(decoder: LineDecoder, chunks: list[bytes]) -> list[Message | LineError]:
    out: list[Message | LineError] = []
    for chunk in chunks:
        out += decoder.feed(chunk)
    return out


# --- property tests --------------------------------------------------------------------------

TYPE_WORDS = st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,11}", fullmatch=True)
KEYS = st.one_of(
    st.from_regex(r"[A-Za-z][A-Za-z0-9_.]{0,11}", fullmatch=True),
    st.text(
        st.characters(blacklist_categories=("Cs", "Zs", "Zl", "Zp", "Cc")), min_size=1, max_size=8
    ).filter(lambda k: "{" not in k and "}" not in k and not any(c.isspace() for c in k)),
    st.sampled_from(sorted(FREE_TEXT_KEYS)),
)
FLOATS = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e9, max_value=1e9)
INTS = st.integers(min_value=-(2**70), max_value=2**70)
STRINGS = st.text(
    st.characters(blacklist_categories=["Cs"], blacklist_characters="{}\r\n"), max_size=40
)
VECTORS = st.lists(st.one_of(FLOATS, INTS), min_size=1, max_size=6)
VALUES = st.one_of(st.booleans(), INTS, FLOATS, STRINGS, VECTORS, VECTORS.map(tuple))


def _expected_text(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return f"{value:.6f}"
    if isinstance(value, str):
        return value.strip()
    assert isinstance(value, list | tuple)
    return ",".join(_expected_text(v) for v in value)


def _check_value(m: Message, index: int, key: str, value: object) -> None:
    """The typed accessor for the value's kind gives the value back (floats to 6 decimals)."""
    got_key, got_text = m.fields[index]
    assert got_key == key
    assert got_text == _expected_text(value)
    first = next(i for i, (k, _) in enumerate(m.fields) if k.casefold() == key.casefold())
    if first != index:  # a repeated key: the accessors read the first one
        return
    if isinstance(value, bool):
        other_case = key.swapcase()
        assert m.get_bool(other_case if other_case.casefold() == key.casefold() else key) is value
    elif isinstance(value, int):
        assert m.get_int(key) == value
    elif isinstance(value, float):
        assert m.get_float(key) == float(f"{value:.6f}")
        assert abs(m.get_float(key) - value) <= 5e-7 + 1e-15 * abs(value)
    elif isinstance(value, list | tuple):
        expected = tuple(float(v) if isinstance(v, int) else float(f"{v:.6f}") for v in value)
        assert m.get_vector(key, len(value)) == expected


@settings(max_examples=300, deadline=None)
@given(
    TYPE_WORDS,
    st.lists(st.tuples(KEYS, VALUES), max_size=8),
    st.integers(min_value=1, max_value=64),
)
def test_round_trip(type_: str, fields: list[tuple[str, object]], chunk: int) -> None:
    try:
        data = format_message(type_, *fields)
    except LocalProtocolError as exc:
        # The one refusal a valid value can meet: free text that would read back as fields.
        assert "would read back as several fields" in str(exc)
        assume(False)
    assert data.endswith(b"\r\n") and data.count(b"\n") == 1 and data.count(b"\r") == 1
    decoder = LineDecoder()
    out = _feed_all(decoder, [data[i : i + chunk] for i in range(0, len(data), chunk)])
    assert len(out) == 1
    m = out[0]
    assert isinstance(m, Message), m
    assert m.type == type_.upper()
    assert len(m.fields) == len(fields) == len(m.blocks)
    for index, (key, value) in enumerate(fields):
        _check_value(m, index, key, value)
    again = parse_line(m.to_bytes().decode())
    assert (again.type, again.fields) == (m.type, m.fields)


def test_value_that_would_split_is_refused_only_when_it_would() -> None:
    with pytest.raises(LocalProtocolError, match="several fields"):
        format_message("X", ("Name", "F1 Range 2.5"))
    assert parse_line(format_message("X", ("Name", "F1 Range")).decode()).get("Name") == "F1 Range"


@settings(max_examples=300, deadline=None)
@given(
    st.binary(max_size=400),
    st.lists(st.integers(min_value=1, max_value=50), min_size=1, max_size=20),
    st.sampled_from([16, 64, 65536]),
)
def test_fuzz_arbitrary_bytes(data: bytes, cuts: list[int], max_line_bytes: int) -> None:
    decoder = LineDecoder(max_line_bytes=max_line_bytes)
    pos = 0
    out: list[Message | LineError] = []
    index = 0
    while pos < len(data):
        size = cuts[index % len(cuts)]
        out += decoder.feed(data[pos : pos + size])
        pos += size
        index += 1
    for item in out:
        assert isinstance(item, Message | LineError)
        if isinstance(item, LineError):
            assert isinstance(item.command, str) and item.command
            assert len(item.line) <= 200
            format_error(item.command, item.reason)
    fatal = [i for i, item in enumerate(out) if isinstance(item, LineError) and item.fatal]
    assert fatal in ([], [len(out) - 1])


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.sampled_from([b"PING", b" {Id 1}", b"{", b"}", b"\r", b"\n", b"\r\n", b"\xff", b"x "]),
        max_size=40,
    ),
    st.integers(min_value=1, max_value=7),
)
def test_fuzz_protocol_shaped_bytes(pieces: list[bytes], chunk: int) -> None:
    data = b"".join(pieces)
    whole = LineDecoder().feed(data)
    chunked = _feed_all(LineDecoder(), [data[i : i + chunk] for i in range(0, len(data), chunk)])
    assert whole == chunked  # how the bytes arrive never changes what they mean
    assert all(isinstance(item, Message | LineError) for item in whole)
