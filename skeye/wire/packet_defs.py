"""Vehicle packet messages (docs/protocols/packets.md) and the one table that lays them out.

How this works: every structure and command is a frozen dataclass whose integer fields carry the
AscTec (or skeye) names and raw wire units. ``LAYOUTS`` maps each message class to its
``Layout``: descriptor, how it is framed (``FrameKind``), and its wire fields in order, each with
a struct code, an allowed range and, for a physical quantity, its ``Scale`` (wire unit and SI
unit, ``skeye.wire.scales``). That table is the single source for the codec in
``skeye.wire.packets``, for the SI views in ``skeye.wire.packet_units`` and for the range
checks here: ``__post_init__`` walks the message's layout and raises ``LocalProtocolError``
naming the field for anything out of range, so an invalid message cannot exist and the encoder
never meets a value it cannot pack. Integer-like values (numpy ints too) are normalised to
``int``; enum-valued fields are normalised to their ``IntEnum``.
"""

from __future__ import annotations

import operator
import struct
from dataclasses import dataclass, field, fields
from enum import Enum, IntEnum, IntFlag
from typing import Any, ClassVar

from skeye.errors import LocalProtocolError
from skeye.wire.scales import (
    ACC,
    ANGVEL,
    CLOCK_MS,
    CONTROLLER_THRUST,
    CS,
    DEG_E7,
    DM,
    HEADING_MDEG,
    MDEG,
    MM,
    MM_S,
    MRAD_S,
    MS,
    MV,
    QUALITY,
    STICK_ANGLE,
    STICK_YAW_RATE,
    THRUST,
    Scale,
)

MAX_PAYLOAD = 1024  # longest payload a receiver accepts; a longer length field is a bad frame


class PD(IntEnum):
    """Packet descriptors: structures, AscTec command acks, skeye commands and replies."""

    IMU_RAWDATA = 0x01
    LL_STATUS = 0x02
    IMU_CALCDATA = 0x03
    CONTROLLER_OUTPUT = 0x11
    RC_DATA = 0x15
    CTRL_INPUT = 0x17  # ack of >*>di
    CURRENT_WAY = 0x21
    GPS_DATA = 0x23
    WAYPOINT = 0x24  # ack of >*>ws
    WAYPOINT_GOTO = 0x25  # ack of >*>wg
    LAUNCH = 0x26  # ack of >*>wl
    END_FLIGHT = 0x27  # ack of >*>we
    COME_HOME = 0x28  # ack of >*>wh
    GPS_DATA_ADVANCED = 0x29
    VELOCITY = 0x80
    MOVE_BY = 0x81
    GOTO_GPS = 0x82
    TAKE_OFF = 0x83
    LAND = 0x84
    HOLD = 0x85
    PAD_MODE = 0x86
    STREAM = 0x87
    RESET = 0x88
    CLOCK = 0x8E
    NAV_STATUS = 0x90
    PAD = 0x91
    RESULT = 0x92
    HEALTH = 0x93
    VEHICLE = 0x94
    TRUTH = 0x95


ACK_PDS = frozenset(
    {PD.CTRL_INPUT, PD.WAYPOINT, PD.WAYPOINT_GOTO, PD.LAUNCH, PD.END_FLIGHT, PD.COME_HOME}
)


class ResultCode(IntEnum):
    """RESULT codes (and the code a ``CommandError`` asks the vehicle to answer with)."""

    OK = 0
    BAD_CHECKSUM = 1
    BAD_LENGTH = 2
    BAD_VALUE = 3
    REFUSED = 4
    BUSY = 5


class PollMask(IntFlag):
    """Poll mask bits (``>*>p`` and STREAM): one bit per structure."""

    LL_STATUS = 0x0001
    IMU_RAWDATA = 0x0002
    IMU_CALCDATA = 0x0004
    RC_DATA = 0x0008
    CONTROLLER_OUTPUT = 0x0010
    GPS_DATA = 0x0080
    CURRENT_WAY = 0x0100
    GPS_DATA_ADVANCED = 0x0200


POLL_PDS: dict[PollMask, PD] = {
    PollMask.LL_STATUS: PD.LL_STATUS,
    PollMask.IMU_RAWDATA: PD.IMU_RAWDATA,
    PollMask.IMU_CALCDATA: PD.IMU_CALCDATA,
    PollMask.RC_DATA: PD.RC_DATA,
    PollMask.CONTROLLER_OUTPUT: PD.CONTROLLER_OUTPUT,
    PollMask.GPS_DATA: PD.GPS_DATA,
    PollMask.CURRENT_WAY: PD.CURRENT_WAY,
    PollMask.GPS_DATA_ADVANCED: PD.GPS_DATA_ADVANCED,
}
POLL_MASK_ALL = sum(POLL_PDS)


class SkeyeMask(IntFlag):
    """STREAM's second mask: skeye replies pushed at the stream rate."""

    NAV_STATUS = 0x0001
    PAD = 0x0002
    TRUTH = 0x0004  # a simulated vehicle's ground truth (nothing from a real one)


class CtrlBits(IntFlag):
    """CTRL_INPUT ``ctrl``: which stick inputs the vehicle takes from the command."""

    PITCH = 0x01
    ROLL = 0x02
    YAW = 0x04
    THRUST = 0x08
    HEIGHT_CONTROL = 0x10
    GPS_POSITION_CONTROL = 0x20


class WaypointProps(IntFlag):
    """WAYPOINT ``properties`` bits."""

    ABSOLUTE = 0x01
    HEIGHT_ENABLED = 0x02
    YAW_ENABLED = 0x04
    AUTOMATIC_GOTO = 0x10


class NavigationStatus(IntFlag):
    """CURRENT_WAY ``navigation_status`` bits."""

    REACHED = 0x01
    REACHED_AND_WAITED = 0x02
    WITHIN_20M = 0x04
    ABORTED = 0x08


class NavState(IntEnum):
    """NAV_STATUS ``state``."""

    LANDED = 0
    TAKING_OFF = 1
    FLYING = 2
    HOLDING = 3
    LANDING = 4
    FAILSAFE = 5
    MANUAL = 6  # CTRL_INPUT sticks fly it: they took over from whatever flew it before
    CRASHED = 7  # the vehicle crashed (HEALTH says why); only RESET brings it back


class HealthStatus(IntEnum):
    """HEALTH ``status``: whether the vehicle below the pilot is whole and answering."""

    OK = 0
    CRASHED = 1  # the vehicle crashed (tumbled, a hard impact, removed by the simulator)
    LOST = 2  # the vehicle below stopped answering (simulator gone or frozen)


class PadAction(IntEnum):
    """PAD_MODE ``mode`` (and NAV_STATUS ``pad_mode``)."""

    OFF = 0
    HOLD = 1
    LAND = 2


class MoveFrame(IntEnum):
    """MOVE_BY ``frame``."""

    BODY_FRD = 0
    WORLD_NED = 1


class FrameKind(Enum):
    """How a message is put on the wire."""

    VEHICLE = "vehicle"  # >*> len PD payload crc <#<
    ACK = "ack"  # >a PD a<
    ASCTEC = "asctec"  # fixed prefix (>*>p, >*>di, >*>ws, ...) + fixed payload
    SKEYE = "skeye"  # >*>s len PD payload crc <#<


_CODE_RANGES = {
    "b": (-(2**7), 2**7 - 1),
    "B": (0, 2**8 - 1),
    "h": (-(2**15), 2**15 - 1),
    "H": (0, 2**16 - 1),
    "i": (-(2**31), 2**31 - 1),
    "I": (0, 2**32 - 1),
}


@dataclass(frozen=True)
class Field:
    """One wire field: struct code, element count, inclusive range, allowed bits, enum, scale.

    ``scale`` is the field's wire unit (None: a count, code or raw value without SI view);
    ``saturate``: built from SI, the value saturates at ``limits`` as a real sensor's reading
    does (int16 accelerations and velocities), instead of being refused.
    """

    name: str
    code: str
    lo: int | None = None
    hi: int | None = None
    count: int = 1
    bits: int | None = None
    enum: type[IntEnum] | None = None
    computed: bool = False  # the command checksum: not a message attribute, made on encode
    scale: Scale | None = None
    saturate: bool = False

    @property
    def limits(self) -> tuple[int, int]:
        type_lo, type_hi = _CODE_RANGES[self.code]
        return (type_lo if self.lo is None else self.lo, type_hi if self.hi is None else self.hi)


@dataclass(frozen=True)
class Layout:
    """How one message class looks on the wire."""

    pd: PD | None  # None for poll and ack, whose wire form carries no fixed descriptor
    kind: FrameKind
    fields: tuple[Field, ...]
    prefix: bytes = b""  # AscTec command prefix
    checksum: tuple[str, ...] = ()  # fields summed into the computed 'chksum'
    tail: str | None = None  # attribute holding the variable-length UTF-8 tail (RESULT)
    packer: struct.Struct = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        fmt = "<" + "".join(f"{f.count if f.count > 1 else ''}{f.code}" for f in self.fields)
        object.__setattr__(self, "packer", struct.Struct(fmt))

    @property
    def size(self) -> int:
        """Fixed payload size in bytes (the minimum size when there is a tail)."""
        return self.packer.size


def _int(msg: object, name: str, value: Any) -> int:
    try:
        return operator.index(value)
    except TypeError:
        raise LocalProtocolError(
            f"{type(msg).__name__}.{name} must be an integer, got {value!r}"
        ) from None


def _check_value(msg: object, f: Field, name: str, value: Any) -> int:
    v = _int(msg, name, value)
    lo, hi = f.limits
    if not lo <= v <= hi:
        raise LocalProtocolError(f"{type(msg).__name__}.{name}={v} outside {lo}..{hi}")
    if f.bits is not None and v & ~f.bits:
        raise LocalProtocolError(
            f"{type(msg).__name__}.{name}=0x{v:x} sets bits outside 0x{f.bits:x}"
        )
    return v


@dataclass(frozen=True)
class Message:
    """Base of every packet: checks and normalises fields against the class's layout."""

    def __post_init__(self) -> None:
        layout = LAYOUTS[type(self)]
        for f in layout.fields:
            if f.computed:
                continue
            value = getattr(self, f.name)
            if f.count > 1:
                try:
                    items = tuple(value)
                except TypeError:
                    raise LocalProtocolError(
                        f"{type(self).__name__}.{f.name} must be a sequence of {f.count} ints"
                    ) from None
                if len(items) != f.count:
                    raise LocalProtocolError(
                        f"{type(self).__name__}.{f.name} needs {f.count} values, got {len(items)}"
                    )
                norm: Any = tuple(
                    _check_value(self, f, f"{f.name}[{k}]", v) for k, v in enumerate(items)
                )
            else:
                norm = _check_value(self, f, f.name, value)
                if f.enum is not None:
                    try:
                        norm = f.enum(norm)
                    except ValueError:
                        raise LocalProtocolError(
                            f"{type(self).__name__}.{f.name}={norm} is not a {f.enum.__name__}"
                        ) from None
            object.__setattr__(self, f.name, norm)


# --- AscTec structures (vehicle -> ground) ------------------------------------------------


@dataclass(frozen=True)
class LlStatus(Message):
    """LL_STATUS: low-level board status."""

    battery_voltage_1: int  # mV
    battery_voltage_2: int
    status: int
    cpu_load: int  # control cycles/s
    compass_enabled: int
    chksum_error: int
    flying: int
    motors_on: int
    flightMode: int  # AscTec's name
    up_time: int  # s


@dataclass(frozen=True)
class ImuRawData(Message):
    """IMU_RAWDATA: raw sensor counts."""

    pressure: int
    gyro_x: int
    gyro_y: int
    gyro_z: int
    mag_x: int
    mag_y: int
    mag_z: int
    acc_x: int
    acc_y: int
    acc_z: int
    temp_gyro: int
    temp_ADC: int  # AscTec's name


@dataclass(frozen=True)
class ImuCalcData(Message):
    """IMU_CALCDATA: fused attitude, rates, accelerations, velocity, height (see packet_units)."""

    angle_nick: int  # 1/1000 deg; nick is pitch
    angle_roll: int
    angle_yaw: int  # 0..360000
    angvel_nick: int  # 64.8 counts = 1 deg/s (0.0154 deg/s per count)
    angvel_roll: int
    angvel_yaw: int
    acc_x_calib: int  # 10000 = 1 g, body FRD
    acc_y_calib: int
    acc_z_calib: int
    acc_x: int  # 10000 = 1 g, earth frame
    acc_y: int
    acc_z: int
    acc_angle_nick: int  # 1/1000 deg
    acc_angle_roll: int
    acc_absolute_value: int  # 10000 = 1 g
    Hx: int  # magnetic field, direction only
    Hy: int
    Hz: int
    mag_heading: int  # 1/1000 deg
    speed_x: int  # mm/s
    speed_y: int
    speed_z: int
    height: int  # mm, fused
    dheight: int  # mm/s
    dheight_reference: int  # mm/s, pressure only
    height_reference: int  # mm, pressure only


@dataclass(frozen=True)
class RcData(Message):
    """RC_DATA: remote-control channels."""

    channels_in: tuple[int, ...]  # 8 values
    channels_out: tuple[int, ...]  # 8 values, 0..4095
    lock: int


@dataclass(frozen=True)
class ControllerOutput(Message):
    """CONTROLLER_OUTPUT: what the attitude controller commands."""

    nick: int
    roll: int
    yaw: int
    thrust: int  # 0..200


@dataclass(frozen=True)
class GpsData(Message):
    """GPS_DATA: receiver solution."""

    latitude: int  # deg x 1e7
    longitude: int
    height: int  # mm
    speed_x: int  # mm/s east
    speed_y: int  # mm/s north
    heading: int  # 1/1000 deg
    horizontal_accuracy: int  # mm
    vertical_accuracy: int  # mm
    speed_accuracy: int  # mm/s
    numSV: int  # AscTec's name
    status: int  # 0x03 = valid fix


GPS_FIX_VALID = 0x03


@dataclass(frozen=True)
class GpsDataAdvanced(Message):
    """GPS_DATA_ADVANCED: GPS_DATA plus the fused best estimates."""

    latitude: int
    longitude: int
    height: int
    speed_x: int
    speed_y: int
    heading: int
    horizontal_accuracy: int
    vertical_accuracy: int
    speed_accuracy: int
    numSV: int  # AscTec's name
    status: int
    latitude_best_estimate: int  # deg x 1e7
    longitude_best_estimate: int
    speed_x_best_estimate: int  # mm/s
    speed_y_best_estimate: int


@dataclass(frozen=True)
class CurrentWay(Message):
    """CURRENT_WAY: waypoint navigation progress."""

    dummy1: int
    properties: int
    nr_of_wp: int
    current_wp: int
    current_wp_memlocation: int
    status: int
    dummy2: int
    navigation_status: int  # NavigationStatus bits
    distance_to_wp: int  # dm


# --- AscTec commands (ground -> vehicle) ----------------------------------------------------


@dataclass(frozen=True)
class Poll(Message):
    """``>*>p``: send each requested structure once. Unknown bits are kept and ignored."""

    mask: int

    def requested(self) -> list[PD]:
        """The structures to send, in mask-bit order."""
        return [pd for bit, pd in POLL_PDS.items() if self.mask & bit]


@dataclass(frozen=True)
class CtrlInput(Message):
    """``>*>di``: direct stick input; the checksum is computed on encode."""

    pitch: int  # -2047..2047, 0.025 deg per count
    roll: int
    yaw: int  # 0.120 deg/s per count
    thrust: int  # 0..4095
    ctrl: int  # CtrlBits


@dataclass(frozen=True)
class Waypoint(Message):
    """``>*>ws``: the single waypoint; the checksum is computed on encode."""

    properties: int  # WaypointProps
    max_speed: int  # %
    time: int  # 1/100 s to stay
    pos_acc: int  # mm
    X: int  # mm relative, or longitude deg x 1e7 when absolute
    Y: int  # mm, or latitude deg x 1e7
    yaw: int  # 1/1000 deg
    height: int  # mm
    wp_number: int = 1
    dummy_1: int = 0
    dummy_2: int = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.properties & WaypointProps.ABSOLUTE:
            if not -1_800_000_000 <= self.X <= 1_800_000_000:
                raise LocalProtocolError(f"Waypoint.X={self.X} is not a longitude x 1e7")
            if not -900_000_000 <= self.Y <= 900_000_000:
                raise LocalProtocolError(f"Waypoint.Y={self.Y} is not a latitude x 1e7")


@dataclass(frozen=True)
class WaypointGoto(Message):
    """``>*>wg``: fly to the uploaded waypoint."""


@dataclass(frozen=True)
class Launch(Message):
    """``>*>wl``: take off; set home when hovering."""


@dataclass(frozen=True)
class EndFlight(Message):
    """``>*>we``: land where you are."""


@dataclass(frozen=True)
class ComeHome(Message):
    """``>*>wh``: come home."""


# --- skeye commands (ground -> vehicle) -----------------------------------------------------


@dataclass(frozen=True)
class Velocity(Message):
    """VELOCITY: fly at these velocities (body FRD) for ``duration`` ms (0 = until replaced)."""

    vx: int  # mm/s forward
    vy: int  # mm/s right
    vz: int  # mm/s down
    yaw_rate: int  # mrad/s
    duration: int  # ms


@dataclass(frozen=True)
class MoveBy(Message):
    """MOVE_BY: move by a distance relative to the current position."""

    dx: int  # mm
    dy: int
    dz: int
    dyaw: int  # 1/1000 deg
    frame: MoveFrame
    speed: int  # mm/s


@dataclass(frozen=True)
class GotoGps(Message):
    """GOTO_GPS: fly to GPS coordinates."""

    latitude: int  # deg x 1e7
    longitude: int
    height: int  # mm above home
    speed: int  # mm/s


@dataclass(frozen=True)
class TakeOff(Message):
    """TAKE_OFF: start motors and climb to ``height`` mm (must be positive)."""

    height: int


@dataclass(frozen=True)
class Land(Message):
    """LAND: descend and stop motors."""


@dataclass(frozen=True)
class Hold(Message):
    """HOLD: stop and hover here."""


@dataclass(frozen=True)
class PadMode(Message):
    """PAD_MODE: landing-pad detection and what to do with it."""

    mode: PadAction
    deadband: int  # mm
    max_speed: int  # mm/s


@dataclass(frozen=True)
class Reset(Message):
    """RESET: bring the vehicle back at home, still, motors off (a simulated vehicle respawns
    at its start pose); the way out of CRASHED."""


@dataclass(frozen=True)
class Stream(Message):
    """STREAM: push the masked telemetry every ``period`` ms (0 = stop)."""

    poll_mask: int  # PollMask bits
    skeye_mask: int  # SkeyeMask bits
    period: int  # ms


@dataclass(frozen=True)
class Clock(Message):
    """CLOCK: with ``skeye pilot --ground-clock``, let lockstep sim time run up to ``until`` ms.

    The pilot advances the simulator only up to the latest granted time and then waits (telemetry
    and commands still served), so a scripted ground station acts at exact sim times.
    """

    until: int  # ms of sim time


# --- skeye replies (vehicle -> ground) ------------------------------------------------------


@dataclass(frozen=True)
class NavStatus(Message):
    """NAV_STATUS: navigation state, position and velocity in world NED."""

    state: NavState
    pad_mode: PadAction
    x: int  # mm north
    y: int  # mm east
    z: int  # mm down
    yaw: int  # 1/1000 deg
    vx: int  # mm/s
    vy: int
    vz: int
    battery: int  # mV
    time: int  # ms
    sigma_h: int = 0  # mm, the position estimate's horizontal 1-sigma (0: not known)
    sigma_v: int = 0  # mm, its vertical 1-sigma (0: not known)


@dataclass(frozen=True)
class PadReport(Message):
    """PAD: latest landing-pad estimate."""

    found: int  # 0 or 1
    rings: int  # bit per identified ring
    dx: int  # mm, body FRD
    dy: int
    height: int  # mm
    quality: int  # 0..1000
    frame_time: int  # ms
    vision: int = 0  # 1: vision too slow to hold (the pad modes hold still), else 0


@dataclass(frozen=True)
class Result(Message):
    """RESULT: answer to every skeye command and to a bad AscTec command."""

    command_pd: int
    code: ResultCode
    reason: str = ""

    MAX_REASON_BYTES: ClassVar[int] = MAX_PAYLOAD - 2

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_reason(self.reason, self.MAX_REASON_BYTES, "Result.reason")


def _check_reason(reason: object, max_bytes: int, what: str) -> None:
    """A text tail: a str of at most ``max_bytes`` of UTF-8."""
    if not isinstance(reason, str):
        raise LocalProtocolError(f"{what} must be a str, got {reason!r}")
    try:
        n = len(reason.encode("utf-8"))
    except UnicodeEncodeError as exc:  # lone surrogates
        raise LocalProtocolError(f"{what} is not encodable as UTF-8: {exc}") from None
    if n > max_bytes:
        raise LocalProtocolError(f"{what} is {n} bytes of UTF-8, more than {max_bytes}")


@dataclass(frozen=True)
class Health(Message):
    """HEALTH: the vehicle's health now and why (pushed when it changes, streamed with
    NAV_STATUS while it is not OK)."""

    status: HealthStatus
    reason: str = ""

    MAX_REASON_BYTES: ClassVar[int] = MAX_PAYLOAD - 1

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_reason(self.reason, self.MAX_REASON_BYTES, "Health.reason")


@dataclass(frozen=True)
class VehicleInfo(Message):
    """VEHICLE: what the pilot flies (streamed with NAV_STATUS once a second): whether it is
    simulated, and a line naming it and where it is reached (``skeye ground`` shows it)."""

    simulated: int  # 1: a robot of the simulator (TRUTH can be asked for), 0: a real vehicle
    description: str = ""

    MAX_DESCRIPTION_BYTES: ClassVar[int] = 200

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_reason(self.description, self.MAX_DESCRIPTION_BYTES, "VehicleInfo.description")


@dataclass(frozen=True)
class Truth(Message):
    """TRUTH: a simulated vehicle's true position and heading (the simulator's ground truth)
    in NAV_STATUS's frame, for display beside the estimate; a real vehicle sends none."""

    x: int  # mm north of the world origin
    y: int  # mm east
    z: int  # mm down from the ground at home (NAV_STATUS's z)
    yaw: int  # 1/1000 deg
    time: int  # ms


@dataclass(frozen=True)
class Ack(Message):
    """``>a PD a<``: short acknowledgement of an AscTec command."""

    pd: PD

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.pd not in ACK_PDS:
            raise LocalProtocolError(f"Ack.pd=0x{self.pd:02x} is not an AscTec command's PD")


# --- the table ------------------------------------------------------------------------------

_I, _H, _h, _B = "i", "H", "h", "B"
_LAT = (-900_000_000, 900_000_000)
_LON = (-1_800_000_000, 1_800_000_000)
_GPS_FIELDS = (
    Field("latitude", _I, *_LAT, scale=DEG_E7),
    Field("longitude", _I, *_LON, scale=DEG_E7),
    Field("height", _I, scale=MM),
    Field("speed_x", _I, scale=MM_S),
    Field("speed_y", _I, scale=MM_S),
    Field("heading", _I, scale=HEADING_MDEG),
    Field("horizontal_accuracy", "I", scale=MM),
    Field("vertical_accuracy", "I", scale=MM),
    Field("speed_accuracy", "I", scale=MM_S),
    Field("numSV", "I"),
    Field("status", _I),
)


def _plain(
    code: str, *names: str, scale: Scale | None = None, saturate: bool = False
) -> tuple[Field, ...]:
    return tuple(Field(n, code, scale=scale, saturate=saturate) for n in names)


def _v(pd: PD, *f: Field) -> Layout:
    return Layout(pd, FrameKind.VEHICLE, f)


def _s(pd: PD, *f: Field) -> Layout:
    return Layout(pd, FrameKind.SKEYE, f)


def _cmd(pd: PD, prefix: bytes) -> Layout:
    return Layout(pd, FrameKind.ASCTEC, (), prefix=prefix)


LAYOUTS: dict[type[Message], Layout] = {
    LlStatus: _v(
        PD.LL_STATUS,
        *_plain(_h, "battery_voltage_1", "battery_voltage_2", scale=MV, saturate=True),
        *_plain(_h, "status", "cpu_load"),
        *_plain(_B, "compass_enabled", "chksum_error", "flying", "motors_on"),
        *_plain(_h, "flightMode", "up_time"),
    ),
    ImuRawData: _v(
        PD.IMU_RAWDATA,
        Field("pressure", _I),
        *_plain(_h, "gyro_x", "gyro_y", "gyro_z", scale=ANGVEL, saturate=True),
        *_plain(_h, "mag_x", "mag_y", "mag_z"),
        *_plain(_h, "acc_x", "acc_y", "acc_z", scale=ACC, saturate=True),
        Field("temp_gyro", _H),
        Field("temp_ADC", "I"),
    ),
    ImuCalcData: _v(
        PD.IMU_CALCDATA,
        *_plain(_I, "angle_nick", "angle_roll", scale=MDEG),
        Field("angle_yaw", _I, 0, 360_000, scale=HEADING_MDEG),
        *_plain(_I, "angvel_nick", "angvel_roll", "angvel_yaw", scale=ANGVEL),
        *_plain(_h, "acc_x_calib", "acc_y_calib", "acc_z_calib", scale=ACC, saturate=True),
        *_plain(_h, "acc_x", "acc_y", "acc_z", scale=ACC, saturate=True),
        *_plain(_I, "acc_angle_nick", "acc_angle_roll", scale=MDEG),
        Field("acc_absolute_value", _I, scale=ACC),
        *_plain(_I, "Hx", "Hy", "Hz"),
        Field("mag_heading", _I, scale=HEADING_MDEG),
        *_plain(_I, "speed_x", "speed_y", "speed_z", scale=MM_S),
        Field("height", _I, scale=MM),
        *_plain(_I, "dheight", "dheight_reference", scale=MM_S),
        Field("height_reference", _I, scale=MM),
    ),
    RcData: _v(
        PD.RC_DATA,
        Field("channels_in", _H, count=8),
        Field("channels_out", _H, 0, 4095, count=8),
        Field("lock", _B),
    ),
    ControllerOutput: _v(
        PD.CONTROLLER_OUTPUT,
        *_plain(_I, "nick", "roll", "yaw"),
        Field("thrust", _I, 0, 200, scale=CONTROLLER_THRUST),
    ),
    GpsData: _v(PD.GPS_DATA, *_GPS_FIELDS),
    GpsDataAdvanced: _v(
        PD.GPS_DATA_ADVANCED,
        *_GPS_FIELDS,
        Field("latitude_best_estimate", _I, *_LAT, scale=DEG_E7),
        Field("longitude_best_estimate", _I, *_LON, scale=DEG_E7),
        *_plain(_I, "speed_x_best_estimate", "speed_y_best_estimate", scale=MM_S),
    ),
    CurrentWay: _v(
        PD.CURRENT_WAY,
        *_plain(_B, "dummy1", "properties"),
        Field("nr_of_wp", _H),
        *_plain(_B, "current_wp", "current_wp_memlocation", "status", "dummy2"),
        Field("navigation_status", _H),
        Field("distance_to_wp", _H, scale=DM, saturate=True),  # 6553.5 m: "that far or more"
    ),
    Poll: Layout(None, FrameKind.ASCTEC, (Field("mask", _H),), prefix=b">*>p"),
    CtrlInput: Layout(
        PD.CTRL_INPUT,
        FrameKind.ASCTEC,
        (
            Field("pitch", _h, -2047, 2047, scale=STICK_ANGLE),
            Field("roll", _h, -2047, 2047, scale=STICK_ANGLE),
            Field("yaw", _h, -2047, 2047, scale=STICK_YAW_RATE),
            Field("thrust", _h, 0, 4095, scale=THRUST),
            Field("ctrl", _h, 0, 0x3F, bits=0x3F),
            Field("chksum", _H, computed=True),
        ),
        prefix=b">*>di",
        checksum=("pitch", "roll", "yaw", "thrust", "ctrl"),
    ),
    Waypoint: Layout(
        PD.WAYPOINT,
        FrameKind.ASCTEC,
        (
            Field("wp_number", _B, 1, 1),
            Field("dummy_1", _B),
            Field("dummy_2", _H),
            Field("properties", _B, bits=int(sum(WaypointProps))),
            Field("max_speed", _B, 0, 100),
            Field("time", _H, scale=CS),
            Field("pos_acc", _H, scale=MM),
            Field("chksum", _H, computed=True),
            *_plain(_I, "X", "Y", scale=MM),  # degrees x 1e7 when ABSOLUTE (packet_units)
            Field("yaw", _I, scale=HEADING_MDEG),
            Field("height", _I, scale=MM),
        ),
        prefix=b">*>ws",
        checksum=(
            "yaw",
            "height",
            "time",
            "X",
            "Y",
            "max_speed",
            "pos_acc",
            "properties",
            "wp_number",
        ),
    ),
    WaypointGoto: _cmd(PD.WAYPOINT_GOTO, b">*>wg"),
    Launch: _cmd(PD.LAUNCH, b">*>wl"),
    EndFlight: _cmd(PD.END_FLIGHT, b">*>we"),
    ComeHome: _cmd(PD.COME_HOME, b">*>wh"),
    Velocity: _s(
        PD.VELOCITY,
        *_plain(_h, "vx", "vy", "vz", scale=MM_S),
        Field("yaw_rate", _h, scale=MRAD_S),
        Field("duration", _H, scale=MS),
    ),
    MoveBy: _s(
        PD.MOVE_BY,
        *_plain(_I, "dx", "dy", "dz", scale=MM),
        Field("dyaw", _I, scale=MDEG),
        Field("frame", _B, 0, max(MoveFrame), enum=MoveFrame),
        Field("speed", _H, scale=MM_S),
    ),
    GotoGps: _s(
        PD.GOTO_GPS,
        Field("latitude", _I, *_LAT, scale=DEG_E7),
        Field("longitude", _I, *_LON, scale=DEG_E7),
        Field("height", _I, scale=MM),
        Field("speed", _H, scale=MM_S),
    ),
    TakeOff: _s(PD.TAKE_OFF, Field("height", _I, 1, None, scale=MM)),
    Land: _s(PD.LAND),
    Hold: _s(PD.HOLD),
    PadMode: _s(
        PD.PAD_MODE,
        Field("mode", _B, 0, max(PadAction), enum=PadAction),
        Field("deadband", _H, scale=MM),
        Field("max_speed", _H, scale=MM_S),
    ),
    Stream: _s(
        PD.STREAM,
        Field("poll_mask", _H, bits=POLL_MASK_ALL),
        Field("skeye_mask", _H, bits=int(sum(SkeyeMask))),
        Field("period", _H, scale=MS),
    ),
    Clock: _s(PD.CLOCK, Field("until", "I", scale=MS)),
    Reset: _s(PD.RESET),
    NavStatus: _v(
        PD.NAV_STATUS,
        Field("state", _B, 0, max(NavState), enum=NavState),
        Field("pad_mode", _B, 0, max(PadAction), enum=PadAction),
        *_plain(_I, "x", "y", "z", scale=MM),
        Field("yaw", _I, scale=HEADING_MDEG),
        *_plain(_h, "vx", "vy", "vz", scale=MM_S, saturate=True),
        Field("battery", _H, scale=MV),
        Field("time", "I", scale=CLOCK_MS),
        *_plain(_H, "sigma_h", "sigma_v", scale=MM, saturate=True),
    ),
    PadReport: _v(
        PD.PAD,
        Field("found", _B, 0, 1),
        Field("rings", _B),
        *_plain(_I, "dx", "dy", "height", scale=MM),
        Field("quality", _H, 0, 1000, scale=QUALITY),
        Field("frame_time", "I", scale=CLOCK_MS),
        Field("vision", _B, 0, 1),
    ),
    Result: Layout(
        PD.RESULT,
        FrameKind.VEHICLE,
        (Field("command_pd", _B), Field("code", _B, 0, max(ResultCode), enum=ResultCode)),
        tail="reason",
    ),
    Health: Layout(
        PD.HEALTH,
        FrameKind.VEHICLE,
        (Field("status", _B, 0, max(HealthStatus), enum=HealthStatus),),
        tail="reason",
    ),
    VehicleInfo: Layout(
        PD.VEHICLE,
        FrameKind.VEHICLE,
        (Field("simulated", _B, 0, 1),),
        tail="description",
    ),
    Truth: _v(
        PD.TRUTH,
        *_plain(_I, "x", "y", "z", scale=MM),
        Field("yaw", _I, scale=HEADING_MDEG),
        Field("time", "I", scale=CLOCK_MS),
    ),
    Ack: Layout(None, FrameKind.ACK, (Field("pd", _B, enum=PD),)),
}

# Receivers' lookup tables, derived from LAYOUTS.
VEHICLE_BY_PD: dict[int, type[Message]] = {
    lay.pd: cls
    for cls, lay in LAYOUTS.items()
    if lay.kind is FrameKind.VEHICLE and lay.pd is not None
}
SKEYE_BY_PD: dict[int, type[Message]] = {
    lay.pd: cls
    for cls, lay in LAYOUTS.items()
    if lay.kind is FrameKind.SKEYE and lay.pd is not None
}
ASCTEC_BY_PREFIX: dict[bytes, type[Message]] = {
    lay.prefix: cls for cls, lay in LAYOUTS.items() if lay.kind is FrameKind.ASCTEC
}


def _check_layouts() -> None:
    """Import-time guard: each layout names exactly the message's attributes, in range."""
    for cls, lay in LAYOUTS.items():
        wire = {f.name for f in lay.fields if not f.computed} | ({lay.tail} if lay.tail else set())
        attrs = {f.name for f in fields(cls)}
        if wire != attrs:
            raise AssertionError(f"layout of {cls.__name__} names {wire}, class has {attrs}")
        for f in lay.fields:
            lo, hi = f.limits
            type_lo, type_hi = _CODE_RANGES[f.code]
            if not type_lo <= lo <= hi <= type_hi:
                raise AssertionError(f"{cls.__name__}.{f.name}: range {lo}..{hi} vs '{f.code}'")
            if f.saturate and f.scale is None:
                raise AssertionError(f"{cls.__name__}.{f.name}: saturates but has no scale")


_check_layouts()
