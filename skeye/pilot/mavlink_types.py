"""The MAVLink endpoint's small types: what goes out, a refusal, a command, the settings, and
LANDING_TARGET from a pad detection (``skeye.pilot.mavlink_vehicle`` uses them; the companion
airframe sends LANDING_TARGET too).
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mav

from skeye.errors import SkeyeError
from skeye.mavlink.codec import MavCodec, MavMessage
from skeye.pilot.pad import PadObservation
from skeye.wire.packet_defs import ResultCode

FORCE_MAGIC = 21196.0  # COMPONENT_ARM_DISARM param2: force (PX4, ArduPilot)
RESULT_OF_CODE = {
    ResultCode.BAD_VALUE: mav.MAV_RESULT_DENIED,
    ResultCode.REFUSED: mav.MAV_RESULT_TEMPORARILY_REJECTED,
    ResultCode.BUSY: mav.MAV_RESULT_TEMPORARILY_REJECTED,
    ResultCode.BAD_CHECKSUM: mav.MAV_RESULT_DENIED,
    ResultCode.BAD_LENGTH: mav.MAV_RESULT_DENIED,
}


@dataclass(frozen=True)
class Out:
    """A message to send: on link ``link`` (None: every link) to ``peer`` (None: every peer)."""

    msg: MavMessage
    link: int | None = None
    peer: Hashable | None = None


class Refused(SkeyeError):
    """A command refused: ``result`` is the MAV_RESULT, the message the reason."""

    def __init__(self, result: int, reason: str) -> None:
        super().__init__(reason)
        self.result = result


@dataclass(frozen=True)
class Command:
    """COMMAND_LONG and COMMAND_INT in one form (x, y in degrees x 1e7 for COMMAND_INT)."""

    command: int
    params: tuple[float, ...]  # param1..param7 (COMMAND_INT: 5, 6 as given, 7 = z)
    frame: int | None  # COMMAND_INT's frame; None for COMMAND_LONG
    x: int = 0
    y: int = 0

    @classmethod
    def of(cls, msg: MavMessage) -> Command:
        if msg.get_type() == "COMMAND_INT":
            return cls(int(msg.command), (msg.param1, msg.param2, msg.param3, msg.param4,
                                          float(msg.x), float(msg.y), msg.z),
                       int(msg.frame), int(msg.x), int(msg.y))
        return cls(int(msg.command), (msg.param1, msg.param2, msg.param3, msg.param4,
                                      msg.param5, msg.param6, msg.param7), None)

    def key(self) -> tuple[object, ...]:
        """What makes two transmissions the same command: every field, a NaN parameter
        equal to a NaN (MAVSDK sends NaN for each one it leaves unset; NaN != NaN would make
        every retransmission of such a command look new)."""
        params = tuple("nan" if math.isnan(p) else p for p in map(float, self.params))
        return (self.command, params, self.frame, self.x, self.y)

    def p(self, n: int) -> float:
        return float(self.params[n - 1])

    def whole(self, n: int, what: str) -> int:
        """param ``n`` as the integer it carries (an id, a mode, flags), as PX4 casts it;
        refused (MAV_RESULT_DENIED) when it is NaN or infinite, which no integer is."""
        value = self.p(n)
        if not math.isfinite(value):
            raise Refused(mav.MAV_RESULT_DENIED, f"{what} (param{n}) is {value}, not a number")
        return int(value)


@dataclass
class Settings:
    """The endpoint's own settings (parameters beside the boards')."""

    takeoff_alt_m: float = 2.5  # PX4 MIS_TAKEOFF_ALT default
    rtl_alt_m: float = 15.0  # ArduPilot RTL_ALT's default, 15 m (PX4's RTL_RETURN_ALT: 60 m)
    offboard_loss_s: float = 1.0  # PX4 COM_OF_LOSS_T default
    disarm_preflight_s: float = 10.0  # PX4 COM_DISARM_PRFLT default
    pad_vision: bool = False  # the pilot runs pad detection (precision landing possible)


@dataclass
class Step:
    """Where a program is: its item or phase, the motion it started, when it waits until."""

    index: int = 0
    phase: str = "start"
    mark: int = -1
    wait_until_s: float | None = None


def landing_target(codec: MavCodec, obs: PadObservation, yaw_rad: float) -> MavMessage:
    """LANDING_TARGET from one pad detection.

    The detector gives the pad's offset in the level, yaw-aligned body frame (forward, right;
    roll and pitch removed) and the camera's height above it. ``angle_x``/``angle_y`` are the
    target's angles in that frame as an image sees them (x right, y back: ``atan(right / h)``,
    ``atan(-forward / h)``), ``distance`` the slant range; x, y, z are the pad's position
    relative to the vehicle in MAV_FRAME_LOCAL_NED (north, east, down: the frame PX4's
    precision landing takes positions in), turned by the estimate's yaw.
    """
    fwd, right, h = obs.dx_m, obs.dy_m, max(obs.height_m, 1e-3)
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    north, east = c * fwd - s * right, s * fwd + c * right
    distance = math.sqrt(fwd * fwd + right * right + h * h)
    return codec.mav.landing_target_encode(
        round(obs.frame_time_s * 1e6), 0, mav.MAV_FRAME_LOCAL_NED, math.atan2(right, h),
        math.atan2(-fwd, h), distance, 0.0, 0.0, north, east, h, [1.0, 0.0, 0.0, 0.0],
        mav.LANDING_TARGET_TYPE_VISION_FIDUCIAL, 1)


def command_name(command: int) -> str:
    entry = mav.enums["MAV_CMD"].get(command)
    return entry.name.replace("MAV_CMD_", "") if entry is not None else f"command {command}"
