"""The simulator protocol's codec table: typed messages <-> lines (docs/protocols/simulator.md).

How this works: :data:`CODECS` maps each type word (and :data:`SEN_CODECS` each SEN Type) to the
dataclass of :mod:`skeye.wire.sim_messages` it stands for, with that class's fields: wire key,
value kind and range, read once from the dataclass field metadata. :func:`decode` turns a parsed
:class:`~skeye.wire.sim_lines.Message` into its dataclass (every value typed and range-checked,
RemoteProtocolError naming the key and the text otherwise); :func:`encode` turns a dataclass into
one line (LocalProtocolError for a value of the wrong kind or out of range). The simulator's
streams, which write the same shape of line many times a second, use :func:`line_format`: a
precompiled :class:`~skeye.wire.sim_format.LineFormat` built from the same table, writing the
same bytes as :func:`encode`. Sans-IO: no sockets, threads or clocks.

Invariants: ``decode(parse_line(encode(m)))`` equals ``m`` for every message whose floats have
at most six decimals on the wire (the wire writes six; a field in degrees on the wire, such as
DRIVE's angles, holds ``wire * DEG``); type words and keys are case-insensitive on input.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

from skeye.errors import LocalProtocolError, RemoteProtocolError
from skeye.wire.sim_format import (
    BOOL,
    FLOAT,
    INT,
    WORD,
    Layout,
    LineFormat,
    Slot,
    floats,
    format_start_poses,
    ints,
    parse_start_poses,
)
from skeye.wire.sim_lines import (
    CONTROL_CHARACTERS,
    Message,
    clean_reason,
    format_error,
    format_message,
    parse_line,
    parse_usarsim_float,
    parse_usarsim_vector,
)
from skeye.wire.sim_messages import (
    SEN_CLASSES,
    TILT_LIMIT_RAD,
    Conf,
    Drive,
    Err,
    Geo,
    GetConf,
    GetGeo,
    GetStartPoses,
    Init,
    Nfo,
    Ping,
    Res,
    Reset,
    RobotConf,
    Sen,
    SenOther,
    Set,
    Sta,
    StartPoses,
    Step,
)

__all__ = [
    "CODECS",
    "COMMANDS",
    "COMMAND_WORDS",
    "MAX_LOCATION_M",
    "SEN_CODECS",
    "Codec",
    "DriveLimits",
    "FieldSpec",
    "decode",
    "decode_as",
    "decode_line",
    "drive_in_si",
    "encode",
    "fields_of",
    "line_format",
    "parse_value",
    "res_time_s",
    "sen_layout",
    "sen_line_format",
    "unknown_command",
    "usarsim_drive",
    "usarsim_notes",
]

_SEN_HEADER = ("Time", "Name")
MAX_LOCATION_M = 1.0e4
"""The farthest a place to spawn a robot lies from the world's origin along each axis (INIT's
and RESET's Location; a world file's start poses too): 10 km, so a spawned vehicle's
barometer stays within its atmosphere model whatever the world's origin altitude."""
T = TypeVar("T")


@dataclass(frozen=True)
class FieldSpec:
    """One block of a message: the dataclass attribute, its wire key, kind and range."""

    attr: str
    key: str
    kind: str
    required: bool
    min_value: float | None
    max_value: float | None
    scale: float = 1.0
    """field value (SI) = wire value * scale; the range is in wire units."""
    max_chars: int | None = None
    """The most characters of a word or text (None: as many as a line holds)."""


@dataclass(frozen=True)
class Codec:
    """How one message class goes on the wire: its type word and its fields in order."""

    word: str
    cls: type
    fields: tuple[FieldSpec, ...]

    def spec(self, key: str) -> FieldSpec:
        """The field with wire key ``key`` (case-insensitive); KeyError if none."""
        wanted = key.casefold()
        for f in self.fields:
            if f.key.casefold() == wanted:
                return f
        raise KeyError(key)


def _codec(cls: type) -> Codec:
    specs = []
    for f in dataclasses.fields(cls):
        if "key" not in f.metadata:
            continue
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        specs.append(
            FieldSpec(
                f.name,
                f.metadata["key"],
                f.metadata["kind"],
                required,
                f.metadata["min"],
                f.metadata["max"],
                f.metadata.get("scale", 1.0),
                f.metadata.get("max_chars"),
            )
        )
    return Codec(cls.WORD, cls, tuple(specs))  # type: ignore[attr-defined]


COMMANDS: tuple[type, ...] = (
    Init, Drive, Step, Set, Ping, GetConf, GetGeo, GetStartPoses, Reset
)
"""The commands a client sends."""

COMMAND_WORDS: frozenset[str] = frozenset(cls.WORD for cls in COMMANDS)  # type: ignore[attr-defined]
"""The type words of :data:`COMMANDS`: a client's line with any other is no command."""


def unknown_command(word: str) -> Err | None:
    """The simulator's answer to a client's line whose type word is not a command (``ERR
    {Command X} {Reason unknown command X}``); None for a command. The simulator and ``skeye
    replay`` both answer with it."""
    if word in COMMAND_WORDS:
        return None
    return Err(word, reason=f"unknown command {word}")

CODECS: dict[str, Codec] = {
    c.word: c for c in (_codec(cls) for cls in (*COMMANDS, Sta, Res, Err, Nfo))
}
"""Codec by type word: commands, STA, RES, ERR and NFO (SEN, CONF, GEO have their own)."""

SEN_CODECS: dict[str, Codec] = {cls.TYPE.lower(): _codec(cls) for cls in SEN_CLASSES}
"""Codec of each SEN class by its lower-case Type."""

_ROBOT_CONF = _codec(RobotConf)
_ROBOT_TYPES = ("aerialvehicle",)


# --- decoding --------------------------------------------------------------------------------


def parse_value(
    key: str, text: str, kind: str, min_value: float | None = None, max_value: float | None = None
) -> Any:
    """One value's text as ``kind`` within the range; RemoteProtocolError naming key and text."""
    msg = Message("", ((key, text),))
    return _read(msg, FieldSpec(key, key, kind, True, min_value, max_value))


def _too_long(spec: FieldSpec, text: str) -> str:
    return (f"{spec.key}: {clean_reason(text)[:40]!r}... of {len(text)} characters: at most "
            f"{spec.max_chars} characters")


def _read(msg: Message, spec: FieldSpec) -> Any:
    key, kind = spec.key, spec.kind
    if kind == "float":
        value = msg.get_float(key, min_value=spec.min_value, max_value=spec.max_value)
        return value * spec.scale if spec.scale != 1.0 else value
    if kind == "int":
        lo = None if spec.min_value is None else int(spec.min_value)
        hi = None if spec.max_value is None else int(spec.max_value)
        return msg.get_int(key, min_value=lo, max_value=hi)
    if kind == "bool":
        return msg.get_bool(key)
    if kind in ("word", "text"):
        text = msg.require(key)
        if spec.max_chars is not None and len(text) > spec.max_chars:
            raise RemoteProtocolError(_too_long(spec, text))
        return text
    if kind == "vec3":
        return msg.get_vector(key, 3)
    if kind == "uvec3":
        return parse_usarsim_vector(key, msg.require(key))[0]
    if kind in ("vec2", "ivec2"):
        return msg.get_vector(key, 2)
    return msg.get_vector(key, None)


def _decode_fields(codec: Codec, msg: Message, skip: Iterable[str] = ()) -> dict[str, Any]:
    out: dict[str, Any] = {}
    skipped = set(skip)
    for spec in codec.fields:
        if spec.key in skipped:
            continue
        if msg.has(spec.key):
            out[spec.attr] = _read(msg, spec)
        elif spec.required:
            msg.require(spec.key)  # raises "missing {Key ...}"
    return out


def _check_init(init: Init | Reset) -> None:
    """INIT's (and RESET's) place: a start pose or a location within the world, a rotation
    within 2 pi (RESET may give neither: where the robot was spawned)."""
    if init.rotation_rpy_rad is not None and any(abs(v) > 2 * math.pi
                                                 for v in init.rotation_rpy_rad):
        raise RemoteProtocolError(
            f"Rotation {init.rotation_rpy_rad} must be in [-2pi, 2pi] rad per axis "
            "(radians, not degrees)"
        )
    if isinstance(init, Init) and init.start is None and init.location_ned_m is None:
        raise RemoteProtocolError("INIT needs {Location x,y,z} or {Start name}")
    if init.location_ned_m is not None and any(abs(v) > MAX_LOCATION_M
                                               for v in init.location_ned_m):
        raise RemoteProtocolError(
            f"Location {init.location_ned_m} is outside the world (|x| > 10 km)"
        )


def _check_keys(codec: Codec, msg: Message) -> None:
    """A command's keys: each one the command reads, or one of USARSim's own command that skeye
    accepts and does nothing with (the class's ``IGNORED_KEYS``: INIT's Team). Any other is
    refused, naming it: a misspelt key (``STEP {Cuont 500}``) would otherwise be left unread
    and the command done without it. USARSim ignores every key its command does not read;
    its clients send only the keys it reads, which skeye reads or ignores likewise."""
    known = [f.key for f in codec.fields] + list(getattr(codec.cls, "IGNORED_KEYS", ()))
    folded = {k.casefold() for k in known}
    unknown = [k for k, _ in msg.fields if k.casefold() not in folded]
    if unknown:
        raise RemoteProtocolError(
            f"{codec.word}: unknown key(s) {unknown}; known: {', '.join(known) or 'none'}")


def _check_characters(codec: Codec, msg: Message) -> None:
    """A command's values hold no control character (:data:`CONTROL_CHARACTERS`: ESC, BEL,
    NUL, DEL, C1's CSI...): none is any value's, and one echoed back (a PING's Id, a robot's
    name in every STA line) would reach the terminal that shows the answer (``nc``, a client's
    log) and run there. Refused, naming the key and the character as ``\\xHH``."""
    for key, text in msg.fields:
        found = CONTROL_CHARACTERS.search(text)
        if found is not None:
            raise RemoteProtocolError(
                f"{codec.word}: {key} holds the control character \\x{ord(found.group()):02x}; "
                "a value is printable text")


def _check_drive_form(msg: Message) -> None:
    if msg.has("Thrust") and msg.has("AltitudeVelocity"):
        raise RemoteProtocolError(
            "DRIVE: Thrust and AltitudeVelocity both set the vertical axis; send one of them"
        )
    if not any(msg.has(k) for k in (*Drive.ATTITUDE_KEYS, *Drive.VELOCITY_KEYS,
                                     "RotationalVelocity")):
        raise RemoteProtocolError("DRIVE needs at least one velocity or attitude segment")


def _usarsim_scalars(msg: Message) -> tuple[Message, list[str]]:
    """A DRIVE's numbers read as USARSim reads them (:func:`parse_usarsim_float`): the line
    with each number that was not plain replaced by what was read, and a note for each. Only
    a key's first block is read (:meth:`Message.get`, as USARSim's ``GetArgVal``); a later
    block of the same key is left as it is, unread."""
    codec = CODECS["DRIVE"]
    fields: list[tuple[str, str]] = []
    notes: list[str] = []
    seen: set[str] = set()
    for key, text in msg.fields:
        try:
            spec: FieldSpec | None = codec.spec(key)
        except KeyError:
            spec = None
        first = key.casefold() not in seen
        seen.add(key.casefold())
        if spec is not None and spec.kind == "float" and first:
            value, note = parse_usarsim_float(spec.key, text)
            if note is not None:
                notes.append(note)
                text = repr(value)
        fields.append((key, text))
    return Message(msg.type, tuple(fields), msg.blocks), notes


def _axis_notes(msg: Message) -> list[str]:
    """Where a DRIVE gives one axis both its velocity and its angle: the velocity is flown
    (USARSim moves the vehicle at the velocity; the angle only sets its look)."""
    notes = []
    for velocity, angle in Drive.AXES[:2]:  # vertical: refused by _check_drive_form
        if msg.has(velocity) and msg.has(angle):
            notes.append(f"{angle} not flown: {velocity} sets that axis in the same DRIVE "
                         "(as in USARSim, where the velocity moves the vehicle)")
    return notes


def usarsim_notes(msg: Message) -> list[str]:
    """How a command was read where it was not plain: INIT's ``uvec3`` vectors (Location,
    Rotation; :func:`~skeye.wire.sim_lines.parse_usarsim_vector`) and DRIVE's numbers
    (:func:`~skeye.wire.sim_lines.parse_usarsim_float`) read as USARSim reads them, and a
    DRIVE axis given both its velocity and its angle; empty when all was plain.

    Raises:
        RemoteProtocolError: as :func:`decode` (a DRIVE number with no leading number).
    """
    codec = CODECS.get(msg.type)
    if codec is None:
        return []
    if codec.cls is Drive:
        return _usarsim_scalars(msg)[1] + _axis_notes(msg)
    notes = []
    for spec in codec.fields:
        text = msg.get(spec.key) if spec.kind == "uvec3" else None
        if text is not None:
            note = parse_usarsim_vector(spec.key, text)[1]
            if note is not None:
                notes.append(note)
    return notes


def usarsim_drive(msg: Message) -> Message:
    """A DRIVE line with its numbers as USARSim reads them (``0,5`` -> ``0.0``): the line
    :func:`drive_in_si` checks the limits on.

    Raises:
        RemoteProtocolError: a number with no leading number at all.
    """
    return _usarsim_scalars(msg)[0]


def _decode_sen(msg: Message) -> Sen | SenOther:
    type_name = msg.require("Type")
    codec = SEN_CODECS.get(type_name.lower())
    if codec is None:
        time_s = msg.get_float("Time", min_value=0.0)
        return SenOther(time_s, type_name, msg.require("Name"), msg.fields)
    values = _decode_fields(codec, msg)
    result: Sen = codec.cls(**values)
    return result


def _generic_fields(msg: Message) -> tuple[str, str, tuple[tuple[str, object], ...]]:
    rest = tuple((k, v) for k, v in msg.fields if k.casefold() not in ("type", "name"))
    return msg.require("Type"), msg.get("Name") or "", rest


def decode(msg: Message) -> Any:
    """The typed message a parsed line holds.

    Raises:
        RemoteProtocolError: an unknown type word, a command's key it does not know, a missing
            key, a value of the wrong kind or out of range, or a combination the protocol
            forbids (DRIVE's two forms, INIT without a place); the message says which.
    """
    word = msg.type
    if word == "SEN":
        return _decode_sen(msg)
    if word == "NFO" and msg.has("StartPoses"):
        poses = parse_start_poses(msg)
        return StartPoses(tuple((name, loc, rot) for name, (loc, rot) in poses.items()))
    if word == "CONF":
        if (msg.get("Type") or "").lower() in _ROBOT_TYPES:
            return RobotConf(**_decode_fields(_ROBOT_CONF, msg))
        return Conf(*_generic_fields(msg))
    if word == "GEO":
        return Geo(*_generic_fields(msg))
    codec = CODECS.get(word)
    if codec is None:
        raise RemoteProtocolError(f"unknown command {word}")
    if codec.cls in COMMANDS:
        _check_keys(codec, msg)
        _check_characters(codec, msg)
    if codec.cls is Drive:
        msg = usarsim_drive(msg)
        _check_drive_form(msg)
    result = codec.cls(**_decode_fields(codec, msg))
    if isinstance(result, Init | Reset):
        _check_init(result)
    return result


def decode_as(msg: Message, cls: type[T]) -> T:
    """The fields of ``msg`` read as a ``cls``, whatever its type word and ``Type`` say.

    For a reader that already knows what a line is (a client's sensor object, handed the lines
    of its own sensor): a SEN class's ``Name`` may then be left out (it reads as ``""``), and
    :class:`~skeye.wire.sim_messages.SenOther` keeps the fields as text.

    Raises:
        RemoteProtocolError: as :func:`decode`.
    """
    if cls is SenOther:
        time_s = msg.get_float("Time", min_value=0.0)
        other = SenOther(time_s, msg.get("Type") or "", msg.get("Name") or "", msg.fields)
        return other  # type: ignore[return-value]
    if issubclass(cls, Sen):
        codec = SEN_CODECS[cls.TYPE.lower()]
        named = msg.has("Name")
        values = _decode_fields(codec, msg, skip=() if named else ("Name",))
        if not named:
            values["name"] = ""
        return cls(**values)
    codec = _ROBOT_CONF if cls is RobotConf else CODECS[cls.WORD]  # type: ignore[attr-defined]
    return cls(**_decode_fields(codec, msg))


def decode_line(line: str) -> Any:
    """:func:`decode` of one line of text."""
    return decode(parse_line(line))


def res_time_s(answer: object) -> float:
    """The sim time a ``RES`` (of STEP or PING) carries; RemoteProtocolError if it has none."""
    if not isinstance(answer, Res) or answer.time_s is None:
        raise RemoteProtocolError(f"expected RES {{Time ...}}, got {answer!r}")
    return answer.time_s


@dataclass(frozen=True)
class DriveLimits:
    """A robot's limits, which bound DRIVE (its CONF's MaxSpeed, MaxClimb, MaxYawRate, MaxTilt)."""

    speed_m_s: float
    climb_m_s: float
    yaw_rate_rad_s: float
    tilt_rad: float = TILT_LIMIT_RAD


def drive_in_si(msg: Message, drive: Drive, limits: DriveLimits) -> Drive:
    """``drive`` (decoded from ``msg``) checked against a robot's limits, in m/s, rad and rad/s.

    The wire units are USARSim's (``AerialVehicle.uc``): m/s, deg/s for ``RotationalVelocity``,
    degrees for ``RollAngle`` and ``PitchAngle``. With ``Normalized true`` every one of them is
    percent of the robot's limit (bound +-100; the angles' limit is MaxTilt), as USARSim's
    ``setPitchAngle`` ... ``setRotationVelocity`` scale them. Without it the velocities are
    bound by the limits and the angles by +-(90 deg - 1 mrad).

    Raises:
        RemoteProtocolError: a value beyond its bound (naming the key and the text).
    """
    msg = usarsim_drive(msg)
    normalized = bool(drive.normalized)
    mode = drive.board_mode
    if mode is not None:
        form = Drive.BOARD_MODES.get(mode.lower())
        if form is None:
            raise RemoteProtocolError(
                f"DRIVE: BoardMode {mode!r} is not one of {', '.join(Drive.BOARD_MODES)}"
            )
        if form != drive.attitude or (form and drive.velocity):
            raise RemoteProtocolError(
                f"DRIVE: BoardMode {mode} goes with the "
                f"{'attitude (RollAngle/PitchAngle/Thrust)' if form else 'velocity'} form "
                "alone"
            )
        mode = mode.lower()
    changes: dict[str, Any] = {"board_mode": mode}
    # An axis given its velocity and its angle flies the velocity (see _axis_notes).
    if drive.forward_m_s is not None:
        changes["pitch_rad"] = None
    if drive.right_m_s is not None:
        changes["roll_rad"] = None
    for key, attr, limit in (
        ("LinearVelocity", "forward_m_s", limits.speed_m_s),
        ("LateralVelocity", "right_m_s", limits.speed_m_s),
        ("AltitudeVelocity", "up_m_s", limits.climb_m_s),
        ("RotationalVelocity", "yaw_rate_rad_s", limits.yaw_rate_rad_s),
        ("RollAngle", "roll_rad", limits.tilt_rad),
        ("PitchAngle", "pitch_rad", limits.tilt_rad),
    ):
        if getattr(drive, attr) is None or (attr in changes and changes[attr] is None):
            continue
        scale = CODECS["DRIVE"].spec(key).scale
        if normalized:
            value = msg.get_float(key, min_value=-100.0, max_value=100.0)
            changes[attr] = value / 100.0 * limit
            continue
        bound = (TILT_LIMIT_RAD if attr in ("roll_rad", "pitch_rad") else limit) / scale
        value = msg.get_float(key, min_value=-round(bound, 6), max_value=round(bound, 6))
        changes[attr] = value * scale
    return dataclasses.replace(drive, normalized=None, **changes)


# --- encoding --------------------------------------------------------------------------------


def _check_value(spec: FieldSpec, value: Any) -> object:
    kind, key = spec.kind, spec.key
    if spec.scale != 1.0 and isinstance(value, numbers.Real) and not isinstance(value, bool):
        value = float(value) / spec.scale  # SI -> the wire unit (degrees)
    if kind in ("float", "int"):
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise LocalProtocolError(f"{key}: {value!r} is not a number")
        if kind == "int" and not isinstance(value, numbers.Integral):
            raise LocalProtocolError(f"{key}: {value!r} is not an integer")
        number: float = int(value) if isinstance(value, numbers.Integral) else float(value)
        if not math.isfinite(number):
            raise LocalProtocolError(f"{key}: {value!r} is not a finite number")
        if (spec.min_value is not None and number < spec.min_value) or (
            spec.max_value is not None and number > spec.max_value
        ):
            raise LocalProtocolError(
                f"{key}: {value!r} is out of range [{spec.min_value}, {spec.max_value}]"
            )
        return value  # as given: an int stays an int (``1``, not ``1.000000``), as always
    if kind == "bool":
        if not isinstance(value, bool):
            raise LocalProtocolError(f"{key}: {value!r} is not a bool")
        return value
    if kind in ("word", "text"):
        if not isinstance(value, str):
            raise LocalProtocolError(f"{key}: {value!r} is not a str")
        if kind == "word" and (not value or any(c.isspace() for c in value)):
            raise LocalProtocolError(f"{key}: {value!r} is not one word")
        if spec.max_chars is not None and len(value) > spec.max_chars:
            raise LocalProtocolError(_too_long(spec, value))
        if (found := CONTROL_CHARACTERS.search(value)) is not None:  # the simulator refuses it
            raise LocalProtocolError(f"{key}: {value!r} holds the control character "
                                     f"\\x{ord(found.group()):02x}")
        return value
    try:
        items = tuple(value)
    except TypeError:
        raise LocalProtocolError(f"{key}: {value!r} is not a vector") from None
    size = {"vec3": 3, "uvec3": 3, "vec2": 2, "ivec2": 2}.get(kind)
    if size is not None and len(items) != size:
        raise LocalProtocolError(f"{key}: {value!r} must have {size} components")
    if not items or not all(
        isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v)
        for v in items
    ):
        raise LocalProtocolError(f"{key}: {value!r} is not a vector of finite numbers")
    if kind == "ivec2":
        if not all(float(v).is_integer() for v in items):
            raise LocalProtocolError(f"{key}: {value!r} must be whole numbers")
        return tuple(int(v) for v in items)
    return items  # as given: ints stay ints


def fields_of(message: Any) -> list[tuple[str, object]]:
    """The ``(key, value)`` blocks of a typed message, in wire order (None fields left out)."""
    if isinstance(message, Sen):
        codec = SEN_CODECS[message.TYPE.lower()]
        out: list[tuple[str, object]] = [
            ("Time", _check_value(codec.spec("Time"), message.time_s)),
            ("Type", message.TYPE),
            ("Name", _check_value(codec.spec("Name"), message.name)),
        ]
        skip: tuple[str, ...] = _SEN_HEADER
    elif isinstance(message, (Conf, Geo)):
        return [("Type", message.type), ("Name", message.name), *message.fields]
    elif isinstance(message, RobotConf):
        codec, out, skip = _ROBOT_CONF, [], ()
    else:
        codec = CODECS.get(getattr(type(message), "WORD", ""))  # type: ignore[assignment]
        if codec is None or codec.cls is not type(message):
            raise LocalProtocolError(f"{type(message).__name__} is not a simulator message")
        out, skip = [], ()
    for spec in codec.fields:
        if spec.key in skip:
            continue
        value = getattr(message, spec.attr)
        if value is not None:
            out.append((spec.key, _check_value(spec, value)))
    return out


def encode(message: Any) -> bytes:
    """One ``\\r\\n``-ended line of a typed message.

    Raises:
        LocalProtocolError: a value of the wrong kind or out of range, or text the line syntax
            cannot carry (see :func:`~skeye.wire.sim_lines.format_message`).
    """
    if isinstance(message, StartPoses):
        return format_start_poses(message.poses)
    if isinstance(message, Err) and message.name is None:
        return format_error(message.command, message.reason)
    if isinstance(message, Err):
        return format_message(
            "ERR",
            ("Command", message.command),
            ("Name", message.name),
            ("Reason", clean_reason(message.reason)),
        )
    if isinstance(message, SenOther):
        return format_message(
            "SEN",
            ("Time", message.time_s),
            ("Type", message.type),
            ("Name", message.name),
            *message.fields,
        )
    word = "CONF" if isinstance(message, RobotConf) else getattr(type(message), "WORD", "")
    return format_message(word, *fields_of(message))


# --- precompiled stream lines ----------------------------------------------------------------

_SLOTS: dict[str, Slot] = {
    "float": FLOAT,
    "int": INT,
    "bool": BOOL,
    "word": WORD,
    "vec3": floats(3),
    "uvec3": floats(3),
    "vec2": floats(2),
    "ivec2": ints(2),
}


def sen_layout(
    cls: type[Sen], keys: Iterable[str] | None = None, counts: Mapping[str, int] | None = None
) -> Layout:
    """The keys and slots of a SEN class's fields after Time, Type and Name.

    Args:
        cls: the SEN class.
        keys: the keys present (the optional ones a sensor writes), in any order; all if None.
        counts: the length of each variable-length vector (``vec``) field.
    """
    codec = SEN_CODECS[cls.TYPE.lower()]
    wanted = None if keys is None else {k.casefold() for k in keys}
    layout = []
    for spec in codec.fields:
        if spec.key in _SEN_HEADER:
            continue
        if wanted is not None and spec.key.casefold() not in wanted:
            continue
        if spec.kind == "vec":
            slot = floats((counts or {})[spec.key])
        elif spec.kind == "text":
            raise LocalProtocolError(f"{spec.key}: free text has no slot")
        else:
            slot = _SLOTS[spec.kind]
        layout.append((spec.key, slot))
    return tuple(layout)


def sen_line_format(type_name: str, name: str, layout: Layout) -> LineFormat:
    """``SEN {Time %} {Type type_name} {Name name}`` followed by ``layout``'s slots."""
    return LineFormat("SEN", [("Time", FLOAT), ("Type", type_name), ("Name", name), *layout])


def line_format(cls: type, fixed: Mapping[str, str], layout: Layout | None = None) -> LineFormat:
    """A precompiled line of ``cls`` whose ``fixed`` keys hold fixed words.

    For a SEN class the line is ``SEN {Time %} {Type T} {Name n}`` followed by ``layout``
    (:func:`sen_layout`); ``fixed`` must give the Name. For another class every field of its
    codec is a slot or, when named in ``fixed``, that word; values fill the slots in order.
    """
    if issubclass(cls, Sen):
        if layout is None:
            layout = sen_layout(cls)
        return sen_line_format(cls.TYPE, fixed["Name"], layout)
    codec = CODECS[cls.WORD]  # type: ignore[attr-defined]
    parts: list[tuple[str, str | Slot]] = []
    for spec in codec.fields:
        if spec.key in fixed:
            parts.append((spec.key, fixed[spec.key]))
        else:
            parts.append((spec.key, _SLOTS[spec.kind]))
    return LineFormat(codec.word, parts)
