"""SI views of vehicle packets, derived from the scales in ``packet_defs.LAYOUTS``.

How this works: each SI view is a small frozen dataclass whose fields say which wire fields
they stand for (``Annotated[float, Wire("angle_roll")]``; a vector names three). ``to_si(msg,
View)`` reads every named field through the ``Scale`` its ``packet_defs.Field`` carries, and
``from_si(Message, *views)`` writes them back: one generic pair for every message, so a unit
is written once, in the table. Unscaled fields (states, modes, counts) pass through.

Building from SI rounds to the nearest count and refuses NaN, infinity and non-numbers with
``LocalProtocolError`` naming the view's field; only the stick, thrust and quality units clamp,
because the protocol defines their range and full stick is a legitimate request. Fields the
table marks ``saturate`` (int16 accelerations, NAV_STATUS velocities, battery voltage, the
distance to the waypoint) saturate at their wire limits, as a real sensor saturates, so a hard
landing cannot crash the telemetry; anything else out of range is refused (LocalProtocolError
naming the view's field, its value and the range the message carries, in SI units).

Frames: AscTec's IMU body frame is x forward, y right, z down (FRD), the same as the simulator
protocol's; "nick" is pitch. Earth-frame vectors (IMU_CALCDATA acc_x/y/z and speed_x/y/z,
NAV_STATUS x/y/z and vx/vy/vz) are world NED: x north, y east, z down. GPS_DATA is the
exception the protocol names: speed_x is east, speed_y north. ``height`` fields are positive up.
Yaw on the wire is 0..360000 (1/1000 deg, clockwise from north); yaw in SI is wrapped to
[-pi, pi).

The named converters (``rad_to_mdeg`` / ``mdeg_to_rad`` ...) are the scales' two directions,
for code that converts one value.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Annotated, Any, TypeVar, get_args, get_origin, get_type_hints

from skeye.errors import LocalProtocolError
from skeye.wire import scales as u
from skeye.wire.packet_defs import (
    LAYOUTS,
    CtrlBits,
    CtrlInput,
    Field,
    GotoGps,
    GpsData,
    GpsDataAdvanced,
    ImuCalcData,
    Message,
    MoveBy,
    MoveFrame,
    NavState,
    NavStatus,
    PadAction,
    PadMode,
    PadReport,
    Stream,
    TakeOff,
    Truth,
    Velocity,
    Waypoint,
    WaypointProps,
)
from skeye.wire.scales import STICK_MAX as STICK_MAX  # re-exported: the unit's range
from skeye.wire.scales import THRUST_MAX as THRUST_MAX
from skeye.wire.scales import Scale, clamp
from skeye.wire.scales import wrap_pi as wrap_pi

Vec3 = tuple[float, float, float]
M = TypeVar("M", bound=Message)
V = TypeVar("V")

# --- one value at a time: each scale's two directions ---------------------------------------

mdeg_to_rad, rad_to_mdeg = u.MDEG.to_si, u.MDEG.to_wire  # no wrapping: roll, pitch, relative yaw
yaw_mdeg_to_rad, yaw_rad_to_mdeg = u.HEADING_MDEG.to_si, u.HEADING_MDEG.to_wire
angvel_counts_to_rad_s, rad_s_to_angvel_counts = u.ANGVEL.to_si, u.ANGVEL.to_wire
mrad_s_to_rad_s, rad_s_to_mrad_s = u.MRAD_S.to_si, u.MRAD_S.to_wire
acc_counts_to_m_s2, m_s2_to_acc_counts = u.ACC.to_si, u.ACC.to_wire
mm_to_m, m_to_mm = u.MM.to_si, u.MM.to_wire
mm_s_to_m_s, m_s_to_mm_s = u.MM_S.to_si, u.MM_S.to_wire
dm_to_m, m_to_dm = u.DM.to_si, u.DM.to_wire
deg_e7_to_deg, deg_to_deg_e7 = u.DEG_E7.to_si, u.DEG_E7.to_wire
ms_to_s, s_to_ms = u.MS.to_si, u.MS.to_wire
cs_to_s, s_to_cs = u.CS.to_si, u.CS.to_wire
mv_to_v, v_to_mv = u.MV.to_si, u.MV.to_wire
quality_to_fraction, fraction_to_quality = u.QUALITY.to_si, u.QUALITY.to_wire
controller_thrust_to_fraction = u.CONTROLLER_THRUST.to_si
fraction_to_controller_thrust = u.CONTROLLER_THRUST.to_wire
stick_to_angle_rad, angle_rad_to_stick = u.STICK_ANGLE.to_si, u.STICK_ANGLE.to_wire
stick_to_yaw_rate_rad_s, yaw_rate_rad_s_to_stick = u.STICK_YAW_RATE.to_si, u.STICK_YAW_RATE.to_wire
thrust_counts_to_fraction, thrust_fraction_to_counts = u.THRUST.to_si, u.THRUST.to_wire


# --- the generic views ----------------------------------------------------------------------


@dataclass(frozen=True)
class Wire:
    """Marks an SI view's field with the wire field(s) it stands for (three for a vector).

    ``read`` converts the passed-through value of an unscaled field (``bool``, a flag type).
    """

    names: tuple[str, ...]
    read: Callable[[Any], Any] | None = None


def _w(*names: str, read: Callable[[Any], Any] | None = None) -> Wire:
    return Wire(names, read)


_VIEWS: dict[type, tuple[tuple[str, Wire], ...]] = {}
_FIELDS = {cls: {f.name: f for f in lay.fields} for cls, lay in LAYOUTS.items()}


def view_fields(view: type) -> tuple[tuple[str, Wire], ...]:
    """(SI field name, ``Wire``) of every field of an SI view class, in order."""
    known = _VIEWS.get(view)
    if known is not None:
        return known
    hints = get_type_hints(view, include_extras=True)
    out = []
    for f in fields(view):
        hint = hints[f.name]
        marks = [a for a in get_args(hint) if isinstance(a, Wire)]
        if get_origin(hint) is not Annotated or len(marks) != 1:
            raise TypeError(f"{view.__name__}.{f.name} is not annotated with one Wire")
        out.append((f.name, marks[0]))
    return _VIEWS.setdefault(view, tuple(out))


def _field(cls: type[Message], name: str) -> Field:
    try:
        return _FIELDS[cls][name]
    except KeyError:
        raise LocalProtocolError(f"{cls.__name__} has no wire field {name!r}") from None


ZERO_MEANS: dict[tuple[type[Message], str], str] = {
    (Velocity, "duration"): "until replaced",
    (MoveBy, "speed"): "the default 1 m/s",
    (GotoGps, "speed"): "the default 1 m/s",
    (PadMode, "deadband"): "the default 0.05 m",
    (PadMode, "max_speed"): "the default 0.3 m/s",
    (Stream, "period"): "stop streaming",
}
"""The wire fields whose 0 is no small value but a word of its own (docs/protocols/packets.md),
and what the vehicle reads it as: a value not 0 that rounds to 0 counts there is refused
(:class:`RoundsToZero`), where it was sent as that word (a 0.4 ms stream period as "stop")."""


class RoundsToZero(LocalProtocolError):
    """A value not 0 that a field whose 0 means something else (:data:`ZERO_MEANS`) would
    carry as 0."""


def wire_value(
    cls: type[Message], name: str, value: Any, scale: Scale | None = None, what: str = ""
) -> Any:
    """``value`` in SI -> what ``cls``'s field ``name`` carries (its scale, or ``scale``)."""
    f = _field(cls, name)
    scale = scale or f.scale
    if scale is None:
        return value
    counts = scale.to_wire(value, what or f"{cls.__name__}.{name} in {scale.unit}")
    meaning = ZERO_MEANS.get((cls, name))
    if meaning is not None and counts == 0 and value != 0:
        step = abs(scale.to_si(1))
        raise RoundsToZero(f"{what or f'{cls.__name__}.{name}'} {float(value):g} "
                           f"{scale.unit} is 0 in {cls.__name__}, which carries it in steps "
                           f"of {step:g} {scale.unit}, and 0 there means {meaning}: give 0 "
                           f"for that, or at least {step:g} {scale.unit}")
    if f.saturate:
        return clamp(counts, *f.limits)
    lo, hi = f.limits
    if not lo <= counts <= hi:  # said in the caller's SI units (the message says it on the wire)
        a, b = sorted((scale.to_si(lo), scale.to_si(hi)))
        said = what or f"{cls.__name__}.{name}"
        raise LocalProtocolError(f"{said} {float(value):g} {scale.unit} is outside "
                                 f"{a:g}..{b:g} {scale.unit}, what {cls.__name__} carries")
    return counts


def si_range(cls: type[Message], name: str) -> tuple[float, float]:
    """The SI values (low, high) that ``cls``'s scaled field ``name`` carries."""
    f = _field(cls, name)
    if f.scale is None:
        raise LocalProtocolError(f"{cls.__name__}.{name} has no SI scale")
    lo, hi = f.limits
    a, b = sorted((f.scale.to_si(lo), f.scale.to_si(hi)))
    return a, b


def si_value(msg: Message, name: str, scale: Scale | None = None) -> Any:
    """Field ``name`` of ``msg`` in SI (through its scale, or ``scale``; unscaled: as is)."""
    raw = getattr(msg, name)
    scale = scale or _field(type(msg), name).scale
    return raw if scale is None else scale.to_si(raw)


def to_si(msg: Message, view: type[V], scales: Mapping[str, Scale] | None = None) -> V:
    """Read ``msg`` as the SI view ``view``; ``scales`` overrides the table's, by wire name."""
    over = scales or {}
    kwargs: dict[str, Any] = {}
    for name, mark in view_fields(view):
        values = tuple(si_value(msg, n, over.get(n)) for n in mark.names)
        value: Any = values[0] if len(values) == 1 else values
        kwargs[name] = value if mark.read is None else mark.read(value)
    return view(**kwargs)


def from_si(cls: type[M], *views: object, scales: Mapping[str, Scale] | None = None) -> M:
    """Build ``cls`` from SI views (each wire field from the view that names it).

    Raises:
        LocalProtocolError: a value is not a finite number, a vector has not the length its
            view names, or the message refuses a value (out of its wire range).
    """
    over = scales or {}
    kwargs: dict[str, Any] = {}
    for view in views:
        for name, mark in view_fields(type(view)):
            what = f"{type(view).__name__}.{name}"
            value = getattr(view, name)
            parts = _vector(value, len(mark.names), what) if len(mark.names) > 1 else (value,)
            for k, (n, part) in enumerate(zip(mark.names, parts, strict=True)):
                label = what if len(parts) == 1 else f"{what}[{k}]"
                if len(parts) > 1 and isinstance(part, numbers.Real):
                    part = float(part) if (over.get(n) or _field(cls, n).scale) else part
                kwargs[n] = wire_value(cls, n, part, over.get(n), label)
    return cls(**kwargs)


def _vector(v: Any, n: int, what: str) -> tuple[Any, ...]:
    """The ``n`` components of a vector (scaled ones are then converted in double precision,
    numpy float32 too, as a vector always was)."""
    try:
        items = tuple(v)
    except TypeError:
        raise LocalProtocolError(f"{what} needs {n} components, got {v!r}") from None
    if len(items) != n:
        raise LocalProtocolError(f"{what} needs {n} components, got {len(items)}")
    return items


# --- the views ------------------------------------------------------------------------------


@dataclass(frozen=True)
class ImuCalcSi:
    """IMU_CALCDATA in SI. Angles and rates about body FRD axes; earth vectors NED."""

    roll_rad: Annotated[float, _w("angle_roll")]
    pitch_rad: Annotated[float, _w("angle_nick")]
    yaw_rad: Annotated[float, _w("angle_yaw")]
    roll_rate_rad_s: Annotated[float, _w("angvel_roll")]
    pitch_rate_rad_s: Annotated[float, _w("angvel_nick")]
    yaw_rate_rad_s: Annotated[float, _w("angvel_yaw")]
    # calibrated, body frame
    acc_body_frd_m_s2: Annotated[Vec3, _w("acc_x_calib", "acc_y_calib", "acc_z_calib")]
    acc_earth_ned_m_s2: Annotated[Vec3, _w("acc_x", "acc_y", "acc_z")]
    # attitude from the accelerometer alone
    acc_angle_roll_rad: Annotated[float, _w("acc_angle_roll")]
    acc_angle_pitch_rad: Annotated[float, _w("acc_angle_nick")]
    acc_absolute_m_s2: Annotated[float, _w("acc_absolute_value")]
    # Hx, Hy, Hz: direction only, passed through unscaled
    mag_field_raw: Annotated[tuple[int, int, int], _w("Hx", "Hy", "Hz")]
    mag_heading_rad: Annotated[float, _w("mag_heading")]
    vel_ned_m_s: Annotated[Vec3, _w("speed_x", "speed_y", "speed_z")]
    height_m: Annotated[float, _w("height")]  # fused, positive up
    climb_rate_m_s: Annotated[float, _w("dheight")]  # positive up
    baro_climb_rate_m_s: Annotated[float, _w("dheight_reference")]
    baro_height_m: Annotated[float, _w("height_reference")]


@dataclass(frozen=True)
class StickSi:
    """CTRL_INPUT in SI: commanded attitude, yaw rate and thrust fraction."""

    roll_rad: Annotated[float, _w("roll")]
    pitch_rad: Annotated[float, _w("pitch")]
    yaw_rate_rad_s: Annotated[float, _w("yaw")]
    thrust_fraction: Annotated[float, _w("thrust")]
    ctrl: Annotated[int, _w("ctrl", read=CtrlBits)]  # CtrlBits


_ALL_STICKS = CtrlBits.PITCH | CtrlBits.ROLL | CtrlBits.YAW | CtrlBits.THRUST


def ctrl_input_from_si(
    roll_rad: float,
    pitch_rad: float,
    yaw_rate_rad_s: float,
    thrust_fraction: float,
    ctrl: int = _ALL_STICKS,
) -> CtrlInput:
    """Build CTRL_INPUT from SI commands (sticks and thrust clamp to their ranges)."""
    return from_si(CtrlInput, StickSi(roll_rad, pitch_rad, yaw_rate_rad_s, thrust_fraction, ctrl))


@dataclass(frozen=True)
class GpsSi:
    """GPS_DATA in SI (velocities east/north, as the structure carries them)."""

    latitude_deg: Annotated[float, _w("latitude")]
    longitude_deg: Annotated[float, _w("longitude")]
    height_m: Annotated[float, _w("height")]
    vel_east_m_s: Annotated[float, _w("speed_x")]
    vel_north_m_s: Annotated[float, _w("speed_y")]
    heading_rad: Annotated[float, _w("heading")]
    horizontal_accuracy_m: Annotated[float, _w("horizontal_accuracy")]
    vertical_accuracy_m: Annotated[float, _w("vertical_accuracy")]
    speed_accuracy_m_s: Annotated[float, _w("speed_accuracy")]
    num_sv: Annotated[int, _w("numSV")]
    status: Annotated[int, _w("status")]  # GPS_FIX_VALID (0x03) = valid fix


@dataclass(frozen=True)
class GpsBestSi:
    """GPS_DATA_ADVANCED's fused best estimates in SI."""

    latitude_deg: Annotated[float, _w("latitude_best_estimate")]
    longitude_deg: Annotated[float, _w("longitude_best_estimate")]
    vel_east_m_s: Annotated[float, _w("speed_x_best_estimate")]
    vel_north_m_s: Annotated[float, _w("speed_y_best_estimate")]


def gps_data_to_si(msg: GpsData | GpsDataAdvanced) -> GpsSi:
    """Read GPS_DATA (or the GPS_DATA part of GPS_DATA_ADVANCED) in SI."""
    return to_si(msg, GpsSi)


def gps_data_advanced_from_si(gps: GpsSi, best: GpsBestSi) -> GpsDataAdvanced:
    """Build GPS_DATA_ADVANCED from the receiver solution and the fused estimate."""
    return from_si(GpsDataAdvanced, gps, best)


def gps_data_advanced_to_si(msg: GpsDataAdvanced) -> tuple[GpsSi, GpsBestSi]:
    """Read GPS_DATA_ADVANCED in SI: (receiver solution, fused best estimate)."""
    return to_si(msg, GpsSi), to_si(msg, GpsBestSi)


@dataclass(frozen=True)
class NavStatusSi:
    """NAV_STATUS in SI (world NED)."""

    state: Annotated[NavState, _w("state")]
    pad_mode: Annotated[PadAction, _w("pad_mode")]
    pos_ned_m: Annotated[Vec3, _w("x", "y", "z")]
    yaw_rad: Annotated[float, _w("yaw")]
    vel_ned_m_s: Annotated[Vec3, _w("vx", "vy", "vz")]
    battery_v: Annotated[float, _w("battery")]
    time_s: Annotated[float, _w("time")]
    # The estimate's own 1-sigma, horizontal (sqrt(var_n + var_e), GNSS's "DRMS") and vertical;
    # 0: not known (the vehicle's estimator states none).
    sigma_h_m: Annotated[float, _w("sigma_h")] = 0.0
    sigma_v_m: Annotated[float, _w("sigma_v")] = 0.0


@dataclass(frozen=True)
class TruthSi:
    """TRUTH in SI: a simulated vehicle's true position (NAV_STATUS's frame: north and east of
    the world origin, down from the ground at home) and heading."""

    pos_ned_m: Annotated[Vec3, _w("x", "y", "z")]
    yaw_rad: Annotated[float, _w("yaw")]
    time_s: Annotated[float, _w("time")]


@dataclass(frozen=True)
class PadSi:
    """PAD in SI: pad centre offset in body FRD, height, identified rings, quality 0..1, and
    whether the pilot finds its vision too slow to hold on (the pad modes then hold still)."""

    found: Annotated[bool, _w("found", read=bool)]
    rings: Annotated[int, _w("rings")]
    dx_m: Annotated[float, _w("dx")]
    dy_m: Annotated[float, _w("dy")]
    height_m: Annotated[float, _w("height")]
    quality: Annotated[float, _w("quality")]
    frame_time_s: Annotated[float, _w("frame_time")]
    vision_too_slow: Annotated[bool, _w("vision", read=bool)] = False


# --- skeye and AscTec commands ----------------------------------------------------------------


@dataclass(frozen=True)
class VelocitySi:
    """VELOCITY in SI: body FRD velocity, yaw rate, duration (0 = until replaced)."""

    vel_frd_m_s: Annotated[Vec3, _w("vx", "vy", "vz")]
    yaw_rate_rad_s: Annotated[float, _w("yaw_rate")]
    duration_s: Annotated[float, _w("duration")]


def velocity_from_si(
    vel_frd_m_s: Sequence[float], yaw_rate_rad_s: float, duration_s: float = 0.0
) -> Velocity:
    """Build VELOCITY (raises LocalProtocolError beyond +-32.767 m/s or 65.535 s)."""
    v = _vector(vel_frd_m_s, 3, "vel_frd_m_s")
    return from_si(Velocity, VelocitySi((v[0], v[1], v[2]), yaw_rate_rad_s, duration_s))


@dataclass(frozen=True)
class MoveBySi:
    """MOVE_BY in SI: displacement in ``frame`` (body FRD or world NED), yaw change, speed."""

    delta_m: Annotated[Vec3, _w("dx", "dy", "dz")]
    dyaw_rad: Annotated[float, _w("dyaw")]
    frame: Annotated[MoveFrame, _w("frame")]
    speed_m_s: Annotated[float, _w("speed")]


@dataclass(frozen=True)
class GotoGpsSi:
    """GOTO_GPS in SI."""

    latitude_deg: Annotated[float, _w("latitude")]
    longitude_deg: Annotated[float, _w("longitude")]
    height_m: Annotated[float, _w("height")]  # above home
    speed_m_s: Annotated[float, _w("speed")]


def take_off_from_si(height_m: float) -> TakeOff:
    """Build TAKE_OFF to ``height_m`` (must round to at least 1 mm)."""
    return TakeOff(height=wire_value(TakeOff, "height", height_m))


def take_off_to_si(msg: TakeOff) -> float:
    """TAKE_OFF's target height in metres."""
    return float(si_value(msg, "height"))


@dataclass(frozen=True)
class PadModeSi:
    """PAD_MODE in SI."""

    mode: Annotated[PadAction, _w("mode")]
    deadband_m: Annotated[float, _w("deadband")]
    max_speed_m_s: Annotated[float, _w("max_speed")]


@dataclass(frozen=True)
class WaypointSi:
    """WAYPOINT in SI. ``x``/``y`` are metres, or longitude/latitude degrees when
    ``properties`` has ABSOLUTE."""

    properties: Annotated[int, _w("properties")]  # WaypointProps
    max_speed_percent: Annotated[int, _w("max_speed")]
    hold_time_s: Annotated[float, _w("time")]
    position_accuracy_m: Annotated[float, _w("pos_acc")]
    x: Annotated[float, _w("X")]
    y: Annotated[float, _w("Y")]
    yaw_rad: Annotated[float, _w("yaw")]
    height_m: Annotated[float, _w("height")]


def _waypoint_scales(properties: int) -> dict[str, Scale]:
    """X and Y are degrees x 1e7 in an absolute waypoint (the table's MM otherwise)."""
    return {"X": u.DEG_E7, "Y": u.DEG_E7} if properties & WaypointProps.ABSOLUTE else {}


def waypoint_from_si(si: WaypointSi) -> Waypoint:
    """Build WAYPOINT from SI values (checksum is added on encode)."""
    return from_si(Waypoint, si, scales=_waypoint_scales(si.properties))


def waypoint_to_si(msg: Waypoint) -> WaypointSi:
    """Read WAYPOINT in SI."""
    return to_si(msg, WaypointSi, scales=_waypoint_scales(msg.properties))


# --- each message's two directions -------------------------------------------------------------


def _pair(cls: type[M], view: type[V]) -> tuple[Callable[[V], M], Callable[[M], V]]:
    """(build ``cls`` from its SI view, read ``cls`` as its SI view), for one message."""

    def build(si: V) -> M:
        return from_si(cls, si)

    def read(msg: M) -> V:
        return to_si(msg, view)

    build.__doc__ = f"Build {cls.__name__} from {view.__name__}."
    read.__doc__ = f"Read {cls.__name__} as {view.__name__}."
    return build, read


imu_calcdata_from_si, imu_calcdata_to_si = _pair(ImuCalcData, ImuCalcSi)
gps_data_from_si = _pair(GpsData, GpsSi)[0]
nav_status_from_si, nav_status_to_si = _pair(NavStatus, NavStatusSi)
truth_from_si, truth_to_si = _pair(Truth, TruthSi)
pad_report_from_si, pad_report_to_si = _pair(PadReport, PadSi)
ctrl_input_to_si = _pair(CtrlInput, StickSi)[1]
velocity_to_si = _pair(Velocity, VelocitySi)[1]
move_by_from_si, move_by_to_si = _pair(MoveBy, MoveBySi)
goto_gps_from_si, goto_gps_to_si = _pair(GotoGps, GotoGpsSi)
pad_mode_from_si, pad_mode_to_si = _pair(PadMode, PadModeSi)
