"""Line syntax of the simulator control protocol (docs/protocols/simulator.md, Gamebots-style).

How this works: bytes go into a :class:`LineDecoder`, which splits them at ``\\r``, ``\\n`` or
``\\r\\n``, decodes UTF-8 and hands each line to :func:`parse_line`; out come :class:`Message`
values or :class:`LineError` values, never an exception. Going the other way,
:func:`format_message` turns a type word and ``(key, value)`` pairs into one ``\\r\\n``-ended
line, one field per block (:mod:`skeye.wire.sim_format` writes the same text faster for lines
whose shape is known in advance; :mod:`skeye.wire.sim` turns messages into typed dataclasses).
No sockets, threads or clocks live here; the simulator server and the Python client are thin
adapters around these functions.

Invariants:
- A line is ``TYPE {Key Value} {Key Value} ...``. The type word and keys are case-insensitive:
  ``Message.type`` is upper-cased, keys keep their spelling and are looked up case-insensitively
  (``str.casefold``).
- Inside a block the key is everything before the first whitespace and the value the trimmed
  rest (``{Key}`` gives ``""``). Blocks never nest; text outside blocks is an error.
- A block reads as several fields (the UT2004 habit ``{Name F1 Range 2.5}``) only when it has an
  even number >= 4 of tokens, every key-position token looks like a key, and the first key is not
  a free-text key (:data:`FREE_TEXT_KEYS`). :func:`format_message` refuses a value that would read
  back that way, so whatever it writes parses back to the same fields (values trimmed).
- Typed accessors (``get_float`` ...) accept only finite decimal text and raise
  :class:`~skeye.errors.RemoteProtocolError` naming the key and the bad text.
- The decoder emits every complete line in order. Empty lines are skipped, so a ``\\r\\n`` split
  across two feeds is harmless. A line longer than ``max_line_bytes`` (even before its end
  arrives) gives a fatal ``LineError``, after which the decoder emits nothing more.
"""

from __future__ import annotations

import enum
import math
import numbers
import re
import sys
from dataclasses import dataclass

import numpy as np

from skeye.errors import LocalProtocolError, RemoteProtocolError

__all__ = [
    "DECIMAL_PATTERN",
    "ERROR_LINE_CHARS",
    "FREE_TEXT_KEYS",
    "LINE_END",
    "MAX_INT_DIGITS",
    "MISSING",
    "LineDecoder",
    "LineError",
    "Message",
    "clean_reason",
    "format_error",
    "format_message",
    "parse_line",
    "parse_usarsim_vector",
]

FREE_TEXT_KEYS = frozenset({"reason", "text", "message", "params", "note"})
"""Keys (lower-case) whose block is never split into several fields: their value is free text."""

LINE_END = b"\r\n"
ERROR_LINE_CHARS = 200
"""How much of a bad line a :class:`LineError` keeps (enough to see what went wrong)."""

_MAX_REASON_CHARS = 1000
MAX_INT_DIGITS = 4300
"""The most digits (leading zeros aside) an integer field is read with: Python's own default
limit for ``int()`` of text (``sys.int_info.default_max_str_digits``, against CVE-2020-10735),
or the interpreter's own limit where it is set lower (``PYTHONINTMAXSTRDIGITS``). No integer
field's range comes anywhere near it."""


def _max_int_digits() -> int:
    """:data:`MAX_INT_DIGITS`, or the interpreter's limit where lower (0 there: none)."""
    limit = sys.get_int_max_str_digits()
    return min(MAX_INT_DIGITS, limit) if limit > 0 else MAX_INT_DIGITS
_KEY_TOKEN = re.compile(r"[A-Za-z][A-Za-z0-9_.]*\Z")
_TYPE_WORD = re.compile(r"[^\s{}]*")
# A decimal number: its digits before the point and after it are one way to split the text
# only (``\d+(?:\.\d*)?``, never ``\d+\.?\d*``, whose two digit runs a failed match tries at
# every split: quadratic in the digits, and the regex engine holds the GIL, so one line of
# 60 000 digits stood the whole simulator still for minutes).
DECIMAL_PATTERN = r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"
_FLOAT_TEXT = re.compile(DECIMAL_PATTERN + r"\Z", re.ASCII)
_INT_TEXT = re.compile(r"[+-]?\d+\Z", re.ASCII)
_LEADING_FLOAT = re.compile(r"\s*(" + DECIMAL_PATTERN + ")", re.ASCII)
_EOL = re.compile(rb"[\r\n]")
_FIRST_WORD = re.compile(r"\s*([^\s{}]+)")


class _Missing(enum.Enum):
    MISSING = enum.auto()


MISSING = _Missing.MISSING
"""Sentinel for "no default": a missing key then raises RemoteProtocolError."""


def _missing_error(key: str) -> RemoteProtocolError:
    return RemoteProtocolError(f"missing {{{key} ...}}")


def _check_range(
    key: str, text: str, value: float, min_value: float | None, max_value: float | None
) -> None:
    if min_value is not None and value < min_value:
        if max_value is not None:
            raise RemoteProtocolError(f"{key}: {text!r} is out of range [{min_value}, {max_value}]")
        raise RemoteProtocolError(f"{key}: {text!r} is below the minimum {min_value}")
    if max_value is not None and value > max_value:
        if min_value is not None:
            raise RemoteProtocolError(f"{key}: {text!r} is out of range [{min_value}, {max_value}]")
        raise RemoteProtocolError(f"{key}: {text!r} is above the maximum {max_value}")


def _parse_float(key: str, text: str) -> float:
    """Finite decimal text -> float; anything else (NaN, inf, '1_0', '') is the peer's error."""
    if not _FLOAT_TEXT.match(text):
        raise RemoteProtocolError(f"{key}: {text!r} is not a number")
    value = float(text)
    if not math.isfinite(value):
        raise RemoteProtocolError(f"{key}: {text!r} is not a finite number")
    return value


def _quoted(text: str, limit: int = 80) -> str:
    """``text`` quoted for a note; a longer text by its start and its length, so that an answer
    that quotes it stays well within the line limit."""
    if len(text) <= limit:
        return repr(text)
    return f"{text[:limit]!r}... ({len(text)} characters)"


def _unreal_float(key: str, text: str, whole: str) -> float:
    """UnrealScript's ``float(string)`` (C ``atof``): the leading decimal number after blanks,
    ignoring the rest; 0 when there is none."""
    match = _LEADING_FLOAT.match(text)
    if match is None:
        return 0.0
    value = float(match.group(1))
    if not math.isfinite(value):
        raise RemoteProtocolError(f"{key}: {whole!r} holds a number too large ({match.group(1)})")
    return value


def parse_usarsim_float(key: str, text: str) -> tuple[float, str | None]:
    """A client's number read as UnrealScript's ``float()`` reads it (USARSim's
    ``AerialVehicle.Drive`` reads each DRIVE value so): the leading number, the rest ignored,
    so ``0,000000`` (a decimal comma) reads 0 and ``1,5`` reads 1.

    Returns:
        The value and, when the text is not a plain number, a note saying how it was read (for
        the answer and the log); None for plain text.

    Raises:
        RemoteProtocolError: text with no leading number at all (``float()`` would read 0:
            skeye refuses it rather than stop an axis on a typo), or a number too large.
    """
    stripped = text.strip()
    if _FLOAT_TEXT.match(stripped):
        return _parse_float(key, stripped), None
    if _LEADING_FLOAT.match(text) is None:
        raise RemoteProtocolError(f"{key}: {text!r} is not a number")
    value = _unreal_float(key, text, text)
    note = (f"{key} {_quoted(text)} read as {value:g} as USARSim's float() reads it (the leading "
            "number); send numbers with '.' decimals")
    return value, note


def parse_usarsim_vector(key: str, text: str) -> tuple[tuple[float, float, float], str | None]:
    """A client's ``x,y,z`` read as USARSim's ``Utilities.ParseVector`` reads it.

    USARSim splits the text at its first two commas and takes ``float()`` of each part, which
    reads a leading number and ignores the rest (no number: 0; no comma: x and y are 0 and z is
    the whole text's leading number; empty text: 0,0,0). So ``0,0000, 0,0000, 0,0000`` (decimal
    commas) reads 0,0,0 and ``1.0 2.0 -0.5`` (blanks) reads 0,0,1, as in USARSim.

    Returns:
        The vector and, when the text is not three plain comma-separated numbers, a note saying
        how it was read (for the answer and the log); None for plain text.

    Raises:
        RemoteProtocolError: a number too large to be finite.
    """
    parts = text.split(",")
    if len(parts) == 3 and all(_FLOAT_TEXT.match(p.strip()) for p in parts):
        x, y, z = (_parse_float(key, p.strip()) for p in parts)
        return (x, y, z), None
    first = text.find(",")
    x = _unreal_float(key, text[:first] if first >= 0 else "", text)
    rest = text[first + 1 :]  # the whole text when there is no comma, as USARSim's Mid(s, 0)
    second = rest.find(",")
    y = _unreal_float(key, rest[:second] if second >= 0 else "", text)
    z = _unreal_float(key, rest[second + 1 :], text)
    note = (
        f"{key} {_quoted(text)} read as {x:g},{y:g},{z:g} as USARSim's ParseVector reads it "
        "(split at the first two commas, the leading number of each part); "
        "send x,y,z with '.' decimals"
    )
    return (x, y, z), note


@dataclass(frozen=True)
class Message:
    """One parsed line.

    Attributes:
        type: the type word, upper-cased (``"DRIVE"``).
        fields: ``(key, value)`` pairs in order; keys as written, values trimmed; multi-field
            UT2004 blocks expanded into several pairs.
        blocks: the inner text of each ``{...}`` block (without braces, trimmed), for layouts
            such as USARSim's start poses that do not fit ``{Key Value}``.
    """

    type: str
    fields: tuple[tuple[str, str], ...] = ()
    blocks: tuple[str, ...] = ()

    def get(self, key: str, default: str | None = None) -> str | None:
        """The first value whose key matches ``key`` case-insensitively, else ``default``."""
        wanted = key.casefold()
        for k, v in self.fields:
            if k.casefold() == wanted:
                return v
        return default

    def has(self, key: str) -> bool:
        """Whether some field has this key (case-insensitive)."""
        return self.get(key) is not None

    def require(self, key: str) -> str:
        """The value of ``key``; RemoteProtocolError ``missing {Key ...}`` when absent."""
        value = self.get(key)
        if value is None:
            raise _missing_error(key)
        return value

    def get_float(
        self,
        key: str,
        *,
        default: float | _Missing = MISSING,
        min_value: float | None = None,
        max_value: float | None = None,
    ) -> float:
        """The value of ``key`` as a finite float within ``[min_value, max_value]``.

        A missing key gives ``default`` (unchecked) or, without one, RemoteProtocolError.
        """
        text = self.get(key)
        if text is None:
            if default is MISSING:
                raise _missing_error(key)
            return default
        value = _parse_float(key, text)
        _check_range(key, text, value, min_value, max_value)
        return value

    def get_int(
        self,
        key: str,
        *,
        default: int | _Missing = MISSING,
        min_value: int | None = None,
        max_value: int | None = None,
    ) -> int:
        """The value of ``key`` as a decimal integer within ``[min_value, max_value]``.

        Leading zeros are read away first; an integer of more than :data:`MAX_INT_DIGITS`
        digits (or the interpreter's lower limit) after them, which Python's ``int()`` refuses
        to convert, is beyond every range: refused as out of range, or as too large when there
        is no range."""
        text = self.get(key)
        if text is None:
            if default is MISSING:
                raise _missing_error(key)
            return default
        if not _INT_TEXT.match(text):
            raise RemoteProtocolError(f"{key}: {text!r} is not an integer")
        negative = text.startswith("-")
        digits = text.lstrip("+-").lstrip("0") or "0"
        most = _max_int_digits()
        if len(digits) > most:
            _check_range(key, text, -math.inf if negative else math.inf, min_value, max_value)
            raise RemoteProtocolError(
                f"{key}: {text!r} is too large an integer (more than {most} digits)")
        value = -int(digits) if negative else int(digits)
        _check_range(key, text, value, min_value, max_value)
        return value

    def get_bool(self, key: str, *, default: bool | _Missing = MISSING) -> bool:
        """The value of ``key`` as a boolean: ``true`` or ``false`` in any case."""
        text = self.get(key)
        if text is None:
            if default is MISSING:
                raise _missing_error(key)
            return default
        lowered = text.lower()
        if lowered == "true":
            return True
        if lowered == "false":
            return False
        raise RemoteProtocolError(f"{key}: {text!r} is not true or false")

    def get_vector(
        self,
        key: str,
        n: int | None = 3,
        *,
        default: tuple[float, ...] | _Missing = MISSING,
    ) -> tuple[float, ...]:
        """The value of ``key`` as ``n`` comma-separated finite numbers (any count if n is None)."""
        text = self.get(key)
        if text is None:
            if default is MISSING:
                raise _missing_error(key)
            return default
        parts = text.split(",")
        if n is not None and len(parts) != n:
            raise RemoteProtocolError(f"{key}: {text!r} has {len(parts)} components, expected {n}")
        values = []
        for i, part in enumerate(parts):
            if not _FLOAT_TEXT.match(part):
                raise RemoteProtocolError(
                    f"{key}: {text!r} component {i} ({part!r}) is not a number"
                )
            value = float(part)
            if not math.isfinite(value):
                raise RemoteProtocolError(
                    f"{key}: {text!r} component {i} ({part!r}) is not a finite number"
                )
            values.append(value)
        return tuple(values)

    def to_bytes(self) -> bytes:
        """This message's fields as one line, one field per block (see :func:`format_message`)."""
        return format_message(self.type, *self.fields)


def _block_fields(content: str) -> list[tuple[str, str]]:
    """The fields of one block's trimmed, non-empty inner text."""
    tokens = content.split()
    if (
        len(tokens) >= 4
        and len(tokens) % 2 == 0
        and tokens[0].casefold() not in FREE_TEXT_KEYS
        and all(_KEY_TOKEN.match(tokens[i]) for i in range(0, len(tokens), 2))
    ):
        return [(tokens[i], tokens[i + 1]) for i in range(0, len(tokens), 2)]
    parts = content.split(None, 1)
    return [(parts[0], parts[1].strip() if len(parts) > 1 else "")]


def _snippet(text: str, limit: int = 40) -> str:
    return text if len(text) <= limit else text[:limit] + "..."


def parse_line(line: str) -> Message:
    """Parse one line (without or with its line end) into a :class:`Message`.

    Raises:
        RemoteProtocolError: the line breaks the syntax; the message says how and where.
    """
    text = line.strip()
    if not text:
        raise RemoteProtocolError("empty line")
    if "\r" in text or "\n" in text:
        raise RemoteProtocolError("line break inside a line")
    match = _TYPE_WORD.match(text)
    assert match is not None  # the pattern matches the empty string
    type_word = match.group()
    pos = match.end()
    if not type_word:
        if text[0] == "{":
            raise RemoteProtocolError("empty type word: the line starts with '{'")
        raise RemoteProtocolError("unbalanced braces: '}' at column 0 has no '{'")
    fields: list[tuple[str, str]] = []
    blocks: list[str] = []
    length = len(text)
    while pos < length:
        char = text[pos]
        if char.isspace():
            pos += 1
            continue
        if char == "{":
            close = text.find("}", pos + 1)
            opening = text.find("{", pos + 1)
            if close < 0:
                if 0 <= opening:
                    raise RemoteProtocolError(f"nested '{{' at column {opening}")
                raise RemoteProtocolError(
                    f"unbalanced braces: '{{' at column {pos} is never closed"
                )
            if 0 <= opening < close:
                raise RemoteProtocolError(f"nested '{{' at column {opening}")
            content = text[pos + 1 : close].strip()
            if not content:
                raise RemoteProtocolError(f"empty block {{}} at column {pos}")
            blocks.append(content)
            fields.extend(_block_fields(content))
            pos = close + 1
        elif char == "}":
            raise RemoteProtocolError(f"unbalanced braces: '}}' at column {pos} has no '{{'")
        else:
            end = text.find("{", pos)
            stray = text[pos:end] if end >= 0 else text[pos:]
            stray = stray.split("}", 1)[0].strip()
            raise RemoteProtocolError(f"text outside a {{...}} block: {_snippet(stray)!r}")
    return Message(type_word.upper(), tuple(fields), tuple(blocks))


def _check_word(what: str, word: str) -> None:
    if not isinstance(word, str):
        raise LocalProtocolError(f"{what} must be a str, not {type(word).__name__}")
    if not word:
        raise LocalProtocolError(f"empty {what}")
    if any(c in "{}" or c.isspace() for c in word):
        raise LocalProtocolError(f"{what} {word!r} contains a brace or whitespace")


def _format_number(key: str, value: object) -> str:
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        raise LocalProtocolError(
            f"{key}: vector element {value!r} ({type(value).__name__}) is not a number"
        )
    return _format_scalar(key, value)


def _format_scalar(key: str, value: object) -> str:
    if isinstance(value, bool | np.bool_):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        number = float(value)
        if not math.isfinite(number):
            raise LocalProtocolError(f"{key}: {number} is not a finite number")
        return f"{number:.6f}"
    if isinstance(value, str):
        for bad in ("{", "}", "\r", "\n"):
            if bad in value:
                raise LocalProtocolError(f"{key}: value {_snippet(value)!r} contains {bad!r}")
        return value
    raise LocalProtocolError(f"{key}: cannot format a {type(value).__name__} value")


def _format_value(key: str, value: object) -> str:
    if isinstance(value, np.ndarray):
        if value.ndim == 0:
            return _format_scalar(key, value.item())
        if value.ndim != 1:
            raise LocalProtocolError(f"{key}: array of shape {value.shape} is not a vector")
        value = value.tolist()
    if isinstance(value, tuple | list):
        if not value:
            raise LocalProtocolError(f"{key}: empty vector")
        return ",".join(_format_number(key, element) for element in value)
    return _format_scalar(key, value)


_PLAIN_WORD = re.compile(r"[^\s{}]+")
_CHECKED_KEYS: set[str] = set()  # keys already validated (a small cache for the hot path)


def format_message(type: str, *fields: tuple[str, object]) -> bytes:
    """One protocol line: ``TYPE {Key Value} ...`` ending in ``\\r\\n``, one field per block.

    Values: bool -> ``true``/``false``; int -> decimal; float -> six decimals; a tuple, list or
    1-D array of numbers -> comma-joined, no spaces; str as is.

    Raises:
        LocalProtocolError: a type word or key that is empty or holds braces or whitespace; a
            value holding a brace or line break, or that is not finite; a value that would read
            back as several UT2004 fields (``{Name F1 Range 2.5}``).
    """
    _check_word("type word", type)
    parts = [type]
    checked = _CHECKED_KEYS
    for field in fields:
        if not isinstance(field, tuple) or len(field) != 2:
            raise LocalProtocolError(f"field {field!r} is not a (key, value) pair")
        key, value = field
        if key not in checked:
            _check_word("key", key)
            if len(checked) < 1024:
                checked.add(key)
        # Fast paths for the stream's common values (same text as _format_value gives).
        kind = value.__class__
        if kind is float:
            if value - value != 0.0:  # type: ignore[operator]  # NaN or infinity
                raise LocalProtocolError(f"{key}: {value} is not a finite number")
            parts.append(f"{{{key} {value:.6f}}}")
            continue
        if kind is tuple and all(e.__class__ is float for e in value):  # type: ignore[attr-defined]
            if not value or any(e - e != 0.0 for e in value):  # type: ignore[attr-defined]
                text = _format_value(key, value)  # raises with the precise reason
            parts.append("{" + key + " " + ",".join([f"{e:.6f}" for e in value]) + "}")  # type: ignore[attr-defined]
            continue
        if kind is str and isinstance(value, str) and value and _PLAIN_WORD.fullmatch(value):
            parts.append("{" + key + " " + value + "}")
            continue
        if kind is bool:
            parts.append("{" + key + (" true}" if value else " false}"))
            continue
        if kind is int:
            parts.append(f"{{{key} {value}}}")
            continue
        text = _format_value(key, value)
        block = f"{key} {text}" if text.strip() else key
        # Only a value of 3 or more words can read back as several fields; skip the rest fast.
        if len(text.split(None, 2)) > 2 and len(_block_fields(block)) != 1:
            raise LocalProtocolError(
                f"{key}: value {_snippet(text)!r} would read back as several fields"
            )
        parts.append(f"{{{block}}}")
    return " ".join(parts).encode("utf-8") + LINE_END


CONTROL_CHARACTERS = re.compile(r"[\x00-\x08\x0e-\x1f\x7f-\x9f]")
"""Control characters a terminal acts on (C0 but the blanks tab to carriage return, DEL, C1):
an answer writes them as ``\\xHH``, and a command's value holding one is refused
(:func:`skeye.wire.sim.decode`)."""


def _safe_text(text: str) -> str:
    """Text fit for a block of an answer: braces and line breaks replaced, and every control
    character but the blanks (ESC, NUL, BEL, DEL, C1's CSI...) written as ``\\xHH``, so that
    a terminal showing the line (``nc``, a client's log) shows a client's escape sequence
    instead of running it, and the text stays recognisable."""
    text = text.replace("{", "(").replace("}", ")").replace("\r", " ").replace("\n", " ")
    return CONTROL_CHARACTERS.sub(lambda m: f"\\x{ord(m.group()):02x}", text)


def clean_reason(reason: str) -> str:
    """Free text fit for ``{Reason ...}``: braces and line breaks replaced, control characters
    escaped (``\\x1b``), blanks collapsed,
    at most 1000 characters (never empty: ``unspecified``). A longer text keeps its beginning
    and its end, and says how much of its middle was left out: a reason quotes the value it
    refuses before saying what is wrong with it, and a long value must not cut that off."""
    text = " ".join(_safe_text(str(reason)).split()) or "unspecified"
    if len(text) > _MAX_REASON_CHARS:
        head = _MAX_REASON_CHARS // 2
        left_out = len(text) - _MAX_REASON_CHARS
        while True:  # the marker's own length moves what it leaves out (by a digit at most)
            marker = f" ...({left_out} characters left out)... "
            tail = _MAX_REASON_CHARS - head - len(marker)
            if len(text) - head - tail == left_out:
                break
            left_out = len(text) - head - tail
        text = text[:head] + marker + text[len(text) - tail:]
    return text


def format_error(command: str, reason: str) -> bytes:
    """``ERR {Command X} {Reason ...}``; braces and line breaks are replaced and control
    characters escaped (``\\x1b``), in the command word as in the reason, so it never fails
    and never carries a client's terminal escape back."""
    word = "_".join(_safe_text(str(command)).split()) or "UNKNOWN"
    text = clean_reason(reason)
    return f"ERR {{Command {word[:_MAX_REASON_CHARS]}}} {{Reason {text}}}".encode() + LINE_END


@dataclass(frozen=True)
class LineError:
    """A line the decoder could not turn into a Message.

    Attributes:
        reason: what is wrong, fit for ``ERR {Reason ...}``.
        line: the offending line (at most ``ERROR_LINE_CHARS`` characters of it).
        fatal: the stream cannot go on (an over-long line); the decoder emits nothing more.
    """

    reason: str
    line: str
    fatal: bool = False

    @property
    def command(self) -> str:
        """The line's first word upper-cased, or ``UNKNOWN``: what ``ERR {Command X}`` names."""
        match = _FIRST_WORD.match(self.line)
        return match.group(1).upper() if match else "UNKNOWN"


class LineDecoder:
    """Splits a byte stream into Messages and LineErrors; sans-IO (feed it whatever arrived).

    Args:
        max_line_bytes: the longest line accepted, terminator excluded.
    """

    def __init__(self, max_line_bytes: int = 65536) -> None:
        if isinstance(max_line_bytes, bool) or not isinstance(max_line_bytes, int):
            raise LocalProtocolError("max_line_bytes must be an int")
        if max_line_bytes < 1:
            raise LocalProtocolError(f"max_line_bytes must be positive, not {max_line_bytes}")
        self.max_line_bytes = max_line_bytes
        self._buffer = bytearray()
        self._scanned = 0  # bytes of _buffer already known to hold no line end
        self._failed = False

    @property
    def failed(self) -> bool:
        """True after a fatal error: the decoder ignores all further input."""
        return self._failed

    @property
    def buffered_bytes(self) -> int:
        """Bytes of an incomplete line waiting for its end."""
        return len(self._buffer)

    def feed(self, data: bytes) -> list[Message | LineError]:
        """Take the next bytes of the stream; return what the complete lines in it hold."""
        if self._failed:
            return []
        buffer = self._buffer
        buffer += data
        out: list[Message | LineError] = []
        start = 0
        while True:
            match = _EOL.search(buffer, max(start, self._scanned))
            if match is None:
                break
            end = match.start()
            if end - start > self.max_line_bytes:
                out.append(self._fail(bytes(buffer[start:end])))
                return out
            item = self._decode(bytes(buffer[start:end]))
            if item is not None:
                out.append(item)
            start = end + 1
        del buffer[:start]
        self._scanned = len(buffer)
        if len(buffer) > self.max_line_bytes:
            out.append(self._fail(bytes(buffer)))
        return out

    def _fail(self, raw: bytes) -> LineError:
        self._failed = True
        self._buffer.clear()
        self._scanned = 0
        shown = raw[: ERROR_LINE_CHARS * 4].decode("utf-8", errors="replace")
        return LineError(
            f"line longer than {self.max_line_bytes} bytes",
            shown[:ERROR_LINE_CHARS],
            fatal=True,
        )

    @staticmethod
    def _decode(raw: bytes) -> Message | LineError | None:
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            shown = raw.decode("utf-8", errors="replace")[:ERROR_LINE_CHARS]
            return LineError(f"invalid UTF-8 at byte {exc.start}", shown)
        if not line.strip():
            return None
        try:
            return parse_line(line)
        except RemoteProtocolError as exc:
            return LineError(str(exc), line.strip()[:ERROR_LINE_CHARS])
