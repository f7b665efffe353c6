"""Precompiled line shapes and USARSim's start-pose layout (docs/protocols/simulator.md).

How this works: a stream writes the same shape of line many times a second (``SEN {Time t}
{Type INS} {Name INS} {Location x,y,z} ...``). A :class:`Layout` names the keys of such a line
and the :class:`Slot` each value fills; :class:`LineFormat` builds the text around the values
once, so formatting a line is one ``%`` operation with the same text as
:func:`~skeye.wire.sim_lines.format_message` writes for the same fields (the tests check this).
The start poses (``NFO {StartPoses n} {Pad1 x,y,z r,p,y ...}``) do not fit ``{Key Value}`` and
have their own writer and reader here. Sans-IO: no sockets, threads or clocks.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from skeye.errors import LocalProtocolError, RemoteProtocolError
from skeye.wire.sim_lines import (
    _PLAIN_WORD,
    Message,
    _check_word,
    _format_value,
    format_message,
)

__all__ = [
    "BOOL",
    "FLOAT",
    "INT",
    "START_POSES_KEY",
    "WORD",
    "Layout",
    "LineFormat",
    "Pose",
    "Slot",
    "floats",
    "format_start_poses",
    "ints",
    "parse_start_poses",
]

@dataclass(frozen=True)
class Slot:
    """A value hole in a :class:`LineFormat`: ``count`` numbers of one kind.

    Kinds: ``f`` (float, six decimals, as :func:`format_message` writes floats), ``d`` (int),
    ``b`` (bool, ``true``/``false``), ``s`` (a word without braces or whitespace).
    """

    count: int = 1
    kind: str = "f"

    def __post_init__(self) -> None:
        if self.kind not in ("f", "d", "b", "s"):
            raise LocalProtocolError(f"slot kind must be one of f, d, b, s; got {self.kind!r}")
        if self.count < 1 or (self.kind in ("b", "s") and self.count != 1):
            raise LocalProtocolError(f"bad slot size {self.count} for kind {self.kind!r}")


FLOAT = Slot(1, "f")
INT = Slot(1, "d")
BOOL = Slot(1, "b")
WORD = Slot(1, "s")


def floats(count: int) -> Slot:
    """A vector of ``count`` floats (``{Key x,y,z}``)."""
    return Slot(count, "f")


def ints(count: int) -> Slot:
    """A vector of ``count`` ints."""
    return Slot(count, "d")


Layout = tuple[tuple[str, Slot], ...]
"""The keys of a line's fields and the slots their values fill, in order."""

_SLOT_TEXT = {"f": "%.6f", "d": "%d", "b": "%s", "s": "%s"}


class LineFormat:
    """A line whose type word, keys and fixed words are known in advance; numbers fill slots.

    Streams write the same shape of line many times a second (``SEN {Time t} {Type INS}
    {Name INS} {Location x,y,z} ...``). This builds the text around the values once, so
    :meth:`format` is one ``%`` operation: several times cheaper than :func:`format_message`,
    with the same text for the same fields (the tests check this).

    Args:
        type: the line's type word.
        fields: ``(key, value)`` pairs in order; a value is a fixed ``str`` word or a
            :class:`Slot` that :meth:`format`'s values fill, in order.
    """

    def __init__(self, type: str, fields: Sequence[tuple[str, str | Slot]]) -> None:
        _check_word("type word", type)
        parts = [type.replace("%", "%%")]
        self.size = 0
        self._bools: list[int] = []
        self._words: list[int] = []
        self._floats: list[tuple[int, str]] = []
        for key, value in fields:
            _check_word("key", key)
            if isinstance(value, Slot):
                if value.kind == "b":
                    self._bools.append(self.size)
                elif value.kind == "s":
                    self._words.append(self.size)
                elif value.kind == "f":
                    self._floats.extend((self.size + i, key) for i in range(value.count))
                text = ",".join([_SLOT_TEXT[value.kind]] * value.count)
                self.size += value.count
            else:
                _check_word(f"{key} value", value)
                text = value.replace("%", "%%")
            parts.append("{" + key.replace("%", "%%") + " " + text + "}")
        self._template = " ".join(parts) + "\r\n"
        self._plain = not (self._bools or self._words)

    def format(self, values: Sequence[object]) -> bytes:
        """The line with ``values`` (flat, one per slot element) filled in.

        Raises:
            LocalProtocolError: the wrong number of values, a non-finite float, a value of the
                wrong type, or a word holding a brace or whitespace.
        """
        if len(values) != self.size:
            raise LocalProtocolError(f"line format takes {self.size} values, got {len(values)}")
        if self._plain:
            try:
                total = sum(values)  # type: ignore[arg-type]
                if total - total == 0.0:
                    return (self._template % tuple(values)).encode()
            except TypeError:
                pass
            return self._checked(values)
        return self._checked(values)

    def _checked(self, values: Sequence[object]) -> bytes:
        """The slow path: check every value, naming the first bad one."""
        filled = list(values)
        for i, key in self._floats:
            v = filled[i]
            if isinstance(v, bool) or not isinstance(v, numbers.Real):
                raise LocalProtocolError(f"{key}: {v!r} is not a number")
            if not math.isfinite(v):
                raise LocalProtocolError(f"{key}: {v} is not a finite number")
        for i in self._bools:
            filled[i] = "true" if filled[i] else "false"
        for i in self._words:
            word = filled[i]
            if not isinstance(word, str) or not _PLAIN_WORD.fullmatch(word):
                raise LocalProtocolError(f"value {word!r} is not a word without braces or spaces")
        try:
            return (self._template % tuple(filled)).encode()
        except TypeError as exc:
            raise LocalProtocolError(f"cannot format the values: {exc}") from None


START_POSES_KEY = "StartPoses"

Pose = tuple[tuple[float, float, float], tuple[float, float, float]]


def _vector3(what: str, value: Sequence[float]) -> tuple[float, float, float]:
    try:
        items = list(value)
    except TypeError:
        raise LocalProtocolError(f"{what} must be 3 numbers, not {value!r}") from None
    if len(items) != 3:
        raise LocalProtocolError(f"{what} must be 3 numbers, not {len(items)}")
    for item in items:
        if isinstance(item, bool | np.bool_) or not isinstance(item, numbers.Real):
            raise LocalProtocolError(f"{what}: {item!r} is not a number")
        if not math.isfinite(float(item)):
            raise LocalProtocolError(f"{what}: {item!r} is not finite")
    return float(items[0]), float(items[1]), float(items[2])


def format_start_poses(
    poses: Sequence[tuple[str, Sequence[float], Sequence[float]]],
) -> bytes:
    """USARSim's one-block layout: ``NFO {StartPoses n} {Pad1 x,y,z r,p,y Pad2 x,y,z r,p,y}``.

    Each pose is ``(name, location_ned_m, rotation_rpy_rad)``; with no poses the line is
    ``NFO {StartPoses 0}``.

    Raises:
        LocalProtocolError: a name that is empty, repeated, or holds braces, commas or
            whitespace; a location or rotation that is not 3 finite numbers.
    """
    seen: set[str] = set()
    words: list[str] = []
    for pose in poses:
        if len(pose) != 3:
            raise LocalProtocolError(f"start pose {pose!r} is not (name, location, rotation)")
        name, location, rotation = pose
        _check_word("start pose name", name)
        if "," in name:
            raise LocalProtocolError(f"start pose name {name!r} contains a comma")
        if name.casefold() in seen:
            raise LocalProtocolError(f"start pose name {name!r} is repeated")
        seen.add(name.casefold())
        loc = _vector3(f"start pose {name} location", location)
        rot = _vector3(f"start pose {name} rotation", rotation)
        words.append(name)
        words.append(_format_value(name, loc))
        words.append(_format_value(name, rot))
    if not words:
        return format_message("NFO", (START_POSES_KEY, 0))
    return format_message("NFO", (START_POSES_KEY, len(seen)), (words[0], " ".join(words[1:])))


def _pose_vector(name: str, what: str, text: str) -> tuple[float, float, float]:
    try:
        x, y, z = Message("NFO", ((what, text),)).get_vector(what, 3)
    except RemoteProtocolError as exc:
        raise RemoteProtocolError(f"start pose {name}: {exc}") from None
    return x, y, z


def parse_start_poses(msg: Message) -> dict[str, Pose]:
    """The poses of a ``NFO {StartPoses n} ...`` message: name -> (location, rotation).

    Reads USARSim's one-block layout and also one block per pose; blocks after the poses are
    ignored (extensions).

    Raises:
        RemoteProtocolError: no ``StartPoses`` count, too few or misaligned tokens, a bad vector
            or a repeated name.
    """
    count = msg.get_int(START_POSES_KEY, min_value=0)
    index = next(
        (
            i
            for i, block in enumerate(msg.blocks)
            if block.split(None, 1)[0].casefold() == START_POSES_KEY.casefold()
        ),
        None,
    )
    if index is None:  # the count came from a multi-field block; no room for a layout
        if count == 0:
            return {}
        raise RemoteProtocolError(f"{{{START_POSES_KEY} {count}}} has no pose block after it")
    wanted = 3 * count
    tokens: list[str] = []
    for block in msg.blocks[index + 1 :]:
        if len(tokens) >= wanted:
            break
        tokens.extend(block.split())
    if len(tokens) != wanted:
        raise RemoteProtocolError(
            f"{{{START_POSES_KEY} {count}}} needs {wanted} tokens (name x,y,z r,p,y per pose), "
            f"the pose blocks hold {len(tokens)}"
        )
    poses: dict[str, Pose] = {}
    seen: set[str] = set()
    for i in range(0, wanted, 3):
        name, location, rotation = tokens[i : i + 3]
        if name.casefold() in seen:
            raise RemoteProtocolError(f"start pose {name!r} is repeated")
        seen.add(name.casefold())
        poses[name] = (
            _pose_vector(name, "location", location),
            _pose_vector(name, "rotation", rotation),
        )
    return poses
