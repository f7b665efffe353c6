"""The simulator protocol's messages as frozen dataclasses (docs/protocols/simulator.md).

How this works: one class per message; each field's wire key, value kind and allowed range are
declared once, in the field's metadata (:func:`wire`), and :mod:`skeye.wire.sim` builds its codec
table from them. Units are SI and named in the field (``time_s``, ``location_ned_m``,
``roll_rad``); angles are radians. A field whose default is None is optional on the wire: it is
left out when None and None when absent. Commands (client to simulator) are :class:`Init`,
:class:`Drive`, :class:`Reset`, :class:`Step`, :class:`Set`, :class:`Ping`, :class:`GetConf`,
:class:`GetGeo`, :class:`GetStartPoses`; messages (simulator to client) are :class:`Sta`, one
``Sen*`` class per sensor Type, :class:`Res`, :class:`Err`, :class:`Nfo`, :class:`StartPoses`,
:class:`Conf` and :class:`Geo`.

Invariants: messages never change after they are built; the field order of a class is the order
of its blocks on the wire (the simulator's stream bytes depend on it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

Vec3 = tuple[float, float, float]
Pose = tuple[str, Vec3, Vec3]
"""A start pose: name, location (NED, m) and rotation (roll, pitch, yaw, rad)."""

KINDS = ("float", "int", "bool", "word", "text", "vec3", "uvec3", "vec2", "ivec2", "vec")
"""Value kinds: a finite float, a decimal int, true/false, a word without blanks, free text, a
vector of 3 or 2 floats, 2 ints (written as ints, read as floats), any number of floats.
``uvec3`` is a vector of 3 floats a client sends, read as USARSim's ``ParseVector`` reads it
(:func:`skeye.wire.sim_lines.parse_usarsim_vector`) and written like ``vec3``."""

TILT_LIMIT_RAD = math.pi / 2 - 1e-3
"""The largest DRIVE roll or pitch angle accepted (the wire carries it in degrees)."""

DEG = math.pi / 180.0
"""The scale of a field whose wire unit is the degree (or deg/s): SI value = wire value * DEG."""


MAX_ROBOT_NAME_CHARS = 64
"""The longest robot name (INIT's ``Name``): an identifier, written in every STA line (and
INIT's answer), which must stay within the control protocol's 64 KiB line limit."""
MAX_PING_ID_CHARS = 1000
"""The longest PING ``Id``, echoed in its answer: as long as an ERR's reason."""


def wire(
    key: str,
    kind: str,
    *,
    min_value: float | None = None,
    max_value: float | None = None,
    scale: float = 1.0,
    max_chars: int | None = None,
) -> dict[str, Any]:
    """A field's metadata: it is the block ``{key value}`` of ``kind`` within the range.

    ``scale`` converts the wire unit to the field's SI unit (field = wire * scale; ``DEG`` for
    USARSim's degrees); the range is in wire units. ``max_chars`` bounds a word or text: the
    simulator refuses a longer one, and a client cannot build it.
    """
    if kind not in KINDS:
        raise ValueError(f"unknown wire kind {kind!r}")  # a bug in this module
    if scale != 1.0 and kind != "float":
        raise ValueError(f"{key}: only a float field may have a scale")  # a bug in this module
    if max_chars is not None and kind not in ("word", "text"):
        raise ValueError(f"{key}: only a word or text may have max_chars")  # a bug here
    return {"key": key, "kind": kind, "min": min_value, "max": max_value, "scale": scale,
            "max_chars": max_chars}


# --- commands --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Init:
    """``INIT``: spawn a robot of a class at a start pose or a NED location."""

    WORD: ClassVar[str] = "INIT"
    IGNORED_KEYS: ClassVar[tuple[str, ...]] = ("Team",)
    """Keys of USARSim's INIT (``BotConnection.InitReceived``) accepted and unused: no teams."""
    class_name: str = field(metadata=wire("ClassName", "word"))
    name: str | None = field(
        default=None, metadata=wire("Name", "word", max_chars=MAX_ROBOT_NAME_CHARS))
    start: str | None = field(default=None, metadata=wire("Start", "word"))
    location_ned_m: Vec3 | None = field(default=None, metadata=wire("Location", "uvec3"))
    rotation_rpy_rad: Vec3 | None = field(default=None, metadata=wire("Rotation", "uvec3"))
    """None: level, heading north (0, 0, 0). Both vectors read as USARSim's ``ParseVector``."""


@dataclass(frozen=True)
class Drive:
    """``DRIVE``: set-points per axis, as USARSim's ``AerialVehicle.Drive``: each field sets its
    own axis and the axes left out keep theirs. The pitch axis takes ``LinearVelocity`` or
    ``PitchAngle``, the roll axis ``LateralVelocity`` or ``RollAngle``, the vertical axis
    ``AltitudeVelocity`` or ``Thrust`` (a skeye extension), the yaw axis
    ``RotationalVelocity``. All of one form make the attitude form (roll, pitch, thrust) or
    the velocity form.

    The fields are SI (m/s, rad, rad/s); on the wire ``RollAngle`` and ``PitchAngle`` are degrees
    and ``RotationalVelocity`` deg/s, as in USARSim's ``AerialVehicle.uc`` (``AngleFromDeg``).
    With ``normalized`` the wire values are percent of the robot's limits. The angle bounds
    (``TILT_LIMIT_RAD``, or the limits when normalized) are checked by
    :func:`skeye.wire.sim.drive_in_si`.
    """

    WORD: ClassVar[str] = "DRIVE"
    roll_rad: float | None = field(default=None, metadata=wire("RollAngle", "float", scale=DEG))
    pitch_rad: float | None = field(default=None, metadata=wire("PitchAngle", "float", scale=DEG))
    forward_m_s: float | None = field(default=None, metadata=wire("LinearVelocity", "float"))
    right_m_s: float | None = field(default=None, metadata=wire("LateralVelocity", "float"))
    up_m_s: float | None = field(default=None, metadata=wire("AltitudeVelocity", "float"))
    yaw_rate_rad_s: float | None = field(
        default=None, metadata=wire("RotationalVelocity", "float", scale=DEG)
    )
    thrust_fraction: float | None = field(
        default=None, metadata=wire("Thrust", "float", min_value=0.0, max_value=1.0)
    )
    normalized: bool | None = field(default=None, metadata=wire("Normalized", "bool"))
    name: str | None = field(default=None, metadata=wire("Name", "word"))
    # skeye extension: the board mode the set-point is flown in (docs/physics.md, board modes):
    # "height" with the attitude form (angles; Thrust is a climb rate around 0.5, height held
    # at the centre), "gps" with the velocity form (centred sticks hold the position while the
    # estimator has a GPS fix). Absent: attitude mode / flow velocity hold, by the form.
    board_mode: str | None = field(default=None, metadata=wire("BoardMode", "word"))

    BOARD_MODES: ClassVar[dict[str, bool]] = {"height": True, "gps": False}  # mode -> attitude
    ATTITUDE_KEYS: ClassVar[tuple[str, ...]] = ("RollAngle", "PitchAngle", "Thrust")
    VELOCITY_KEYS: ClassVar[tuple[str, ...]] = (
        "AltitudeVelocity",
        "LinearVelocity",
        "LateralVelocity",
    )
    AXES: ClassVar[tuple[tuple[str, str], ...]] = (
        ("LinearVelocity", "PitchAngle"),
        ("LateralVelocity", "RollAngle"),
        ("AltitudeVelocity", "Thrust"),
    )
    """Each axis's (velocity form, attitude form) key."""

    @property
    def attitude(self) -> bool:
        """Whether some axis is given in the attitude form (roll, pitch, thrust)."""
        return not (
            self.roll_rad is None and self.pitch_rad is None and self.thrust_fraction is None
        )

    @property
    def velocity(self) -> bool:
        """Whether some axis is given in the velocity form (forward, right, up)."""
        return not (self.forward_m_s is None and self.right_m_s is None and self.up_m_s is None)


@dataclass(frozen=True)
class Reset:
    """``RESET``: respawn the connection's robot, still, with a fresh board (a skeye extension):
    at a start pose, at a NED location (and rotation), or, with neither, where it was spawned.
    It keeps its name and cameras; a crashed robot flies again."""

    WORD: ClassVar[str] = "RESET"
    start: str | None = field(default=None, metadata=wire("Start", "word"))
    location_ned_m: Vec3 | None = field(default=None, metadata=wire("Location", "uvec3"))
    rotation_rpy_rad: Vec3 | None = field(default=None, metadata=wire("Rotation", "uvec3"))


@dataclass(frozen=True)
class Step:
    """``STEP``: advance a lockstep simulator ``count`` physics steps; with ``sync``, in step
    with the other connections that drive the clock so (see skeye.sim.clock_barrier)."""

    WORD: ClassVar[str] = "STEP"
    count: int = field(default=1, metadata=wire("Count", "int", min_value=1, max_value=10_000_000))
    sync: bool | None = field(default=None, metadata=wire("Sync", "bool"))


@dataclass(frozen=True)
class Set:
    """``SET``: change the world (``Type Wind``: mode, params) or a camera (name, opcode)."""

    WORD: ClassVar[str] = "SET"
    type: str = field(metadata=wire("Type", "word"))
    name: str | None = field(default=None, metadata=wire("Name", "word"))
    mode: str | None = field(default=None, metadata=wire("Mode", "word"))
    opcode: str | None = field(default=None, metadata=wire("Opcode", "word"))
    params: str | None = field(default=None, metadata=wire("Params", "text"))


@dataclass(frozen=True)
class Ping:
    """``PING``: the simulator answers ``RES {Command PING} {Id id} {Time t}``."""

    WORD: ClassVar[str] = "PING"
    id: str = field(default="", metadata=wire("Id", "text", max_chars=MAX_PING_ID_CHARS))


@dataclass(frozen=True)
class GetConf:
    """``GETCONF``: the robot's (``Type Robot``) or a sensor's configuration."""

    WORD: ClassVar[str] = "GETCONF"
    type: str = field(metadata=wire("Type", "word"))
    name: str | None = field(default=None, metadata=wire("Name", "word"))


@dataclass(frozen=True)
class GetGeo:
    """``GETGEO``: the robot's (``Type Robot``) or a sensor's geometry."""

    WORD: ClassVar[str] = "GETGEO"
    type: str = field(metadata=wire("Type", "word"))
    name: str | None = field(default=None, metadata=wire("Name", "word"))


@dataclass(frozen=True)
class GetStartPoses:
    """``GETSTARTPOSES``: the world's start poses, answered by :class:`StartPoses`."""

    WORD: ClassVar[str] = "GETSTARTPOSES"


# --- messages --------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class Sta:
    """``STA``: a robot's status: battery life left (whole s), voltage, current, flight state.

    ``{Time t} {Battery n}`` come first, as USARSim's ``USARVehicle.GetStatus`` writes them (an
    integer ``Battery``, as its ``Battery.ExpectedLifeTime``); skeye's keys follow. There is no
    ``{Type}``: UDK writes none for an aerial vehicle, and a UT2004-era client reads one as
    UT2004's status layout for that type (a ``Type`` in a line read is ignored).
    """

    WORD: ClassVar[str] = "STA"
    time_s: float = field(metadata=wire("Time", "float", min_value=0.0))
    battery_s: int | None = field(default=None, metadata=wire("Battery", "int", min_value=0))
    """None: not given (a simulator that writes no Battery)."""
    name: str | None = field(default=None, metadata=wire("Name", "word"))
    voltage_v: float | None = field(default=None, metadata=wire("Voltage", "float"))
    current_a: float | None = field(default=None, metadata=wire("Current", "float"))
    armed: bool = field(default=False, metadata=wire("Armed", "bool"))
    landed: bool = field(default=False, metadata=wire("Landed", "bool"))


@dataclass(frozen=True)
class Sen:
    """``SEN {Time t} {Type T} {Name n} ...``: one sensor reading; one subclass per Type."""

    WORD: ClassVar[str] = "SEN"
    TYPE: ClassVar[str] = ""
    time_s: float = field(metadata=wire("Time", "float", min_value=0.0))
    name: str = field(metadata=wire("Name", "word"))


@dataclass(frozen=True)
class SenGroundTruth(Sen):
    TYPE: ClassVar[str] = "GroundTruth"
    location_ned_m: Vec3 = field(metadata=wire("Location", "vec3"))
    orientation_rpy_rad: Vec3 = field(metadata=wire("Orientation", "vec3"))
    velocity_ned_m_s: Vec3 = field(metadata=wire("Velocity", "vec3"))
    angular_velocity_frd_rad_s: Vec3 = field(metadata=wire("AngularVelocity", "vec3"))


@dataclass(frozen=True)
class SenIns(Sen):
    TYPE: ClassVar[str] = "INS"
    location_ned_m: Vec3 = field(metadata=wire("Location", "vec3"))
    orientation_rpy_rad: Vec3 = field(metadata=wire("Orientation", "vec3"))
    velocity_ned_m_s: Vec3 | None = field(default=None, metadata=wire("Velocity", "vec3"))
    position_sigma_ned_m: Vec3 | None = field(default=None, metadata=wire("PositionSigma", "vec3"))
    """The estimator's own 1-sigma of each position axis (the square root of its covariance's
    diagonal), m; absent where the estimate has no covariance (``--estimator truth``)."""


@dataclass(frozen=True)
class SenAccelerometer(Sen):
    TYPE: ClassVar[str] = "Accelerometer"
    proper_acceleration_frd_m_s2: Vec3 = field(metadata=wire("ProperAcceleration", "vec3"))


@dataclass(frozen=True)
class SenGyro(Sen):
    TYPE: ClassVar[str] = "Gyro"
    angular_velocity_frd_rad_s: Vec3 = field(metadata=wire("AngularVelocity", "vec3"))


@dataclass(frozen=True)
class SenMagneticCompass(Sen):
    TYPE: ClassVar[str] = "MagneticCompass"
    magnetic_angle_rad: float = field(metadata=wire("MagneticAngle", "float"))
    field_frd_ut: Vec3 | None = field(default=None, metadata=wire("Field", "vec3"))


@dataclass(frozen=True)
class SenBarometer(Sen):
    TYPE: ClassVar[str] = "Barometer"
    pressure_pa: float = field(metadata=wire("Pressure", "float", min_value=0.0))
    altitude_m: float = field(metadata=wire("Altitude", "float"))


@dataclass(frozen=True)
class SenGps(Sen):
    """A GPS fix (``Fix`` > 0) or none; positions both as USARSim's ``39,8.0341,N`` text and
    as decimal degrees.

    Wire order: USARSim's ``GPSSensor.GetData`` writes ``{Latitude} {Longitude} {Fix 1}
    {Satellites n}`` with a fix and ``{Fix 0} {Satellites n}`` without, so its keys stay first
    (Latitude, Longitude) and last (Fix, Satellites); skeye's extensions sit between them.
    """

    TYPE: ClassVar[str] = "GPS"
    latitude: str | None = field(default=None, metadata=wire("Latitude", "word"))
    longitude: str | None = field(default=None, metadata=wire("Longitude", "word"))
    latitude_deg: float | None = field(
        default=None, metadata=wire("LatitudeDeg", "float", min_value=-90.0, max_value=90.0)
    )
    longitude_deg: float | None = field(
        default=None, metadata=wire("LongitudeDeg", "float", min_value=-180.0, max_value=180.0)
    )
    altitude_m: float | None = field(default=None, metadata=wire("Altitude", "float"))
    velocity_ned_m_s: Vec3 | None = field(default=None, metadata=wire("VelocityNED", "vec3"))
    fix: int = field(default=0, metadata=wire("Fix", "int"))
    satellites: int = field(default=0, metadata=wire("Satellites", "int", min_value=0))


@dataclass(frozen=True)
class SenSonar(Sen):
    TYPE: ClassVar[str] = "Sonar"
    range_m: float = field(metadata=wire("Range", "float", min_value=0.0))


@dataclass(frozen=True)
class SenOpticalFlow(Sen):
    TYPE: ClassVar[str] = "OpticalFlow"
    delta_counts: tuple[float, float] = field(metadata=wire("Delta", "ivec2"))
    quality: int = field(default=0, metadata=wire("Quality", "int"))


@dataclass(frozen=True)
class SenBattery(Sen):
    TYPE: ClassVar[str] = "Battery"
    voltage_v: float = field(metadata=wire("Voltage", "float", min_value=0.0))
    current_a: float = field(metadata=wire("Current", "float"))
    remaining: float = field(metadata=wire("Remaining", "float", min_value=0.0, max_value=1.0))


@dataclass(frozen=True)
class SenMotors(Sen):
    TYPE: ClassVar[str] = "Motors"
    speeds_rad_s: tuple[float, ...] = field(metadata=wire("Speeds", "vec"))
    commands_rad_s: tuple[float, ...] | None = field(default=None, metadata=wire("Commands", "vec"))
    thrust_n: float | None = field(default=None, metadata=wire("Thrust", "float"))


@dataclass(frozen=True)
class SenCamera(Sen):
    """A camera's frame ``frame`` now exists on the image server."""

    TYPE: ClassVar[str] = "Camera"
    frame: int = field(metadata=wire("Frame", "int", min_value=0))


SEN_CLASSES: tuple[type[Sen], ...] = (
    SenGroundTruth,
    SenIns,
    SenAccelerometer,
    SenGyro,
    SenMagneticCompass,
    SenBarometer,
    SenGps,
    SenSonar,
    SenOpticalFlow,
    SenBattery,
    SenMotors,
    SenCamera,
)
"""Every SEN class; a reading of another Type decodes as :class:`SenOther`."""


@dataclass(frozen=True)
class SenOther:
    """A reading of a sensor Type this codec has no class for: its fields as text."""

    time_s: float
    type: str
    name: str
    fields: tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class Res:
    """``RES``: a command succeeded (INIT names the robot, STEP and PING give the sim time)."""

    WORD: ClassVar[str] = "RES"
    command: str = field(metadata=wire("Command", "word"))
    name: str | None = field(default=None, metadata=wire("Name", "word"))
    type: str | None = field(default=None, metadata=wire("Type", "word"))
    id: str | None = field(default=None, metadata=wire("Id", "text"))
    status: str | None = field(default=None, metadata=wire("Status", "word"))
    time_s: float | None = field(default=None, metadata=wire("Time", "float"))
    note: str | None = field(default=None, metadata=wire("Note", "text"))
    """How the simulator read an ambiguous value (a USARSim-style vector), for the client's log."""


CRASH_COMMAND = "CRASH"
"""``ERR {Command CRASH}``: the robot crashed (skeye's crash rules, docs/protocols/simulator.md)."""
ROBOT_ERRORS = (CRASH_COMMAND, "PHYSICS", "CAMERA")
"""The ``ERR`` commands the engine sends a robot's connection of its own accord, in its stream
(a crash, a robot stopped by its physics or its camera), not as an answer to a command."""


@dataclass(frozen=True)
class Err:
    """``ERR``: a command failed, or (``PHYSICS``, ``CAMERA``, ``ENGINE``, ``CONNECT``) the
    simulator reports a failure of its own. Encoding replaces braces and line breaks in the
    reason, so an error can always be sent."""

    WORD: ClassVar[str] = "ERR"
    command: str = field(metadata=wire("Command", "word"))
    name: str | None = field(default=None, metadata=wire("Name", "word"))
    reason: str = field(default="", metadata=wire("Reason", "text"))


@dataclass(frozen=True)
class Nfo:
    """``NFO``: the greeting, with the world and the physics step (s)."""

    WORD: ClassVar[str] = "NFO"
    gametype: str | None = field(default=None, metadata=wire("Gametype", "word"))
    level: str | None = field(default=None, metadata=wire("Level", "text"))
    time_limit: int | None = field(default=None, metadata=wire("TimeLimit", "int"))
    time_step_s: float | None = field(
        default=None, metadata=wire("TimeStep", "float", min_value=1e-6)
    )
    mode: str | None = field(default=None, metadata=wire("Mode", "word"))


@dataclass(frozen=True)
class StartPoses:
    """``NFO {StartPoses n} {Pad1 x,y,z r,p,y ...}``: the answer to ``GETSTARTPOSES``."""

    WORD: ClassVar[str] = "NFO"
    poses: tuple[Pose, ...] = ()


@dataclass(frozen=True)
class RobotConf:
    """``CONF {Type AerialVehicle}``: a robot's limits, rates and mounted sensors."""

    WORD: ClassVar[str] = "CONF"
    type: str = field(default="AerialVehicle", metadata=wire("Type", "word"))
    name: str | None = field(default=None, metadata=wire("Name", "word"))
    class_name: str | None = field(default=None, metadata=wire("Class", "word"))
    mass_kg: float | None = field(default=None, metadata=wire("Mass", "float"))
    max_speed_m_s: float | None = field(default=None, metadata=wire("MaxSpeed", "float"))
    max_climb_m_s: float | None = field(default=None, metadata=wire("MaxClimb", "float"))
    max_yaw_rate_rad_s: float | None = field(default=None, metadata=wire("MaxYawRate", "float"))
    max_tilt_rad: float | None = field(default=None, metadata=wire("MaxTilt", "float"))
    max_thrust_n: float | None = field(default=None, metadata=wire("MaxThrust", "float"))
    board_rate_hz: float | None = field(default=None, metadata=wire("BoardRate", "float"))
    time_step_s: float | None = field(default=None, metadata=wire("TimeStep", "float"))
    sensors: str | None = field(default=None, metadata=wire("Sensors", "text"))
    """``Type:Name`` pairs, comma-separated."""

    def mounted(self) -> list[tuple[str, str]]:
        """The mounted sensors as (Type, Name) pairs."""
        out = []
        for item in (self.sensors or "").split(","):
            if ":" in item:
                type_name, sensor_name = (part.strip() for part in item.split(":", 1))
                out.append((type_name, sensor_name))
        return out


@dataclass(frozen=True)
class Conf:
    """``CONF {Type T} {Name n} ...`` of a sensor: its parameters, keys as the sensor names them."""

    WORD: ClassVar[str] = "CONF"
    type: str
    name: str
    fields: tuple[tuple[str, object], ...] = ()


@dataclass(frozen=True)
class Geo:
    """``GEO {Type T} {Name n} ...``: a robot's dimensions or a sensor's mount pose."""

    WORD: ClassVar[str] = "GEO"
    type: str
    name: str
    fields: tuple[tuple[str, object], ...] = ()
