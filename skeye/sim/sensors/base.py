"""Sensor base class, mount poses, parameter validation and the shared noise model.

How this works: every simulated sensor is built from a name, a :class:`Mount` (its pose on the
body, USARSim's Position and Direction) and a parameter mapping, plus a ``numpy`` Generator that
the engine seeds. Parameters are declared per class as :class:`Param` rows; keys match the
``CONF`` field names case-insensitively and ignoring underscores (``MaxRange``, ``max_range``;
the rate is ``Rate`` or ``rate_hz``). Validation happens once, in the constructor, and every
mistake raises ConfigError naming the sensor and the key. After that, :meth:`Sensor.sample`
turns ground truth (:class:`~skeye.sim.state.BodyState`, NED world, FRD body, SI) and a
:class:`WorldQuery` into the ``SEN`` fields that follow ``{Time} {Type} {Name}``.

Invariants: every random draw comes from the sensor's own Generator, in an order fixed by the
sequence of calls, so the same seed and the same calls give the same readings bit for bit. The
sensors that draw only normal deviates once set up take them through :class:`NormalStream`
(``Sensor.normals``): the same numbers in the same order, drawn ahead in blocks. Time
for random walks is sim time (``state.time_s``), never the wall clock; a time that does not
move forward advances no random walk.

Mount frame: the sensor frame is the body frame rotated by the mount's roll, pitch, yaw (ZYX,
as everywhere in skeye). Vectors the sensor reports are expressed in that frame. Range sensors
(Sonar, OpticalFlow) look along the sensor frame's +z axis, so an identity mount looks straight
down; a forward-looking sonar has Direction (0, pi/2, 0).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar, Final, Generic, Protocol, TypeVar

import numpy as np

from skeye.errors import ConfigError
from skeye.geo import GeoOrigin
from skeye.sim.frames import euler_to_quat, quat_to_rows, wrap_2pi
from skeye.sim.state import BodyState, Mat3, mat_mul, mat_t_vec, mat_vec, transpose
from skeye.wire.sim_format import Layout

Vec3 = tuple[float, float, float]
Fields = list[tuple[str, object]]

DEFAULT_RATES_HZ: Final[dict[str, float]] = {
    "groundtruth": 50.0,
    "ins": 50.0,
    "accelerometer": 100.0,
    "gyro": 100.0,
    "magneticcompass": 20.0,
    "barometer": 20.0,
    "gps": 5.0,
    "sonar": 15.0,
    "opticalflow": 50.0,
    "battery": 1.0,
}
"""Default sample rate of each sensor type, keyed by lower-case protocol Type."""


class WorldQuery(Protocol):
    """What sensors may ask of the world (the engine implements it)."""

    @property
    def geo_origin(self) -> GeoOrigin | None:
        """Geodetic position of the NED origin; None where there is no GPS (indoors)."""

    @property
    def magnetic_field_ned_ut(self) -> np.ndarray:
        """Earth's magnetic field in the world frame, microtesla, shape (3,)."""

    @property
    def sea_level_pressure_pa(self) -> float:
        """ISA sea-level reference pressure of the day, Pa."""

    def ray_distance(
        self, origin_ned_m: Vec3, direction_ned: Vec3, max_range_m: float
    ) -> float | None:
        """Distance to the first hit along a unit ray, excluding the vehicle; None if none."""

    def ray_distances(
        self, origin_ned_m: Vec3, directions_ned: Sequence[Vec3], max_range_m: float
    ) -> list[float | None]:
        """:meth:`ray_distance` for several unit rays from one point (one call, cheaper)."""

    def ray_surface(
        self, origin_ned_m: Vec3, direction_ned: Vec3, max_range_m: float
    ) -> tuple[float | None, float]:
        """:meth:`ray_distance` and the RMS texture contrast of the surface hit (0 if none)."""


@dataclass(frozen=True)
class Mount:
    """A sensor's pose on the body: position (m, body FRD) and direction (roll, pitch, yaw rad)."""

    pos_frd_m: Vec3 = (0.0, 0.0, 0.0)
    rpy_rad: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Param:
    """One configurable parameter: its CONF key, default, lower bound and meaning."""

    key: str
    default: float
    doc: str
    minimum: float = 0.0
    exclusive: bool = False  # the value must be > minimum (else >= minimum)
    maximum: float = math.inf
    integer: bool = False


@dataclass
class Reading:
    """Base of the typed readings kept in ``Sensor.last``.

    A subclass takes its SEN fields from the protocol's codec table, as a module-level
    ``Layout`` constant (keys and slots, :func:`skeye.wire.sim.sen_layout`) that :meth:`layout`
    returns (the same object each time: the server caches its compiled line format by it), and
    returns their
    values flat from :meth:`values`; :meth:`fields` derives the ``(key, value)`` pairs from
    the two, so the engine's precompiled line and the generic fields can never disagree.
    Subclasses write their ``__init__`` out (one is made per sample: mypyc compiles a written
    one, while a dataclass's generated one stays interpreted). Nothing changes a reading.
    """

    time_s: float

    def layout(self) -> Layout:
        """The keys and slots of this reading's SEN fields (after Time, Type and Name)."""
        raise NotImplementedError

    def values(self) -> tuple[object, ...]:
        """The field values, flat, in layout order."""
        raise NotImplementedError

    def fields(self) -> Fields:
        """The SEN fields after Time, Type and Name, in the protocol's keys and units."""
        flat = self.values()
        out: Fields = []
        i = 0
        for key, slot in self.layout():
            if slot.count == 1:
                out.append((key, flat[i]))
            else:
                out.append((key, tuple(flat[i : i + slot.count])))
            i += slot.count
        return out


R = TypeVar("R", bound=Reading)


def vec3(a: np.ndarray | tuple[float, ...] | list[float]) -> Vec3:
    """A length-3 sequence as a tuple of Python floats (what the SEN formatter expects)."""
    x, y, z = (float(v) for v in a)
    return (x, y, z)


def rpy_matrix(rpy_rad: Vec3) -> Mat3:
    """Rotation matrix (child frame -> parent frame) of a roll, pitch, yaw triple (ZYX)."""
    return quat_to_rows(euler_to_quat(*rpy_rad).tolist())


def _norm_key(key: str) -> str:
    return key.replace("_", "").lower()


_ALIASES: Final[dict[str, str]] = {"ratehz": "rate"}
"""Parameter keys (normalised) that name another: ``rate_hz`` is ``Rate``."""


def param_error(name: str, type_name: str, key: str, text: str) -> ConfigError:
    """The error of a bad sensor parameter, naming the sensor and the key."""
    return ConfigError(f"sensor {name!r} ({type_name}): {key} {text}")


def parse_params(
    name: str, type_name: str, specs: Sequence[Param], given: Mapping[str, object]
) -> dict[str, float]:
    """The parameters of sensor ``name`` of Type ``type_name`` from a robot file's mapping:
    each :class:`Param` of ``specs`` at its default unless given. Keys match case-insensitively
    and ignoring underscores; every unknown key, non-number, non-finite or out-of-range value
    raises ConfigError naming the sensor, the key and the value."""
    by_key = {_norm_key(p.key): p for p in specs}
    values: dict[str, float] = {p.key: p.default for p in by_key.values()}
    seen: dict[str, str] = {}
    for raw_key, value in given.items():
        if not isinstance(raw_key, str):
            raise param_error(name, type_name, repr(raw_key), "is not a parameter name")
        norm = _ALIASES.get(_norm_key(raw_key), _norm_key(raw_key))
        spec = by_key.get(norm)
        if spec is None:
            known = ", ".join(p.key for p in by_key.values())
            raise param_error(
                name, type_name, raw_key, f"is not a parameter of {type_name}; known: {known}"
            )
        if norm in seen:
            raise param_error(name, type_name, raw_key, f"is given twice (also as {seen[norm]!r})")
        seen[norm] = raw_key
        values[spec.key] = _coerce(name, type_name, spec, value)
    return values


def _coerce(name: str, type_name: str, spec: Param, value: object) -> float:
    def error(text: str) -> ConfigError:
        return param_error(name, type_name, spec.key, text)

    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise error(f"must be a number, got {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise error(f"must be finite, got {value!r}")
    if spec.integer:
        if not number.is_integer():
            raise error(f"must be an integer, got {value!r}")
        number = float(int(number))
    if spec.exclusive and not number > spec.minimum:
        raise error(f"must be > {spec.minimum:g}, got {value!r}")
    if not spec.exclusive and not number >= spec.minimum:
        raise error(f"must be >= {spec.minimum:g}, got {value!r}")
    if not number <= spec.maximum:
        raise error(f"must be <= {spec.maximum:g}, got {value!r}")
    return number


class Sensor(Generic[R]):
    """Base of all simulated sensors.

    Subclasses set ``type_name`` (the protocol Type) and ``PARAMS``, and implement ``_read``;
    they may override ``_check`` (cross-parameter checks) and ``_setup`` (draw constant biases).
    """

    type_name: ClassVar[str] = ""
    PARAMS: ClassVar[tuple[Param, ...]] = ()

    def __init__(
        self, name: str, mount: Mount, params: Mapping[str, object], rng: np.random.Generator
    ) -> None:
        self.name = name
        self.mount = mount
        self.rng = rng
        for label, vec in (("Position", mount.pos_frd_m), ("Direction", mount.rpy_rad)):
            if not (
                isinstance(vec, tuple | list)
                and len(vec) == 3
                and all(isinstance(v, int | float) and math.isfinite(v) for v in vec)
            ):
                raise self._error(label, f"must be 3 finite numbers, got {vec!r}")
        self.normals = NormalStream(rng)  # nothing drawn until a sensor takes from it
        self.params: dict[str, float] = self._parse(params)
        self.rate_hz: float = float(self.params["Rate"])
        self._rot_mount = rpy_matrix(vec3(mount.rpy_rad))  # sensor -> body
        self._rot_mount_t = transpose(self._rot_mount)
        self._mount_is_identity = self._rot_mount == rpy_matrix((0.0, 0.0, 0.0))
        self._pos_mount = vec3(mount.pos_frd_m)
        self._last_time_s: float | None = None
        self.last: R | None = None
        self._check()
        self._setup()

    # --- configuration -------------------------------------------------------------------

    @classmethod
    def all_params(cls) -> tuple[Param, ...]:
        """The rate followed by the class's own parameters."""
        rate = Param(
            "Rate", DEFAULT_RATES_HZ[cls.type_name.lower()], "sample rate, Hz", exclusive=True
        )
        return (rate, *cls.PARAMS)

    def _error(self, key: str, text: str) -> ConfigError:
        return param_error(self.name, self.type_name, key, text)

    def _parse(self, given: Mapping[str, object]) -> dict[str, float]:
        return parse_params(self.name, self.type_name, self.all_params(), given)

    def _check(self) -> None:
        """Cross-parameter checks (e.g. MinRange < MaxRange); raise ``self._error``."""

    def _setup(self) -> None:
        """Draw constant biases and set up state; runs after validation."""

    def conf_fields(self) -> Fields:
        """Fields of ``CONF {Type X} {Name n} ...``: rate, ranges and noise parameters."""
        return [(p.key, self.params[p.key]) for p in self.all_params()]

    def geo_fields(self) -> Fields:
        """Fields of ``GEO {Type X} {Name n} ...``: the mount pose (orientation in [0, 2 pi))."""
        rpy = vec3(self.mount.rpy_rad)
        return [
            ("Location", vec3(self.mount.pos_frd_m)),
            ("Orientation", (wrap_2pi(rpy[0]), wrap_2pi(rpy[1]), wrap_2pi(rpy[2]))),
        ]

    # --- sampling --------------------------------------------------------------------------

    def sample(self, state: BodyState, world: WorldQuery) -> Fields:
        """One reading from ground truth; returns the SEN fields after Time, Type and Name."""
        return self.read(state, world).fields()

    def read(self, state: BodyState, world: WorldQuery) -> R:
        """One reading from ground truth, kept in ``last`` (the engine's hot path)."""
        last = self._last_time_s
        t = state.time_s
        dt_s = t - last if last is not None and t > last else 0.0
        self._last_time_s = t
        reading = self._read(state, world, dt_s)
        self.last = reading
        return reading

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> R:
        """Compute one reading; ``dt_s`` is sim time since the previous reading (0 at first)."""
        raise NotImplementedError

    # --- geometry helpers (plain floats: these run for every sample) ------------------------

    def _rot_sensor_to_ned(self, state: BodyState) -> Mat3:
        if self._mount_is_identity:
            return state.rot_body_to_ned
        return mat_mul(state.rot_body_to_ned, self._rot_mount)

    def _pos_ned_m(self, state: BodyState) -> Vec3:
        """Where the sensor is in the world (body position + rotated mount offset)."""
        px, py, pz = state.pos_ned_m
        ox, oy, oz = mat_vec(state.rot_body_to_ned, self._pos_mount)
        return (px + ox, py + oy, pz + oz)

    def _body_to_sensor(self, v_frd: Vec3) -> Vec3:
        if self._mount_is_identity:
            return v_frd
        return mat_t_vec(self._rot_mount, v_frd)


_NOISE_BLOCK: Final = 256  # corrupt() calls per block of pre-drawn normal deviates
_STREAM_BLOCK: Final = 4096  # normal deviates a NormalStream draws at a time (at least)


class NormalStream:
    """A Generator's standard normal deviates, drawn ahead in blocks, handed out in order.

    ``take(k)`` returns the next ``k`` deviates: the same numbers, in the same order, as
    ``rng.standard_normal(k)`` called at that moment would give. numpy's Generator draws each
    normal deviate on its own from its bit stream (ziggurat), so one draw of N is the same as
    any sequence of draws adding up to N; one numpy call then serves hundreds of requests (a
    call costs about as much as 100 deviates). Nothing is drawn before the first request, so a
    sensor may still draw its constants from the Generator while it is set up; after that,
    everything it draws from that Generator must come through the stream (which is ahead of
    the Generator), and nothing but normal deviates.
    """

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self._buffer: list[float] = []
        self._next = 0

    def take(self, k: int) -> list[float]:
        """The next ``k`` standard normal deviates."""
        i = self._next
        buffer = self._buffer
        if i + k <= len(buffer):
            self._next = i + k
            return buffer[i : i + k]
        out = buffer[i:]
        need = k - len(out)
        buffer = self._buffer = self.rng.standard_normal(max(_STREAM_BLOCK, need)).tolist()
        out.extend(buffer[:need])
        self._next = need
        return out


class BiasedNoise:
    """White noise + a constant bias (drawn once) + a bias random walk, on n channels.

    ``corrupt(x, dt)`` first advances the bias by ``walk * sqrt(dt) * N(0, 1)`` per channel
    (a Wiener process in sim time, so its statistics do not depend on the sample rate), then
    returns ``x + bias + sigma * N(0, 1)``. The constant bias is drawn from the Generator when
    this is made; the rest in blocks (2n per call: walk, then noise) of 256 calls from
    ``normals`` (the Generator's :class:`NormalStream`, shared with the sensor's other draws),
    so the sequence depends only on the seed and the number of calls.
    """

    def __init__(
        self,
        rng: np.random.Generator,
        n: int,
        noise_sigma: float,
        bias_sigma: float,
        bias_walk: float,
        normals: NormalStream | None = None,
    ) -> None:
        self.rng = rng
        self.normals = normals if normals is not None else NormalStream(rng)
        self.n = n
        self.noise_sigma = noise_sigma
        self.bias_walk = bias_walk
        self._bias: list[float] = (rng.standard_normal(n) * bias_sigma).tolist()
        self._rows: list[list[float]] = []
        self._row_i = 0

    @property
    def bias(self) -> np.ndarray:
        """The current bias, one value per channel."""
        return np.array(self._bias)

    def _next_row(self) -> list[float]:
        i = self._row_i
        if i >= len(self._rows):
            width = 2 * self.n
            flat = self.normals.take(_NOISE_BLOCK * width)  # rows as numpy's (256, 2n) block
            self._rows = [flat[j * width : (j + 1) * width] for j in range(_NOISE_BLOCK)]
            i = 0
        self._row_i = i + 1
        return self._rows[i]

    def corrupt(self, value: Sequence[float], dt_s: float) -> list[float]:
        """The noisy measurement of ``value`` (n floats) after ``dt_s`` of sim time."""
        n = self.n
        row = self._next_row()
        bias = self._bias
        if self.bias_walk > 0.0 and dt_s > 0.0:
            k = self.bias_walk * math.sqrt(dt_s)
            for i in range(n):
                bias[i] = bias[i] + k * row[i]  # not +=: generic in mypyc on list items
        sigma = self.noise_sigma
        return [value[i] + bias[i] + sigma * row[n + i] for i in range(n)]

    def corrupt3(self, x: float, y: float, z: float, dt_s: float) -> Vec3:
        """:meth:`corrupt` for three channels, written out (the IMU's hot path)."""
        row = self._next_row()
        b = self._bias
        if self.bias_walk > 0.0 and dt_s > 0.0:
            k = self.bias_walk * math.sqrt(dt_s)
            b[0] = b[0] + k * row[0]  # not +=: generic in mypyc on list items
            b[1] = b[1] + k * row[1]
            b[2] = b[2] + k * row[2]
        s = self.noise_sigma
        return (x + b[0] + s * row[3], y + b[1] + s * row[4], z + b[2] + s * row[5])
