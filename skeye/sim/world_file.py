"""World files: the TOML validator that turns a world file into a :class:`WorldDescription`.

How this works: :func:`load_world` reads a built-in world (``skeye/sim/worlds/``) or a file and
:func:`parse_world` validates every key (unknown keys included), raising ConfigError naming the
file, the table and the problem; nothing is half-loaded. The description's types and constants
are in :mod:`skeye.sim.world_model`.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any, Final, NoReturn

from skeye.errors import ConfigError
from skeye.geo import LOWEST_LAND_AMSL_M, GeoOrigin
from skeye.sim.world_model import (
    BUILTIN_WORLDS,
    DEFAULT_MAGNETIC_FIELD_NED_UT,
    DEFAULT_SEA_LEVEL_PRESSURE_PA,
    GROUND_TEXTURES,
    NAME_RE,
    Box,
    CheckerboardPlacement,
    Ground,
    Light,
    PadPlacement,
    StartPose,
    Vec3,
    Visual,
    WorldDescription,
)
from skeye.values import is_finite_number
from skeye.vision.pad import get_pad
from skeye.wire.sim import MAX_LOCATION_M

# ----------------------------------------------------------------------------------------------
# Validation


_REQUIRED = object()

# The barometer (skeye/sim/sensors/inertial.py, isa_pressure_pa) uses the ISA troposphere
# formula of ISO 2533:1975 / US Standard Atmosphere 1976, which holds up to the tropopause at
# 11 000 m (above it the formula is wrong, and above ~44.3 km it has no real value). The lower
# bound is the lowest dry land, the Dead Sea shore, about 430 m below sea level.
ORIGIN_ALTITUDE_MIN_M: Final = LOWEST_LAND_AMSL_M
ORIGIN_ALTITUDE_MAX_M: Final = 11000.0
# The ground's texture tiles 2 * size_m / texture_cell_m times; MuJoCo refuses a texrepeat
# beyond float range (a 1e-300 m cell stopped skeye sim with a traceback). 1 mm, the smallest
# checkerboard square_m, is far below any useful tile and keeps the count finite.
MIN_TEXTURE_CELL_M: Final = 0.001


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
        if not is_finite_number(value):
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
            or not all(is_finite_number(v) for v in value)
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
        if not isinstance(value, str) or not NAME_RE.match(value):
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


def _positive(v: float) -> bool:
    return v > 0.0


_TOP_KEYS = {
    "name", "geo_origin", "magnetic_field", "sea_level_pressure_pa", "ground", "pads", "boxes",
    "lights", "visual", "start_poses", "checkerboards",
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

    boxes = tuple(_parse_box(t) for t in top.array_of_tables("boxes"))
    pads: list[PadPlacement] = []
    for i, table in enumerate(top.array_of_tables("pads"), 1):
        pads.append(_parse_pad(table, i))
        _check_on_ground(table, "position_ned_m", pads[-1].position_ned_m, ground, "pad")
        _check_outside_boxes(table, pads[-1].position_ned_m, boxes, f"pad {pads[-1].name!r}")
    boards = []
    for i, table in enumerate(top.array_of_tables("checkerboards"), 1):
        boards.append(_parse_checkerboard(table, i))
        _check_on_ground(table, "position_ned_m", boards[-1].position_ned_m, ground, "board")
        _check_outside_boxes(table, boards[-1].position_ned_m, boxes,
                             f"checkerboard {boards[-1].name!r}")
    _check_unique(top, "checkerboards", [b.name for b in boards])
    lights = tuple(_parse_light(t, i) for i, t in enumerate(top.array_of_tables("lights"), 1))
    _check_unique(top, "pads", [p.name for p in pads])
    _check_unique(top, "boxes", [b.name for b in boxes])
    _check_unique(top, "lights", [light.name for light in lights])
    start_poses: dict[str, StartPose] = {}
    for table in top.array_of_tables("start_poses"):
        pose_name, pose = _parse_start_pose(table)
        same = [n for n in start_poses if n.casefold() == pose_name.casefold()]
        if same:  # INIT {Start name} ignores case: one would shadow the other
            table.fail(f"duplicate start pose name {pose_name!r} (as {same[0]!r}: start pose "
                       "names ignore case)", "name")
        _check_on_ground(table, "position_ned_m", pose.position_ned_m, ground)
        if pose.position_ned_m[2] > 0.0:
            table.fail(f"start pose {pose_name!r} is {pose.position_ned_m[2]:g} m below the "
                       "ground (NED: down is positive, the ground is down = 0)",
                       "position_ned_m")
        if max(abs(v) for v in pose.position_ned_m) > MAX_LOCATION_M:
            table.fail(f"start pose {pose_name!r} lies more than {MAX_LOCATION_M:g} m from the "
                       "origin along an axis, the bound INIT's Location has (beyond it the "
                       "barometer's atmosphere model fails)", "position_ned_m")
        _check_outside_boxes(table, pose.position_ned_m, boxes, f"start pose {pose_name!r}",
                             "a vehicle standing there would stand in the box")
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
        checkerboards=tuple(boards),
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
    alt = table.number(
        "altitude_m",
        0.0,
        lambda v: ORIGIN_ALTITUDE_MIN_M <= v <= ORIGIN_ALTITUDE_MAX_M,
        f"in [{ORIGIN_ALTITUDE_MIN_M:g}, {ORIGIN_ALTITUDE_MAX_M:g}] m, the range of the "
        "barometer's ISA troposphere model (see docs/worlds.md)",
    )
    return GeoOrigin(latitude_deg=lat, longitude_deg=lon, altitude_m=alt)


def _parse_ground(table: _Table) -> Ground:
    table.check_keys({"size_m", "texture", "rgb", "rgb2", "texture_cell_m"})
    size = table.number(
        "size_m", 50.0, lambda v: 0.0 < v <= MAX_LOCATION_M,
        f"in (0, {MAX_LOCATION_M:g}] m, the bound start poses and INIT's Location have",
    )
    texture = table.choice("texture", GROUND_TEXTURES, "grass")
    rgb_default, rgb2_default, cell_default = _GROUND_DEFAULTS[texture]
    return Ground(
        size_m=size,
        texture=texture,
        rgb=table.rgb("rgb", rgb_default),
        rgb2=table.rgb("rgb2", rgb2_default),
        texture_cell_m=table.number(
            "texture_cell_m", cell_default, lambda v: v >= MIN_TEXTURE_CELL_M,
            f"at least {MIN_TEXTURE_CELL_M:g} m (the smallest printed checkerboard square)",
        ),
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


def _parse_checkerboard(table: _Table, index: int) -> CheckerboardPlacement:
    table.check_keys({"name", "inner_corners", "square_m", "position_ned_m", "yaw_rad"})
    corners = table._get("inner_corners", _REQUIRED)
    if (
        not isinstance(corners, list)
        or len(corners) != 2
        or not all(isinstance(c, int) and not isinstance(c, bool) and 2 <= c <= 40
                   for c in corners)
    ):
        table.fail(f"must be [cols, rows], two integers 2..40, got {corners!r}", "inner_corners")
    return CheckerboardPlacement(
        name=table.name("name", f"board{index}"),
        inner_corners=(int(corners[0]), int(corners[1])),
        square_m=table.number("square_m", check=lambda v: 0.001 <= v <= 1.0,
                              rule="in [0.001, 1] m"),
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


# How far (m) a start pose may reach into a box's side or top and still stand beside or on it.
_BOX_TOLERANCE_M: Final = 0.001


def _stands_in_box(position_ned_m: Vec3, box: Box) -> bool:
    """Whether a vehicle standing at this point (the point its gear touches, the vehicle above
    it) would be inside the box: the point within the box's footprint, below its top and not
    below its bottom (a point on the bottom face is a box standing on the ground there; a box
    wholly above the point is a ceiling or an overhang)."""
    dn = position_ned_m[0] - box.center_ned_m[0]
    de = position_ned_m[1] - box.center_ned_m[1]
    c, s = math.cos(box.yaw_rad), math.sin(box.yaw_rad)
    along, across = c * dn + s * de, -s * dn + c * de  # in the box's own axes
    half_n, half_e, half_d = (v / 2.0 for v in box.size_m)
    down = position_ned_m[2] - box.center_ned_m[2]
    tol = _BOX_TOLERANCE_M
    return (abs(along) < half_n - tol and abs(across) < half_e - tol
            and -half_d + tol < down <= half_d + tol)


def _check_outside_boxes(table: _Table, position: Vec3, boxes: tuple[Box, ...], what: str,
                         why: str = "no camera sees it there") -> None:
    """Not inside a box (:func:`_stands_in_box`): a start pose, a pad or a board on the ground
    under a building, or in its walls, is refused; on its top or under a ceiling is fine."""
    for box in boxes:
        if _stands_in_box(position, box):
            top_down = box.center_ned_m[2] - box.size_m[2] / 2.0
            table.fail(f"{what} lies inside box {box.name!r}: {why}; put it on the box's top "
                       f"(down = {top_down:g}) or outside its footprint", "position_ned_m")


def _check_unique(top: _Table, key: str, names: list[str]) -> None:
    seen: set[str] = set()
    for name in names:
        if name in seen:
            top.fail(f"duplicate name {name!r}", f"[[{key}]].name")
        seen.add(name)


def _check_on_ground(table: _Table, key: str, position: Vec3, ground: Ground,
                     what: str | None = None) -> None:
    """North/east within the ground; with ``what`` (a thing lying on a surface: a pad, a
    board) also not below the ground, where no camera sees it."""
    if max(abs(position[0]), abs(position[1])) > ground.size_m:
        table.fail(
            f"north/east {position[:2]} lies outside the ground (half-extent {ground.size_m} m)",
            key,
        )
    if what is not None and position[2] > 0.0:
        table.fail(f"the {what} is {position[2]:g} m below the ground, where no camera sees it "
                   "(NED: down is positive, the ground is down = 0)", key)


def load_world(name_or_path: str | Path) -> WorldDescription:
    """A built-in world by name (see BUILTIN_WORLDS) or a world file by path."""
    text_name = str(name_or_path)
    if isinstance(name_or_path, str) and text_name in BUILTIN_WORLDS:
        resource = resources.files("skeye.sim").joinpath("worlds", f"{text_name}.toml")
        return _load_text(resource.read_text(encoding="utf-8"), str(resource))
    path = Path(name_or_path)
    if path.is_dir():  # before the name's check: a folder named like a world is still a folder
        raise ConfigError(f"{path} is a folder, not a world file (give a .toml file, e.g. "
                          f"{path / 'my_world.toml'})")
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
