"""The vehicle's parameters over MAVLink's parameter protocol, sans-IO.

How this works: a :class:`ParamSpec` names one setting of the vehicle (PX4's name where PX4
has the same setting, ``SKY_`` where it is skeye's own), its range and unit, and how to read
and write it on the vehicle (``get``/``set`` callables, bound by the endpoint to the boards'
settings: envelope, speeds, failsafe timeouts). :class:`ParamTable` answers PARAM_REQUEST_LIST,
PARAM_REQUEST_READ and PARAM_SET with PARAM_VALUE messages (every value a REAL32, so PX4's
byte-wise and ArduPilot's C-cast encodings agree), and a PARAM_SET outside the range,
non-finite, of an integer type or of an unknown name is refused: the current value comes back
unchanged with a STATUSTEXT naming the problem, as PX4 does. A value set is counted
(``changed``): its PARAM_VALUE is for every ground station, as PX4 sends a changed parameter on
all its links, so that one showing the parameters does not keep a stale value.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mav

from skeye.errors import LocalProtocolError
from skeye.mavlink.codec import MavCodec, MavMessage, statustext

MAX_NAME = 16


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: its name, range, unit, meaning, and the vehicle's setting behind it."""

    name: str
    minimum: float
    maximum: float
    unit: str
    doc: str
    get: Callable[[], float]
    set: Callable[[float], None]

    def __post_init__(self) -> None:
        if not (0 < len(self.name) <= MAX_NAME and self.name.isascii()):
            raise LocalProtocolError(f"parameter name {self.name!r}: 1..16 ASCII characters")
        if not self.minimum <= self.maximum:
            raise LocalProtocolError(f"parameter {self.name}: minimum above maximum")

    def check(self, value: float) -> str | None:
        """Why ``value`` cannot be set (None when it can)."""
        if not math.isfinite(value):
            return f"{self.name}: {value} is not a number"
        if not self.minimum <= value <= self.maximum:
            return (f"{self.name} must be {self.minimum:g}..{self.maximum:g} {self.unit}, "
                    f"not {value:g}")
        return None


class ParamTable:
    """The parameter protocol over a list of :class:`ParamSpec` (order = index)."""

    def __init__(self, specs: list[ParamSpec], codec: MavCodec) -> None:
        names = [s.name for s in specs]
        if len(set(names)) != len(names):
            raise LocalProtocolError("duplicate parameter names")
        self.specs = list(specs)
        self._by_name = {s.name: i for i, s in enumerate(self.specs)}
        self.codec = codec
        self.refused = 0
        self.changed = 0  # PARAM_SETs that set a value (the caller tells every ground station)

    def value(self, name: str) -> float:
        return float(self.specs[self._by_name[name]].get())

    def value_msg(self, index: int) -> MavMessage:
        spec = self.specs[index]
        return self.codec.mav.param_value_encode(
            spec.name.encode("ascii"), float(spec.get()), mav.MAV_PARAM_TYPE_REAL32,
            len(self.specs), index)

    def handle(self, msg: MavMessage) -> list[MavMessage]:
        """Answer one PARAM_* message (others: nothing)."""
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            return [self.value_msg(i) for i in range(len(self.specs))]
        if kind == "PARAM_REQUEST_READ":
            index = int(msg.param_index)
            if index < 0:
                index = self._by_name.get(_name(msg.param_id), -1)
            if not 0 <= index < len(self.specs):
                self.refused += 1
                return statustext(self.codec, mav.MAV_SEVERITY_WARNING,
                                  f"no parameter {_name(msg.param_id)!r} (index "
                                  f"{msg.param_index})")
            return [self.value_msg(index)]
        if kind == "PARAM_SET":
            name = _name(msg.param_id)
            found = self._by_name.get(name)
            if found is None:
                self.refused += 1
                return statustext(self.codec, mav.MAV_SEVERITY_WARNING,
                                  f"no parameter {name!r}")
            index = found
            spec = self.specs[index]
            value = float(msg.param_value)
            problem = _type_problem(spec.name, int(msg.param_type)) or spec.check(value)
            if problem is None:
                try:
                    spec.set(value)
                except LocalProtocolError as exc:
                    problem = f"{spec.name}: {exc}"
            if problem is not None:
                self.refused += 1
                return [self.value_msg(index),
                        *statustext(self.codec, mav.MAV_SEVERITY_WARNING, problem)]
            self.changed += 1
            return [self.value_msg(index)]
        return []


def _type_problem(name: str, param_type: int) -> str | None:
    """Why a PARAM_SET of ``param_type`` cannot set ``name`` (every value here is a REAL32).

    An integer type's value comes byte-wise encoded (PX4's way, which MAVSDK's
    ``set_param_int`` uses): 30 arrives as the float 4.2e-44, which read as a float would
    pass a range like 0..600 and set the parameter to almost 0; so it is refused, as PX4
    refuses a type that is not the parameter's. 0 (no type given) is read as a REAL32."""
    if param_type in (0, mav.MAV_PARAM_TYPE_REAL32):
        return None
    entry = mav.enums["MAV_PARAM_TYPE"].get(param_type)
    kind = entry.name.removeprefix("MAV_PARAM_TYPE_") if entry else f"type {param_type}"
    return (f"{name} is a REAL32 (float) parameter, not {kind}: set it as a float "
            "(MAVSDK: set_param_float)")


def _name(raw: object) -> str:
    """A param_id as pymavlink gives it (str or bytes, NUL-padded) -> the name."""
    text = raw.decode("ascii", "replace") if isinstance(raw, bytes) else str(raw)
    return text.split("\x00", 1)[0]
