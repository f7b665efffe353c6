"""A robot's flight state as a transition table (the supervisor in :mod:`skeye.control.robots`).

How this works: :data:`TRANSITIONS` maps ``(state, event) -> state``; :func:`transition` looks a
pair up and raises LocalProtocolError naming both when the table has no such pair, before any
command is sent. ``failed`` is reachable from every state (a physics stop, a crash), and so is
``reset`` (the simulator respawned the robot: it stands landed, or hovers where it was put).
"""

from __future__ import annotations

import enum

from skeye.errors import LocalProtocolError


class FlightState(enum.Enum):
    LANDED = "landed"
    TAKING_OFF = "taking_off"
    FLYING = "flying"
    HOLDING = "holding"
    LANDING = "landing"
    FAILED = "failed"


_S = FlightState
_AIRBORNE = (_S.TAKING_OFF, _S.FLYING, _S.HOLDING, _S.LANDING)
TRANSITIONS: dict[tuple[FlightState, str], FlightState] = {
    (_S.LANDED, "take_off"): _S.TAKING_OFF,
    (_S.HOLDING, "take_off"): _S.TAKING_OFF,
    (_S.FLYING, "take_off"): _S.TAKING_OFF,
    (_S.LANDING, "take_off"): _S.TAKING_OFF,
    (_S.LANDED, "velocity"): _S.FLYING,
    (_S.LANDED, "hold"): _S.LANDED,
    (_S.LANDED, "land"): _S.LANDED,
    (_S.LANDED, "landed"): _S.LANDED,
    **{(s, "move"): _S.FLYING for s in _AIRBORNE},
    **{(s, "velocity"): _S.FLYING for s in _AIRBORNE},
    **{(s, "hold"): _S.HOLDING for s in _AIRBORNE},
    **{(s, "arrived"): _S.HOLDING for s in _AIRBORNE},
    **{(s, "land"): _S.LANDING for s in _AIRBORNE},
    **{(s, "landed"): _S.LANDED for s in _AIRBORNE},
    **{(s, "failed"): _S.FAILED for s in FlightState},
    **{(s, "reset"): _S.LANDED for s in FlightState},
}
"""``(state, event) -> state``; a pair not in the table is an illegal request."""


def transition(state: FlightState, event: str, who: str = "robot") -> FlightState:
    """The state after ``event``; LocalProtocolError naming both when it is not allowed."""
    new = TRANSITIONS.get((state, event))
    if new is None:
        hint = " (call take_off() first)" if state is _S.LANDED else ""
        raise LocalProtocolError(f"{who}: cannot {event} while {state.value}{hint}")
    return new
