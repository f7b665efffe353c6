"""The pilot's flight states as one transition table.

How this works: ``TRANSITIONS`` maps ``(state, event) -> next state``; ``BUSY`` lists the pairs
that are refused because the vehicle is in the middle of something it finishes by itself
(taking off, landing); every other pair not in the table is illegal in that state.
``FlightStateMachine.fire(event)`` applies the table and raises ``IllegalTransition`` with the
RESULT code the pilot answers (4 refused in this state, 5 busy), so a command that does not fit
the state is rejected before anything is sent to the simulator. States are the NAV_STATUS
states of docs/protocols/packets.md.

The sticks always win (docs/pilot.md, "Manual sticks take over"): STICKS (CTRL_INPUT with its
axis bits set, motors running) is legal in every state but CRASHED and leads to MANUAL,
whatever flew the vehicle before (a take-off, a move, a pad mode, a landing, a failsafe), as
PX4 hands an automatic mode to the sticks when they move (COM_RC_OVERRIDE). MANUAL ends as a real
autopilot's manual mode does: by a mode change from ground control (HOLD, a move, LAND), by
the motors stopping on the ground, or by losing the link the sticks come over (FAILSAFE).
CRASHED is entered from every state when the vehicle crashes, and left only by RESET (or by a
new vehicle, when the pilot re-attaches to a restarted simulator: RESPAWNED, also from every
state); the sticks do not take over a crashed vehicle.
"""

from __future__ import annotations

import threading
from enum import Enum

from skeye.errors import LocalProtocolError
from skeye.wire.packets import NavState, ResultCode


class FlightEvent(Enum):
    """What can happen to the vehicle: commands from ground control and what the vehicle sees."""

    TAKE_OFF = "take off"  # TAKE_OFF, >*>wl
    CLIMBED = "reached take-off height"
    MOVE = "move"  # VELOCITY, MOVE_BY, GOTO_GPS, >*>wg, >*>wh
    ARRIVED = "motion finished"
    HOLD = "hold"  # HOLD
    LAND = "land"  # LAND, >*>we
    TOUCHDOWN = "touched down, motors off"
    STICKS = "manual stick input"  # CTRL_INPUT with axis bits while the motors run
    MOTORS_OFF = "motors stopped on the ground"
    LINK_LOST = "ground link lost"
    VEHICLE_LOST = "the vehicle below stopped answering"  # the pilot can no longer fly it
    LAND_TIMEOUT = "no ground link for the land timeout"
    CRASH = "the vehicle crashed"  # tumbled, a hard impact, removed by the simulator
    RESET = "reset"  # RESET: the vehicle back at home, still
    RESPAWNED = "the vehicle came back"  # the pilot re-attached to a restarted simulator


S, E = NavState, FlightEvent

TRANSITIONS: dict[tuple[NavState, FlightEvent], NavState] = {
    (S.LANDED, E.TAKE_OFF): S.TAKING_OFF,
    (S.LANDED, E.MOTORS_OFF): S.LANDED,
    (S.LANDED, E.TOUCHDOWN): S.LANDED,
    (S.LANDED, E.LINK_LOST): S.LANDED,
    (S.TAKING_OFF, E.CLIMBED): S.HOLDING,
    (S.TAKING_OFF, E.HOLD): S.HOLDING,
    (S.TAKING_OFF, E.LAND): S.LANDING,
    (S.TAKING_OFF, E.LINK_LOST): S.FAILSAFE,
    (S.FLYING, E.MOVE): S.FLYING,
    (S.FLYING, E.ARRIVED): S.HOLDING,
    (S.FLYING, E.HOLD): S.HOLDING,
    (S.FLYING, E.LAND): S.LANDING,
    (S.FLYING, E.TOUCHDOWN): S.LANDED,
    (S.FLYING, E.MOTORS_OFF): S.LANDED,
    (S.FLYING, E.LINK_LOST): S.FAILSAFE,
    (S.HOLDING, E.MOVE): S.FLYING,
    (S.HOLDING, E.HOLD): S.HOLDING,
    (S.HOLDING, E.ARRIVED): S.HOLDING,
    (S.HOLDING, E.LAND): S.LANDING,
    (S.HOLDING, E.TOUCHDOWN): S.LANDED,
    (S.HOLDING, E.MOTORS_OFF): S.LANDED,
    (S.HOLDING, E.LINK_LOST): S.FAILSAFE,
    (S.LANDING, E.TOUCHDOWN): S.LANDED,
    (S.LANDING, E.ARRIVED): S.LANDED,
    (S.LANDING, E.MOTORS_OFF): S.LANDED,
    (S.LANDING, E.HOLD): S.HOLDING,
    (S.LANDING, E.LAND): S.LANDING,
    (S.LANDING, E.LINK_LOST): S.LANDING,
    (S.FAILSAFE, E.HOLD): S.HOLDING,
    (S.FAILSAFE, E.LAND): S.LANDING,
    (S.FAILSAFE, E.MOVE): S.FLYING,
    (S.FAILSAFE, E.LAND_TIMEOUT): S.LANDING,
    (S.FAILSAFE, E.TOUCHDOWN): S.LANDED,
    (S.FAILSAFE, E.LINK_LOST): S.FAILSAFE,
    (S.MANUAL, E.MOVE): S.FLYING,
    (S.MANUAL, E.ARRIVED): S.HOLDING,  # stopped at the flight envelope's edge
    (S.MANUAL, E.HOLD): S.HOLDING,
    (S.MANUAL, E.LAND): S.LANDING,
    (S.MANUAL, E.TOUCHDOWN): S.LANDED,
    (S.MANUAL, E.MOTORS_OFF): S.LANDED,
    (S.MANUAL, E.LINK_LOST): S.FAILSAFE,
    # The sticks take over from every state (the rule in the module docstring).
    **{(state, E.STICKS): S.MANUAL for state in (
        S.LANDED, S.TAKING_OFF, S.FLYING, S.HOLDING, S.LANDING, S.FAILSAFE, S.MANUAL)},
    # A vehicle lost in the air is in its own failsafe's hands, a landing included: the pilot
    # can no longer see it touch down (on the ground nothing changes).
    **{(state, E.VEHICLE_LOST): S.FAILSAFE for state in (
        S.TAKING_OFF, S.FLYING, S.HOLDING, S.LANDING, S.FAILSAFE, S.MANUAL)},
    (S.LANDED, E.VEHICLE_LOST): S.LANDED,
    (S.CRASHED, E.VEHICLE_LOST): S.CRASHED,
    # A crash ends whatever the vehicle was doing; only RESET (or a new vehicle) ends a crash.
    **{(state, E.CRASH): S.CRASHED for state in NavState},
    (S.CRASHED, E.RESET): S.LANDED,
    (S.LANDED, E.RESET): S.LANDED,
    (S.CRASHED, E.LINK_LOST): S.CRASHED,
    (S.CRASHED, E.TOUCHDOWN): S.CRASHED,
    (S.CRASHED, E.MOTORS_OFF): S.CRASHED,
    **{(state, E.RESPAWNED): S.LANDED for state in NavState},
}

# Refused with code 5: the vehicle is doing something it finishes by itself; ask again later.
BUSY: frozenset[tuple[NavState, FlightEvent]] = frozenset(
    {
        (S.TAKING_OFF, E.TAKE_OFF),
        (S.TAKING_OFF, E.MOVE),
        (S.LANDING, E.TAKE_OFF),
        (S.LANDING, E.MOVE),
    }
)


class IllegalTransition(LocalProtocolError):
    """An event that the current flight state does not allow; ``code`` is the RESULT code."""

    def __init__(self, state: NavState, event: FlightEvent) -> None:
        busy = (state, event) in BUSY
        self.state = state
        self.event = event
        self.code = ResultCode.BUSY if busy else ResultCode.REFUSED
        why = "busy" if busy else "not allowed"
        super().__init__(f"{event.value}: {why} while {state.name.lower().replace('_', ' ')}")


class FlightStateMachine:
    """The current flight state; ``fire`` is the only way to change it (thread-safe)."""

    def __init__(self, state: NavState = NavState.LANDED) -> None:
        self._state = state
        self._lock = threading.Lock()

    @property
    def state(self) -> NavState:
        return self._state

    def allowed(self, event: FlightEvent) -> bool:
        """Whether ``event`` is legal now."""
        return (self._state, event) in TRANSITIONS

    def check(self, event: FlightEvent) -> None:
        """Raise ``IllegalTransition`` if ``event`` is not legal now (changes nothing)."""
        if (self._state, event) not in TRANSITIONS:
            raise IllegalTransition(self._state, event)

    def fire(self, event: FlightEvent) -> NavState:
        """Apply ``event``; returns the new state or raises ``IllegalTransition``."""
        with self._lock:
            nxt = TRANSITIONS.get((self._state, event))
            if nxt is None:
                raise IllegalTransition(self._state, event)
            self._state = nxt
            return nxt
