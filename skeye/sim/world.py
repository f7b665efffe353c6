"""Worlds: a small declarative description (TOML) and the builder that turns it into MuJoCo MJCF.

How this works: a world file names a ground, landing pads, boxes (buildings, debris, walls,
ceilings), lights, USARSim start poses and the world's geodetic and magnetic facts, all in the
protocol's NED frame (x north, y east, z down, metres; yaw in rad about down). :func:`load_world`
validates every key (unknown keys included) and raises ConfigError naming the file, the table and
the problem; nothing is half-loaded. :func:`build_mjcf` writes the MuJoCo model, which is NWU
(x north, y west, z up): every position and orientation crosses over through
:mod:`skeye.sim.frames` and nowhere else. Textures (the pad, procedural ground) are generated
deterministically and handed back as an assets dict for ``MjModel.from_xml_string``.

Invariants: a pad's visible surface lies ``PAD_SURFACE_HEIGHT_M`` above the point the file gives
(so it never z-fights the ground) and a hidden collider's top face lies in the same plane, so a
vehicle standing on the pad and a camera measuring height above it agree; the pad texture covers
the pad's square exactly once.
"""

from __future__ import annotations

import functools
import math
import re
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, NoReturn
from xml.sax.saxutils import quoteattr

import cv2
import numpy as np

from skeye.errors import ConfigError
from skeye.geo import GeoOrigin
from skeye.sim.frames import euler_to_quat, ned_to_mj, quat_ned_to_mj
from skeye.vision.pad import PadDefinition, get_pad, render_pad

BUILTIN_WORLDS = ("pad", "yard", "indoor")
GROUND_TEXTURES = ("grass", "checker", "concrete", "none")

# The pad's visible plane sits this far above the ground point the file gives (NED: more negative).
PAD_SURFACE_HEIGHT_M = 0.001
PAD_TEXTURE_PX = 2048
# Chemnitz, Germany (WMM, about 2025): north, east, down in microtesla.
DEFAULT_MAGNETIC_FIELD_NED_UT = (20.0, 1.5, 44.0)
DEFAULT_SEA_LEVEL_PRESSURE_PA = 101325.0
# Absolute clipping distances of every rendered camera: a landed vehicle's camera sits a few
# centimetres above the pad, and 1 cm keeps the 1 mm pad layer resolved in depth far away.
NEAR_CLIP_M = 0.01
GRAVITY_M_S2 = 9.81

_NAME_RE = re.compile(r"^[A-Za-z0-9_.\-]+$")  # safe inside protocol segments and MJCF names
Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Ground:
    """A flat ground plane at down = 0 (collision is infinite; rendering covers the square)."""

    size_m: float  # half-extent of the rendered square
    texture: str  # one of GROUND_TEXTURES
    rgb: Vec3
    rgb2: Vec3  # second colour: checker squares, grass/concrete variation
    texture_cell_m: float  # size of one texture tile (one checker square)


@dataclass(frozen=True)
class PadPlacement:
    """A landing pad lying on a surface; ``position_ned_m`` is its centre on that surface."""

    name: str
    pad: PadDefinition
    position_ned_m: Vec3
    yaw_rad: float

    @property
    def surface_down_m(self) -> float:
        """NED down of the visible pad plane; a camera's height above the pad is this - its down."""
        return self.position_ned_m[2] - PAD_SURFACE_HEIGHT_M


@dataclass(frozen=True)
class Box:
    """A collidable box: a building, debris, a wall or a ceiling."""

    name: str
    center_ned_m: Vec3
    size_m: Vec3  # full extents along the box's own north, east, down axes at yaw 0
    yaw_rad: float
    rgb: Vec3


@dataclass(frozen=True)
class Light:
    """A directional light (no position, like the sun) or a spot light at ``position_ned_m``."""

    name: str
    direction_ned: Vec3
    position_ned_m: Vec3 | None
    diffuse: Vec3
    ambient: Vec3
    specular: Vec3
    cutoff_rad: float  # spot lights only: half-angle of the cone


@dataclass(frozen=True)
class Visual:
    """Rendering choices; defaults are fast (no shadows, no reflections, no haze or fog)."""

    headlight_ambient: Vec3 = (0.35, 0.35, 0.35)
    headlight_diffuse: Vec3 = (0.55, 0.55, 0.55)
    shadows: bool = False
    reflectance: float = 0.0
    skybox: bool = True
    sky_rgb: Vec3 = (0.45, 0.65, 0.90)
    horizon_rgb: Vec3 = (0.85, 0.90, 0.95)


@dataclass(frozen=True)
class StartPose:
    """Where a vehicle may be spawned: the ground/pad point its landing gear stands on."""

    position_ned_m: Vec3
    rpy_rad: Vec3


@dataclass(frozen=True)
class WorldDescription:
    """A validated world. ``start_poses`` keeps the file's order."""

    name: str
    geo_origin: GeoOrigin | None  # None: no GPS (indoors)
    magnetic_field_ned_ut: Vec3
    sea_level_pressure_pa: float
    ground: Ground
    pads: tuple[PadPlacement, ...]
    boxes: tuple[Box, ...]
    lights: tuple[Light, ...]
    visual: Visual
    start_poses: dict[str, StartPose]
    source: str


# ----------------------------------------------------------------------------------------------
# Validation


_REQUIRED = object()


class _Table:
    """One TOML table being read; every error names the file and where in it."""

    def __init__(self, source: str, where: str, data: Any) -> None:
        self.source = source
        self.where = where
        if not isinstance(data, dict):
            self.fail(f"must be a table, got {type(data).__name__}")
        self.data: dict[str, Any] = data

    def fail(self, problem: str, key: str | None = None) -> NoReturn:
        at = self.where if key is None else (f"{self.where}.{key}" if self.where else key)
        raise ConfigError(f"{self.source}: {at or 'top level'}: {problem}")

    def check_keys(self, allowed: set[str]) -> None:
        unknown = sorted(set(self.data) - allowed)
        if unknown:
            self.fail(f"unknown key(s) {unknown}; known keys: {sorted(allowed)}")

    def _get(self, key: str, default: Any) -> Any:
        if key in self.data:
            return self.data[key]
        if default is _REQUIRED:
            self.fail("missing required key", key)
        return default

    def number(
        self,
        key: str,
        default: Any = _REQUIRED,
        check: Callable[[float], bool] | None = None,
        rule: str = "",
    ) -> float:
        value = self._get(key, default)
        if not _is_number(value) or not math.isfinite(value):
            self.fail(f"must be a finite number, got {value!r}", key)
        if check is not None and not check(float(value)):
            self.fail(f"must be {rule}, got {value!r}", key)
        return float(value)

    def vector(
        self,
        key: str,
        default: Any = _REQUIRED,
        check: Callable[[float], bool] | None = None,
        rule: str = "",
    ) -> Vec3:
        value = self._get(key, default)
        if isinstance(value, tuple):
            value = list(value)
        if (
            not isinstance(value, list)
            or len(value) != 3
            or not all(_is_number(v) and math.isfinite(v) for v in value)
        ):
            self.fail(f"must be a list of 3 finite numbers, got {value!r}", key)
        if check is not None and not all(check(float(v)) for v in value):
            self.fail(f"must be 3 numbers that are {rule}, got {value!r}", key)
        return (float(value[0]), float(value[1]), float(value[2]))

    def rgb(self, key: str, default: Any = _REQUIRED) -> Vec3:
        return self.vector(key, default, lambda v: 0.0 <= v <= 1.0, "between 0 and 1")

    def boolean(self, key: str, default: Any = _REQUIRED) -> bool:
        value = self._get(key, default)
        if not isinstance(value, bool):
            self.fail(f"must be true or false, got {value!r}", key)
        return bool(value)

    def name(self, key: str, default: Any = _REQUIRED) -> str:
        value = self._get(key, default)
        if not isinstance(value, str) or not _NAME_RE.match(value):
            self.fail(
                "must be a non-empty string of letters, digits, '_', '.' or '-', "
                f"got {value!r}",
                key,
            )
        return str(value)

    def choice(self, key: str, choices: tuple[str, ...], default: Any = _REQUIRED) -> str:
        value = self._get(key, default)
        if value not in choices:
            self.fail(f"must be one of {list(choices)}, got {value!r}", key)
        return str(value)

    def table(self, key: str) -> _Table | None:
        if key not in self.data:
            return None
        return _Table(self.source, f"[{key}]", self.data[key])

    def array_of_tables(self, key: str) -> list[_Table]:
        value = self.data.get(key, [])
        if not isinstance(value, list):
            self.fail(f"must be an array of tables ([[{key}]]), got {type(value).__name__}", key)
        return [_Table(self.source, f"[[{key}]] #{i}", item) for i, item in enumerate(value, 1)]


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _positive(v: float) -> bool:
    return v > 0.0


_TOP_KEYS = {
    "name", "geo_origin", "magnetic_field", "sea_level_pressure_pa", "ground", "pads", "boxes",
    "lights", "visual", "start_poses",
}
_GROUND_DEFAULTS: dict[str, tuple[Vec3, Vec3, float]] = {
    "grass": ((0.22, 0.42, 0.13), (0.36, 0.50, 0.20), 4.0),
    "checker": ((0.30, 0.30, 0.30), (0.55, 0.55, 0.55), 1.0),
    "concrete": ((0.52, 0.52, 0.50), (0.62, 0.61, 0.58), 2.0),
    "none": ((0.40, 0.45, 0.35), (0.40, 0.45, 0.35), 1.0),
}


def parse_world(data: dict[str, Any], source: str) -> WorldDescription:
    """Validate a parsed TOML document; ``source`` names the file in error messages."""
    top = _Table(source, "", data)
    top.check_keys(_TOP_KEYS)
    name = top.name("name")
    pressure = top.number(
        "sea_level_pressure_pa", DEFAULT_SEA_LEVEL_PRESSURE_PA,
        lambda v: 30000.0 <= v <= 120000.0, "between 30000 and 120000 Pa",
    )
    geo = _parse_geo_origin(top.table("geo_origin"))
    field = DEFAULT_MAGNETIC_FIELD_NED_UT
    mag = top.table("magnetic_field")
    if mag is not None:
        mag.check_keys({"ned_ut"})
        field = mag.vector("ned_ut")
        strength = math.hypot(*field)
        if not 0.0 < strength <= 100.0:
            mag.fail(f"field strength must be in (0, 100] uT, got {strength:.3g}", "ned_ut")
    ground = _parse_ground(top.table("ground") or _Table(source, "[ground]", {}))
    visual = _parse_visual(top.table("visual"))

    pads: list[PadPlacement] = []
    for i, table in enumerate(top.array_of_tables("pads"), 1):
        pads.append(_parse_pad(table, i))
        _check_on_ground(table, "position_ned_m", pads[-1].position_ned_m, ground)
    boxes = tuple(_parse_box(t) for t in top.array_of_tables("boxes"))
    lights = tuple(_parse_light(t, i) for i, t in enumerate(top.array_of_tables("lights"), 1))
    _check_unique(top, "pads", [p.name for p in pads])
    _check_unique(top, "boxes", [b.name for b in boxes])
    _check_unique(top, "lights", [light.name for light in lights])
    start_poses: dict[str, StartPose] = {}
    for table in top.array_of_tables("start_poses"):
        pose_name, pose = _parse_start_pose(table)
        if pose_name in start_poses:
            table.fail(f"duplicate start pose name {pose_name!r}", "name")
        _check_on_ground(table, "position_ned_m", pose.position_ned_m, ground)
        start_poses[pose_name] = pose

    return WorldDescription(
        name=name,
        geo_origin=geo,
        magnetic_field_ned_ut=field,
        sea_level_pressure_pa=pressure,
        ground=ground,
        pads=tuple(pads),
        boxes=boxes,
        lights=lights,
        visual=visual,
        start_poses=start_poses,
        source=source,
    )


def _parse_geo_origin(table: _Table | None) -> GeoOrigin | None:
    if table is None:
        return None
    table.check_keys({"gps", "latitude_deg", "longitude_deg", "altitude_m"})
    gps = table.boolean("gps", True)
    if not gps:
        # GPS switched off: any coordinates still present must be valid numbers, but are unused.
        for key in ("latitude_deg", "longitude_deg", "altitude_m"):
            if key in table.data:
                table.number(key)
        return None
    lat = table.number("latitude_deg", check=lambda v: -90.0 < v < 90.0, rule="in (-90, 90)")
    lon = table.number(
        "longitude_deg", check=lambda v: -180.0 <= v <= 180.0, rule="in [-180, 180]"
    )
    alt = table.number("altitude_m", 0.0)
    return GeoOrigin(latitude_deg=lat, longitude_deg=lon, altitude_m=alt)


def _parse_ground(table: _Table) -> Ground:
    table.check_keys({"size_m", "texture", "rgb", "rgb2", "texture_cell_m"})
    size = table.number("size_m", 50.0, _positive, "positive")
    texture = table.choice("texture", GROUND_TEXTURES, "grass")
    rgb_default, rgb2_default, cell_default = _GROUND_DEFAULTS[texture]
    return Ground(
        size_m=size,
        texture=texture,
        rgb=table.rgb("rgb", rgb_default),
        rgb2=table.rgb("rgb2", rgb2_default),
        texture_cell_m=table.number("texture_cell_m", cell_default, _positive, "positive"),
    )


def _parse_visual(table: _Table | None) -> Visual:
    if table is None:
        return Visual()
    table.check_keys({
        "headlight_ambient", "headlight_diffuse", "shadows", "reflectance", "skybox", "sky_rgb",
        "horizon_rgb",
    })
    d = Visual()
    return Visual(
        headlight_ambient=table.rgb("headlight_ambient", d.headlight_ambient),
        headlight_diffuse=table.rgb("headlight_diffuse", d.headlight_diffuse),
        shadows=table.boolean("shadows", d.shadows),
        reflectance=table.number(
            "reflectance", d.reflectance, lambda v: 0.0 <= v <= 1.0, "between 0 and 1"
        ),
        skybox=table.boolean("skybox", d.skybox),
        sky_rgb=table.rgb("sky_rgb", d.sky_rgb),
        horizon_rgb=table.rgb("horizon_rgb", d.horizon_rgb),
    )


def _parse_pad(table: _Table, index: int) -> PadPlacement:
    table.check_keys({"name", "pad", "position_ned_m", "yaw_rad"})
    pad_name = table._get("pad", "skeye-4")
    if not isinstance(pad_name, str):
        table.fail(f"must be a pad name (string), got {pad_name!r}", "pad")
    try:
        pad = get_pad(pad_name)
    except KeyError as exc:
        table.fail(str(exc.args[0]), "pad")
    return PadPlacement(
        name=table.name("name", f"pad{index}"),
        pad=pad,
        position_ned_m=table.vector("position_ned_m"),
        yaw_rad=table.number("yaw_rad", 0.0),
    )


def _parse_box(table: _Table) -> Box:
    table.check_keys({"name", "center_ned_m", "size_m", "yaw_rad", "rgb"})
    return Box(
        name=table.name("name"),
        center_ned_m=table.vector("center_ned_m"),
        size_m=table.vector("size_m", check=_positive, rule="positive"),
        yaw_rad=table.number("yaw_rad", 0.0),
        rgb=table.rgb("rgb", (0.6, 0.6, 0.6)),
    )


def _parse_light(table: _Table, index: int) -> Light:
    table.check_keys({
        "name", "direction_ned", "position_ned_m", "diffuse", "ambient", "specular", "cutoff_rad",
    })
    direction = table.vector("direction_ned", (0.0, 0.0, 1.0))
    if math.hypot(*direction) < 1e-9:
        table.fail("must not be the zero vector", "direction_ned")
    position = table.vector("position_ned_m") if "position_ned_m" in table.data else None
    return Light(
        name=table.name("name", f"light{index}"),
        direction_ned=direction,
        position_ned_m=position,
        diffuse=table.rgb("diffuse", (0.5, 0.5, 0.5)),
        ambient=table.rgb("ambient", (0.0, 0.0, 0.0)),
        specular=table.rgb("specular", (0.0, 0.0, 0.0)),
        cutoff_rad=table.number(
            "cutoff_rad", 1.2, lambda v: 0.0 < v < math.pi / 2, "in (0, pi/2)"
        ),
    )


def _parse_start_pose(table: _Table) -> tuple[str, StartPose]:
    table.check_keys({"name", "position_ned_m", "rpy_rad"})
    return table.name("name"), StartPose(
        position_ned_m=table.vector("position_ned_m"),
        rpy_rad=table.vector("rpy_rad", (0.0, 0.0, 0.0)),
    )


def _check_unique(top: _Table, key: str, names: list[str]) -> None:
    seen: set[str] = set()
    for name in names:
        if name in seen:
            top.fail(f"duplicate name {name!r}", f"[[{key}]].name")
        seen.add(name)


def _check_on_ground(table: _Table, key: str, position: Vec3, ground: Ground) -> None:
    if max(abs(position[0]), abs(position[1])) > ground.size_m:
        table.fail(
            f"north/east {position[:2]} lies outside the ground (half-extent {ground.size_m} m)",
            key,
        )


def load_world(name_or_path: str | Path) -> WorldDescription:
    """A built-in world by name (see BUILTIN_WORLDS) or a world file by path."""
    text_name = str(name_or_path)
    if isinstance(name_or_path, str) and text_name in BUILTIN_WORLDS:
        resource = resources.files("skeye.sim").joinpath("worlds", f"{text_name}.toml")
        return _load_text(resource.read_text(encoding="utf-8"), str(resource))
    path = Path(name_or_path)
    if not path.is_file():
        if path.suffix == "" and len(path.parts) == 1:  # looks like a name, not a path
            raise ConfigError(
                f"unknown world {text_name!r}: not a built-in world "
                f"({', '.join(BUILTIN_WORLDS)}) and no such file"
            )
        raise ConfigError(f"{path}: world file not found")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read world file: {exc}") from exc
    return _load_text(text, str(path))


def _load_text(text: str, source: str) -> WorldDescription:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: TOML syntax error: {exc}") from exc
    return parse_world(data, source)


def start_pose_list(world: WorldDescription) -> list[tuple[str, Vec3, Vec3]]:
    """(name, position NED m, roll/pitch/yaw rad) in file order, for GETSTARTPOSES."""
    return [(n, p.position_ned_m, p.rpy_rad) for n, p in world.start_poses.items()]


# ----------------------------------------------------------------------------------------------
# Textures (deterministic)


@functools.lru_cache(maxsize=8)
def pad_texture_png(pad: PadDefinition, pixels: int = PAD_TEXTURE_PX) -> bytes:
    """The pad as an RGB PNG (grey levels), rendered from the pad's data."""
    grey = render_pad(pad, pixels, supersample=2)
    return _png(np.dstack([grey, grey, grey]))


def _png(rgb: np.ndarray) -> bytes:
    ok, encoded = cv2.imencode(".png", np.ascontiguousarray(rgb[:, :, ::-1]))  # cv2 wants BGR
    if not ok:
        raise ConfigError("could not encode a texture as PNG")
    return encoded.tobytes()


def _periodic_noise(rng: np.random.Generator, n: int, scale_px: float) -> np.ndarray:
    """Tileable smooth noise (zero mean, unit std): white noise low-passed in Fourier space."""
    k = np.fft.fftfreq(n)
    kk = np.hypot(*np.meshgrid(k, k))
    spectrum = np.fft.fft2(rng.standard_normal((n, n))) * np.exp(-((kk * scale_px) ** 2) * 2.0)
    field = np.fft.ifft2(spectrum).real
    return (field - field.mean()) / (field.std() + 1e-12)


@functools.lru_cache(maxsize=8)
def ground_texture_png(texture: str, rgb: Vec3, rgb2: Vec3, pixels: int = 512) -> bytes:
    """A tileable procedural ground texture (grass or concrete), the same bytes every time."""
    rng = np.random.default_rng(20240611 + GROUND_TEXTURES.index(texture))
    if texture == "grass":
        mix = (
            0.55 * _periodic_noise(rng, pixels, 1.0)
            + 0.35 * _periodic_noise(rng, pixels, 6.0)
            + 0.45 * _periodic_noise(rng, pixels, 40.0)
        )
        t = np.clip(0.5 + 0.22 * mix, 0.0, 1.0)
    elif texture == "concrete":
        mix = 0.6 * _periodic_noise(rng, pixels, 0.7) + 0.5 * _periodic_noise(rng, pixels, 30.0)
        t = np.clip(0.5 + 0.2 * mix, 0.0, 1.0)
    else:
        raise ConfigError(f"no procedural texture for ground texture {texture!r}")
    a, b = np.array(rgb), np.array(rgb2)
    img = a[None, None, :] * (1.0 - t[..., None]) + b[None, None, :] * t[..., None]
    return _png(np.round(np.clip(img, 0.0, 1.0) * 255.0).astype(np.uint8))


# ----------------------------------------------------------------------------------------------
# MJCF


def _f(*values: float) -> str:
    return " ".join(format(float(v) + 0.0, ".10g") for v in values)  # + 0.0: no "-0"


def _el(tag: str, **attrs: Any) -> str:
    parts = [tag] + [f"{k}={quoteattr(str(v))}" for k, v in attrs.items() if v is not None]
    return "<" + " ".join(parts) + "/>"


def _pose_attrs(center_ned_m: Vec3, yaw_rad: float) -> dict[str, str]:
    return {
        "pos": _f(*ned_to_mj(center_ned_m)),
        "quat": _f(*quat_ned_to_mj(tuple(euler_to_quat(0.0, 0.0, yaw_rad)))),
    }


def build_mjcf(
    world: WorldDescription,
    robots_xml: str = "",
    robot_assets_xml: str = "",
    timestep_s: float = 0.001,
    offscreen_size: tuple[int, int] = (800, 600),
) -> tuple[str, dict[str, bytes]]:
    """The complete MJCF text and its assets (file name -> bytes).

    ``robots_xml`` goes verbatim into <worldbody>, ``robot_assets_xml`` into <asset>. The
    integrator is MuJoCo's semi-implicit ``Euler``: one dynamics evaluation per step (RK4 costs
    four, and would hold the engine's applied rotor forces fixed across its sub-steps anyway).
    ``implicitfast`` would differ from it only in velocity-dependent joint damping and actuator
    forces, which these models do not have (contacts go through the constraint solver either
    way; drag is an applied force), and costs about 20 % more per step. At 1 kHz the
    first-order error is far below the vehicle model's own uncertainty. MuJoCo's air density
    and viscosity are zero: the engine applies drag itself.
    """
    if not (math.isfinite(timestep_s) and 0.0 < timestep_s <= 0.05):
        raise ConfigError(f"build_mjcf: timestep_s must be in (0, 0.05] s, got {timestep_s!r}")
    width, height = offscreen_size
    if not (isinstance(width, int) and isinstance(height, int) and width > 0 and height > 0):
        raise ConfigError(
            f"build_mjcf: offscreen_size must be two positive ints, got {offscreen_size!r}"
        )
    assets: dict[str, bytes] = {}
    asset_xml: list[str] = []
    body_xml: list[str] = []
    vis = world.visual
    ground = world.ground
    extent_m = max(ground.size_m, 1.0)
    far_m = max(4.0 * extent_m, 200.0)

    # Ground: a plane at down = 0; its texture tiles every texture_cell_m.
    ground_attrs: dict[str, Any] = {
        "name": "ground", "type": "plane", "pos": _f(0.0, 0.0, 0.0),
        "size": _f(ground.size_m, ground.size_m, 0.5), "group": "0", "condim": "3",
    }
    repeat = 2.0 * ground.size_m / ground.texture_cell_m
    if ground.texture == "none":
        ground_attrs["rgba"] = _f(*ground.rgb, 1.0)
    else:
        if ground.texture == "checker":
            # MuJoCo's builtin checker holds 2x2 squares per tile.
            asset_xml.append(_el(
                "texture", name="ground", type="2d", builtin="checker", width="512",
                height="512", rgb1=_f(*ground.rgb), rgb2=_f(*ground.rgb2),
            ))
            repeat /= 2.0
        else:
            file_name = f"skeye_ground_{ground.texture}.png"
            assets[file_name] = ground_texture_png(ground.texture, ground.rgb, ground.rgb2)
            asset_xml.append(_el("texture", name="ground", type="2d", file=file_name))
        asset_xml.append(_el(
            "material", name="ground", texture="ground", texrepeat=_f(repeat, repeat),
            texuniform="false", specular="0", shininess="0", reflectance=_f(vis.reflectance),
        ))
        ground_attrs["material"] = "ground"
    if vis.skybox:
        asset_xml.append(_el(
            "texture", name="sky", type="skybox", builtin="gradient", width="128",
            height="768", rgb1=_f(*vis.sky_rgb), rgb2=_f(*vis.horizon_rgb),
        ))
    body_xml.append(_el("geom", **ground_attrs))

    # Pads: a textured plane (visual only) exactly PAD_SURFACE_HEIGHT_M above the given point,
    # and a hidden collider box (group 3) whose top face is that same plane. With
    # texrepeat 1 1 on a plane of half-size side/2 the texture covers the square exactly once.
    for pad_def in sorted({p.pad for p in world.pads}, key=lambda p: p.name):
        file_name = f"skeye_pad_{pad_def.name}.png"
        assets[file_name] = pad_texture_png(pad_def)
        asset_xml.append(_el("texture", name=f"pad:{pad_def.name}", type="2d", file=file_name))
        asset_xml.append(_el(
            "material", name=f"pad:{pad_def.name}", texture=f"pad:{pad_def.name}",
            texrepeat="1 1", texuniform="false", specular="0", shininess="0", reflectance="0",
            emission="0",
        ))
    for pad in world.pads:
        half = pad.pad.side_m / 2.0
        n, e, _ = pad.position_ned_m
        surface = (n, e, pad.surface_down_m)
        body_xml.append(_el(
            "geom", name=f"pad:{pad.name}", type="plane", size=_f(half, half, half / 6.0),
            material=f"pad:{pad.pad.name}", contype="0", conaffinity="0", group="1",
            **_pose_attrs(surface, pad.yaw_rad),
        ))
        collider_half_m = 0.01
        body_xml.append(_el(
            "geom", name=f"pad:{pad.name}:collider", type="box",
            size=_f(half, half, collider_half_m), group="3", rgba="0.1 0.1 0.1 1",
            **_pose_attrs((n, e, surface[2] + collider_half_m), pad.yaw_rad),
        ))

    for box in world.boxes:
        body_xml.append(_el(
            "geom", name=f"box:{box.name}", type="box", size=_f(*(s / 2.0 for s in box.size_m)),
            rgba=_f(*box.rgb, 1.0), group="0", **_pose_attrs(box.center_ned_m, box.yaw_rad),
        ))

    light_xml: list[str] = []
    for light in world.lights:
        direction = ned_to_mj(light.direction_ned)
        common: dict[str, Any] = {
            "name": f"light:{light.name}", "dir": _f(*(direction / np.linalg.norm(direction))),
            "diffuse": _f(*light.diffuse), "ambient": _f(*light.ambient),
            "specular": _f(*light.specular), "castshadow": str(vis.shadows).lower(),
        }
        if light.position_ned_m is None:
            light_xml.append(_el("light", type="directional", pos=_f(0.0, 0.0, 10.0), **common))
        else:
            light_xml.append(_el(
                "light", type="spot", pos=_f(*ned_to_mj(light.position_ned_m)),
                cutoff=_f(math.degrees(light.cutoff_rad)), exponent="1", **common,
            ))

    visual_xml = "\n".join([
        "  <visual>",
        "    " + _el("global", offwidth=str(width), offheight=str(height)),
        "    " + _el("quality", shadowsize="4096" if vis.shadows else "0"),
        "    " + _el(
            "headlight", active="1", ambient=_f(*vis.headlight_ambient),
            diffuse=_f(*vis.headlight_diffuse), specular="0 0 0",
        ),
        # znear/zfar are fractions of the model extent; haze off.
        "    " + _el(
            "map", znear=_f(NEAR_CLIP_M / extent_m), zfar=_f(far_m / extent_m), haze="0",
        ),
        "    " + _el("rgba", haze="0 0 0 0"),
        "  </visual>",
    ])
    xml = "\n".join([
        f"<mujoco model={quoteattr('skeye-' + world.name)}>",
        "  " + _el("compiler", angle="radian", autolimits="true"),
        "  " + _el(
            "option", timestep=_f(timestep_s), gravity=_f(*ned_to_mj((0.0, 0.0, GRAVITY_M_S2))),
            integrator="Euler", density="0", viscosity="0", wind="0 0 0",
        ),
        "  " + _el("statistic", extent=_f(extent_m), center="0 0 0"),
        visual_xml,
        "  <asset>",
        *("    " + line for line in asset_xml),
        robot_assets_xml,
        "  </asset>",
        "  <worldbody>",
        *("    " + line for line in light_xml + body_xml),
        robots_xml,
        "  </worldbody>",
        "</mujoco>",
        "",
    ])
    return xml, assets
