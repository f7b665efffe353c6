"""PX4-compatible flight modes of a skeye vehicle, as tables.

How this works: a MAVLink ground station reads the vehicle's mode from HEARTBEAT
``custom_mode`` in PX4's layout (main mode in byte 2, sub mode in byte 3: ``px4_custom_mode.h``),
so MAVSDK and QGroundControl name it ("Hold", "Mission", "Return"...). What the vehicle does is
the pilot's flight state (``NavState``, the boards' transition table) plus the MAVLink program
the endpoint runs (a mission, a return, offboard setpoints, sticks, a precision landing):
``MODE_TABLE`` maps ``(state, program)`` to the mode reported, and ``REQUESTS`` maps a mode a
ground station asks for (MAV_CMD_DO_SET_MODE) to the action the endpoint takes; a mode not in
it is refused with the reason. Every ``NavState`` must appear in ``_STATE_MODES`` (a test
checks it), so a new flight state cannot go unreported.
"""

from __future__ import annotations

from enum import Enum, IntEnum

from pymavlink.dialects.v20 import common as mav

from skeye.wire.packet_defs import NavState


class Px4Main(IntEnum):
    """PX4_CUSTOM_MAIN_MODE."""

    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7
    RATTITUDE = 8


class Px4Mode(Enum):
    """The PX4 modes a skeye vehicle reports or accepts: (main mode, auto sub mode)."""

    MANUAL = (Px4Main.MANUAL, 0)
    ALTCTL = (Px4Main.ALTCTL, 0)
    POSCTL = (Px4Main.POSCTL, 0)
    READY = (Px4Main.AUTO, 1)
    TAKEOFF = (Px4Main.AUTO, 2)
    HOLD = (Px4Main.AUTO, 3)  # AUTO_LOITER
    MISSION = (Px4Main.AUTO, 4)
    RTL = (Px4Main.AUTO, 5)
    LAND = (Px4Main.AUTO, 6)
    PRECLAND = (Px4Main.AUTO, 9)
    ACRO = (Px4Main.ACRO, 0)
    OFFBOARD = (Px4Main.OFFBOARD, 0)
    STABILIZED = (Px4Main.STABILIZED, 0)

    @property
    def custom_mode(self) -> int:
        """HEARTBEAT.custom_mode: main mode << 16 | sub mode << 24."""
        main, sub = self.value
        return (int(main) << 16) | (sub << 24)

    @classmethod
    def from_custom(cls, main: int, sub: int) -> Px4Mode | None:
        """The mode of DO_SET_MODE's param2/param3 (sub mode ignored outside AUTO)."""
        for mode in cls:
            m, s = mode.value
            if int(m) == main and (s == sub or main != Px4Main.AUTO):
                return mode
        return None


class Program(Enum):
    """What the MAVLink endpoint is running on top of the flight state."""

    NONE = "none"  # commands one at a time (take-off, reposition, land): PX4's Hold
    MISSION = "mission"
    RTL = "return to launch"
    OFFBOARD = "offboard"
    MANUAL = "manual sticks"  # MANUAL_CONTROL flies (position mode)
    PRECLAND = "precision landing"


P = Program

# Per flight state (by name, so the table names states other branches add): the mode for
# each program, with "*" for every program not listed.
_STATE_MODES: dict[str, dict[Program | str, Px4Mode]] = {
    "LANDED": {"*": Px4Mode.HOLD, P.MISSION: Px4Mode.MISSION, P.OFFBOARD: Px4Mode.OFFBOARD,
               P.MANUAL: Px4Mode.POSCTL},
    "TAKING_OFF": {"*": Px4Mode.TAKEOFF, P.MISSION: Px4Mode.MISSION, P.RTL: Px4Mode.RTL},
    "FLYING": {"*": Px4Mode.HOLD, P.MISSION: Px4Mode.MISSION, P.RTL: Px4Mode.RTL,
               P.OFFBOARD: Px4Mode.OFFBOARD, P.MANUAL: Px4Mode.POSCTL,
               P.PRECLAND: Px4Mode.PRECLAND},
    "HOLDING": {"*": Px4Mode.HOLD, P.MISSION: Px4Mode.MISSION, P.RTL: Px4Mode.RTL,
                P.OFFBOARD: Px4Mode.OFFBOARD, P.MANUAL: Px4Mode.POSCTL,
                P.PRECLAND: Px4Mode.PRECLAND},
    "LANDING": {"*": Px4Mode.LAND, P.MISSION: Px4Mode.MISSION, P.RTL: Px4Mode.RTL,
                P.PRECLAND: Px4Mode.PRECLAND},
    "FAILSAFE": {"*": Px4Mode.HOLD},  # the link-loss failsafe hovers (PX4: hold)
    "MANUAL": {"*": Px4Mode.POSCTL},  # sticks took over (AscTec link)
    "CRASHED": {"*": Px4Mode.HOLD},
}

MODE_TABLE: dict[tuple[NavState, Program], Px4Mode] = {
    (state, program): _STATE_MODES[state.name].get(program, _STATE_MODES[state.name]["*"])
    for state in NavState
    for program in Program
}

_STATUS = {"LANDED": mav.MAV_STATE_STANDBY, "FAILSAFE": mav.MAV_STATE_CRITICAL,
           "CRASHED": mav.MAV_STATE_EMERGENCY}
_LANDED_STATE = {"LANDED": mav.MAV_LANDED_STATE_ON_GROUND,
                 "CRASHED": mav.MAV_LANDED_STATE_ON_GROUND,
                 "TAKING_OFF": mav.MAV_LANDED_STATE_TAKEOFF,
                 "LANDING": mav.MAV_LANDED_STATE_LANDING}


def system_status(state: NavState) -> int:
    """HEARTBEAT.system_status (MAV_STATE) of a flight state."""
    return int(_STATUS.get(state.name, mav.MAV_STATE_ACTIVE))


def landed_state(state: NavState) -> int:
    """EXTENDED_SYS_STATE.landed_state (MAV_LANDED_STATE) of a flight state."""
    return int(_LANDED_STATE.get(state.name, mav.MAV_LANDED_STATE_IN_AIR))


class Request(Enum):
    """What a requested mode makes the endpoint do."""

    HOLD = "hold"
    MISSION = "start the mission"
    RTL = "return to launch"
    LAND = "land"
    TAKEOFF = "take off"
    OFFBOARD = "follow offboard setpoints"
    MANUAL = "fly on MANUAL_CONTROL sticks"
    PRECLAND = "land on the pad"


REQUESTS: dict[Px4Mode, Request] = {
    Px4Mode.HOLD: Request.HOLD,
    Px4Mode.MISSION: Request.MISSION,
    Px4Mode.RTL: Request.RTL,
    Px4Mode.LAND: Request.LAND,
    Px4Mode.TAKEOFF: Request.TAKEOFF,
    Px4Mode.OFFBOARD: Request.OFFBOARD,
    Px4Mode.POSCTL: Request.MANUAL,
    Px4Mode.PRECLAND: Request.PRECLAND,
}
"""Modes a ground station may ask for; the others (MANUAL, ALTCTL, ACRO, STABILIZED, READY)
need a pilot on real sticks flying attitudes, which a skeye vehicle takes only over its AscTec
link (CTRL_INPUT), and are refused with that reason."""
