"""Commands ground control accepts from a browser: validation of JSON, then the vehicle call.

How this works: ``COMMANDS`` is a table, one ``CommandSpec`` per command the page can send (the
skeye packets of docs/protocols/packets.md, in SI with units in the argument names).
``parse_command(name, body)`` checks a decoded JSON object against it: unknown command, unknown
or missing argument, wrong type (a JSON ``true`` is not a number), non-finite number, value out
of range (a whole number too large for a float included) or not one of the choices all raise
``LocalProtocolError`` naming the argument and what was expected. Nothing here does I/O:
``run_command(vehicle, command)`` is the one place a parsed command becomes a
``skeye.link.Vehicle`` call (and so one packet on the wire).

Ranges are what the wire can carry (int16 mm/s, uint16 mm, ...) narrowed to what makes sense
for a small multirotor. Speeds have one more bound, the vehicle's own: :class:`VehicleLimits`
holds the ``[controller]`` limits of the robot file (``max_speed_m_s``, ``max_climb_m_s``,
``max_yaw_rate_rad_s``), the same numbers the pilot flies by; a speed over them is refused with
the limit and where it comes from, and ``describe_commands`` advertises it (``max`` and
``limit``) to the page. Whether the vehicle accepts a value *now* is the vehicle's call, and its
refusal comes back as a RESULT with a code and a reason.

The table is also the page's one source for its forms (static/js/forms.js builds every field
from ``describe_commands``): each ``Arg`` carries its label, the unit the page shows (rad/s as
°/s: ``DISPLAY_FACTORS``), the input step and the field's starting value; ``KEYBOARD`` holds the
keyboard flying's speed field, yaw rate, duration and renewal period (``describe_keyboard``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from skeye.errors import LocalProtocolError
from skeye.link.vehicle import (
    Vehicle,
    goto_gps_command,
    move_by_command,
    pad_mode_command,
    velocity_command,
)
from skeye.wire.packets import Ack, Result

Value = float | str


@dataclass(frozen=True)
class VehicleLimits:
    """The vehicle's speed limits: its robot file's ``[controller]`` table."""

    max_speed_m_s: float
    max_climb_m_s: float
    max_yaw_rate_rad_s: float
    source: str  # where they come from, for messages: "robot file hummingbird"

    @classmethod
    def for_robot(cls, robot: str, robot_dirs: tuple[Path, ...] = ()) -> VehicleLimits:
        """The limits of a robot class (name or TOML path), as ``skeye sim`` loads it (with
        its ``--robot-dir`` folders)."""
        from skeye.robots.config import load_robot_config

        config = load_robot_config(robot, robot_dirs)
        c = config.controller
        return cls(c.max_speed_m_s, c.max_climb_m_s, c.max_yaw_rate_rad_s,
                   f"robot file {config.class_name}")

    def bound(self, kind: str) -> tuple[float, str]:
        """The limit for ``kind`` ('speed', 'climb', 'yaw_rate') and its key in the file."""
        key = {"speed": "max_speed_m_s", "climb": "max_climb_m_s",
               "yaw_rate": "max_yaw_rate_rad_s"}[kind]
        return float(getattr(self, key)), key


# The SI unit of an argument, from the suffix of its name (longest suffix first).
SI_UNITS: tuple[tuple[str, str], ...] = (
    ("_rad_s", "rad/s"), ("_m_s", "m/s"), ("_rad", "rad"), ("_deg", "°"), ("_m", "m"),
    ("_s", "s"),
)
# Units the page may show instead of the SI one: (SI unit, display unit) -> factor, display =
# SI * factor. The page's conversions (static/js/units.js) hold the same pairs.
DISPLAY_FACTORS: dict[tuple[str, str], float] = {
    ("rad/s", "°/s"): 180.0 / math.pi,
    ("rad", "°"): 180.0 / math.pi,
}


def si_unit(name: str) -> str:
    """The SI unit an argument name ends in ("" for none: a choice)."""
    return next((unit for suffix, unit in SI_UNITS if name.endswith(suffix)), "")


@dataclass(frozen=True)
class Arg:
    """One argument: a number in ``[lo, hi]`` or a string from ``choices``.

    ``lo``, ``hi``, ``default`` and ``initial`` are in the SI unit of the name; ``label``,
    ``unit``, ``step`` and ``initial`` describe the page's field: its short label, the unit it
    shows (default: the SI unit; else a key of ``DISPLAY_FACTORS``), the input's step in that
    unit, and the value the field starts with (default: ``default``; None: blank).
    """

    name: str
    lo: float = -math.inf
    hi: float = math.inf
    default: Value | None = None  # None: required
    choices: tuple[str, ...] = ()
    help: str = ""
    limit: str = ""  # a VehicleLimits bound on |value|: "speed", "climb" or "yaw_rate"
    label: str = ""  # the page's label (default: the name)
    unit: str = ""  # the unit the page shows (default: the SI unit)
    step: float | None = None  # the page's input step, in ``unit``
    initial: Value | None = None  # the page's starting value (default: ``default``)

    def __post_init__(self) -> None:
        if not self.choices and (self.si_unit, self.display_unit) not in DISPLAY_FACTORS and (
            self.display_unit != self.si_unit
        ):
            raise ValueError(
                f"argument {self.name!r}: the page cannot show {self.si_unit or 'no unit'} "
                f"as {self.display_unit!r} (known: {sorted(DISPLAY_FACTORS)})"
            )

    @property
    def si_unit(self) -> str:
        return si_unit(self.name)

    @property
    def display_unit(self) -> str:
        return self.unit or self.si_unit

    @property
    def display_factor(self) -> float:
        """Display value = SI value * this."""
        if self.display_unit == self.si_unit:
            return 1.0
        return DISPLAY_FACTORS[(self.si_unit, self.display_unit)]

    @property
    def start_value(self) -> Value | None:
        return self.default if self.initial is None else self.initial

    def check(self, command: str, value: Any, limits: VehicleLimits | None = None) -> Value:
        """The value if valid; raises LocalProtocolError naming what is wrong (for a speed
        over the vehicle's limit: the limit, its key and the robot file)."""
        where = f"{command}: argument {self.name!r}"
        if self.choices:
            if not isinstance(value, str) or value.lower() not in self.choices:
                raise LocalProtocolError(
                    f"{where} must be one of {', '.join(self.choices)}, got {value!r}"
                )
            return value.lower()
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise LocalProtocolError(f"{where} must be a number, got {value!r}")
        try:
            number = float(value)
        except OverflowError:  # a whole number beyond a float's 1.8e308 (JSON has no bound)
            raise LocalProtocolError(
                f"{where} must be within [{self.lo:g}, {self.hi:g}], got a whole number of "
                f"{len(str(abs(value)))} digits"
            ) from None
        if not math.isfinite(number):
            raise LocalProtocolError(f"{where} must be finite, got {value!r}")
        if not self.lo <= number <= self.hi:
            raise LocalProtocolError(
                f"{where} must be within [{self.lo:g}, {self.hi:g}], got {number:g}"
            )
        if self.limit and limits is not None:
            bound, key = limits.bound(self.limit)
            if abs(number) > bound + 1e-9:
                raise LocalProtocolError(
                    f"{where} is {number:g}, over the vehicle's limit of {bound:g} "
                    f"({key} in its {limits.source}); not sent"
                )
        return number

    def effective_range(self, limits: VehicleLimits | None) -> tuple[float, float]:
        """``[lo, hi]`` narrowed by the vehicle's limit."""
        if not self.limit or limits is None:
            return self.lo, self.hi
        bound, _ = limits.bound(self.limit)
        return max(self.lo, -bound), min(self.hi, bound)


@dataclass(frozen=True)
class CommandSpec:
    """A command the page can send: its packet, arguments and a one-line description."""

    name: str
    packet: str
    args: tuple[Arg, ...]
    help: str


COMMANDS: dict[str, CommandSpec] = {
    spec.name: spec
    for spec in (
        CommandSpec(
            "velocity",
            "VELOCITY 0x80",
            (
                Arg("forward_m_s", -5.0, 5.0, 0.0, help="body forward", limit="speed",
                    label="fwd", step=0.1),
                Arg("right_m_s", -5.0, 5.0, 0.0, help="body right", limit="speed",
                    label="right", step=0.1),
                Arg("up_m_s", -3.0, 3.0, 0.0, help="positive up", limit="climb", label="up",
                    step=0.1),
                Arg("yaw_rate_rad_s", -3.0, 3.0, 0.0, help="clockwise seen from above",
                    limit="yaw_rate", label="yaw", unit="°/s", step=5.0),
                Arg("duration_s", 0.0, 65.0, 0.0, help="0 = until replaced", label="for",
                    step=0.5, initial=2.0),
            ),
            "fly at absolute body-frame velocities",
        ),
        CommandSpec(
            "move_by",
            "MOVE_BY 0x81",
            (
                Arg("forward_m", -1000.0, 1000.0, 0.0, help="or north in the world frame",
                    label="fwd/N", step=0.5, initial=1.0),
                Arg("right_m", -1000.0, 1000.0, 0.0, help="or east in the world frame",
                    label="right/E", step=0.5),
                Arg("up_m", -100.0, 100.0, 0.0, label="up", step=0.5),
                Arg("yaw_rad", -2 * math.pi, 2 * math.pi, 0.0, label="yaw", unit="°",
                    step=15.0),
                Arg("frame", default="body", choices=("body", "world"), label="frame"),
                Arg("speed_m_s", 0.05, 10.0, 1.0, limit="speed", label="at", step=0.1,
                    initial=0.5),
            ),
            "move by distances relative to the current position",
        ),
        CommandSpec(
            "goto_gps",
            "GOTO_GPS 0x82",
            (
                Arg("latitude_deg", -90.0, 90.0, label="lat", step=0.00001),
                Arg("longitude_deg", -180.0, 180.0, label="lon", step=0.00001),
                Arg("height_m", 0.0, 1000.0, help="above the ground at the take-off point",
                    label="height above ground", step=0.5, initial=2.0),
                Arg("speed_m_s", 0.05, 10.0, 1.0, limit="speed", label="at", step=0.1),
            ),
            "fly to GPS coordinates",
        ),
        CommandSpec(
            "take_off",
            "TAKE_OFF 0x83",
            (Arg("height_m", 0.1, 100.0, 1.0, help="above the ground under the vehicle",
                 label="height above ground", step=0.1, initial=1.5),),
            "start the motors and climb",
        ),
        CommandSpec("land", "LAND 0x84", (), "descend and stop the motors"),
        CommandSpec("hold", "HOLD 0x85", (), "stop and hover here"),
        CommandSpec("reset", "RESET 0x88", (),
                    "bring a crashed vehicle back at home (the simulator respawns it)"),
        CommandSpec(
            "pad_mode",
            "PAD_MODE 0x86",
            (
                Arg("mode", choices=("off", "hold", "land"), label="mode"),
                # the paper's 5 cm and 0.3 m/s
                Arg("deadband_m", 0.0, 2.0, 0.05, label="deadband", step=0.01),
                Arg("max_speed_m_s", 0.05, 5.0, 0.3, limit="speed", label="max",
                    step=0.05),
            ),
            "landing pad: off, hold over the pad, or land on it",
        ),
    )
}


@dataclass(frozen=True)
class KeyboardSpec:
    """The page's keyboard flying: held keys send ``velocity`` with each axis at ``speed``
    (a field of the page, checked like an argument), the yaw keys at ``yaw_rate_rad_s``, for
    ``duration_s``, renewed every ``repeat_s`` while held (so a lost page or link stops the
    vehicle by itself); every component is also kept inside the ``velocity`` argument's range."""

    speed: Arg
    yaw_rate_rad_s: float
    duration_s: float
    repeat_s: float


KEYBOARD = KeyboardSpec(
    Arg("speed_m_s", 0.1, 5.0, 0.5, help="each axis while its key is held", limit="speed",
        label="speed", step=0.1),
    yaw_rate_rad_s=0.6,
    duration_s=1.0,
    repeat_s=0.3,
)


@dataclass(frozen=True)
class GroundCommand:
    """A validated command: its name and every argument (defaults filled in)."""

    name: str
    args: tuple[tuple[str, Value], ...]

    def kwargs(self) -> dict[str, Value]:
        return dict(self.args)


def parse_command(
    name: str, body: object, limits: VehicleLimits | None = None
) -> GroundCommand:
    """Check ``body`` (decoded JSON: an object, or None for no arguments) against ``COMMANDS``
    and, for speeds, against the vehicle's ``limits``.

    Raises:
        LocalProtocolError: unknown command or argument, missing, wrong type or out of range.
    """
    spec = COMMANDS.get(name)
    if spec is None:
        raise LocalProtocolError(
            f"unknown command {name!r}; known commands: {', '.join(COMMANDS)}"
        )
    if body is None:
        body = {}
    if not isinstance(body, Mapping):
        raise LocalProtocolError(
            f"{name}: arguments must be a JSON object, got {type(body).__name__}"
        )
    known = {a.name for a in spec.args}
    unknown = sorted(str(k) for k in body if k not in known)
    if unknown:
        expected = ", ".join(sorted(known)) or "none"
        raise LocalProtocolError(
            f"{name}: unknown argument(s) {', '.join(unknown)}; expected: {expected}"
        )
    values: list[tuple[str, Value]] = []
    for arg in spec.args:
        if arg.name in body:
            values.append((arg.name, arg.check(name, body[arg.name], limits)))
        elif arg.default is None:
            raise LocalProtocolError(f"{name}: missing argument {arg.name!r}")
        else:
            values.append((arg.name, arg.default))
    command = GroundCommand(name, tuple(values))
    packet = _PACKETS.get(name)
    if packet is not None:  # the packet's own rules too (wire.packet_units), said as a 422 now:
        packet(**command.kwargs())  # they were raised by the send, a 500 / no WebSocket answer
    return command


_PACKETS: dict[str, Callable[..., object]] = {
    "velocity": velocity_command,
    "move_by": move_by_command,
    "goto_gps": goto_gps_command,
    "pad_mode": pad_mode_command,
}
"""The commands whose packet is built from their arguments (the same names as the
:class:`Vehicle` methods that send them): built once in :func:`parse_command` to check it."""


_RUNNERS: dict[str, Callable[..., Result | Ack]] = {
    "velocity": Vehicle.set_velocity,
    "move_by": Vehicle.move_by,
    "goto_gps": Vehicle.goto_gps,
    "take_off": Vehicle.take_off,
    "land": Vehicle.land,
    "hold": Vehicle.hold,
    "reset": Vehicle.reset,
    "pad_mode": Vehicle.pad_mode,
}


def run_command(vehicle: Vehicle, command: GroundCommand) -> Result | Ack:
    """Send ``command`` as its packet and wait for the answer.

    Raises:
        CommandRejected: the vehicle answered a RESULT with a non-zero code.
        LinkTimeout, LinkClosed: no answer / the link went away.
    """
    return _RUNNERS[command.name](vehicle, **command.kwargs())


def describe_arg(a: Arg, limits: VehicleLimits | None = None) -> dict[str, Any]:
    """One argument as JSON: bounds (SI, with the vehicle's limit), default and the page's
    field (label, SI and display unit, step, starting value)."""
    lo, hi = a.effective_range(limits)
    limit = None
    if a.limit and limits is not None:
        bound, key = limits.bound(a.limit)
        limit = {"value": bound, "key": key, "source": limits.source}
    return {
        "name": a.name,
        "min": None if math.isinf(lo) else lo,
        "max": None if math.isinf(hi) else hi,
        "limit": limit,
        "default": a.default,
        "choices": list(a.choices) or None,
        "help": a.help,
        "label": a.label or a.name,
        "si_unit": a.si_unit,
        "unit": a.display_unit,
        "step": a.step,
        "initial": a.start_value,
    }


def describe_commands(limits: VehicleLimits | None = None) -> list[dict[str, Any]]:
    """The command table as JSON, for ``GET /api/commands`` and the page's forms; ``min`` and
    ``max`` include the vehicle's limits, and ``limit`` says where a speed bound comes from."""
    return [
        {
            "name": spec.name,
            "packet": spec.packet,
            "help": spec.help,
            "args": [describe_arg(a, limits) for a in spec.args],
        }
        for spec in COMMANDS.values()
    ]


def describe_keyboard(limits: VehicleLimits | None = None) -> dict[str, Any]:
    """``KEYBOARD`` as JSON (``speed`` described as an argument, with the vehicle's limit)."""
    return {
        "speed": describe_arg(KEYBOARD.speed, limits),
        "yaw_rate_rad_s": KEYBOARD.yaw_rate_rad_s,
        "duration_s": KEYBOARD.duration_s,
        "repeat_s": KEYBOARD.repeat_s,
    }
