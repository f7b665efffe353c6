"""A world as data: the frozen description a world file becomes, and the world's constants.

How this works: :mod:`skeye.sim.world_file` validates a TOML world file into a
:class:`WorldDescription`; :mod:`skeye.sim.world` builds the MuJoCo model from one. Everything
is in the protocol's NED frame (x north, y east, z down, metres; yaw in rad about down).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from skeye.geo import GeoOrigin
from skeye.vision.pad import PAD_SURFACE_HEIGHT_M, PadDefinition

BUILTIN_WORLDS = ("pad", "yard", "indoor", "checkerboard")
GROUND_TEXTURES = ("grass", "checker", "concrete", "none")

PAD_TEXTURE_PX = 2048
# Chemnitz, Germany (WMM, about 2025): north, east, down in microtesla.
DEFAULT_MAGNETIC_FIELD_NED_UT = (20.0, 1.5, 44.0)
DEFAULT_SEA_LEVEL_PRESSURE_PA = 101325.0
# Absolute clipping distances of every rendered camera: a landed vehicle's camera sits a few
# centimetres above the pad, and 1 cm keeps the 1 mm pad layer resolved in depth far away.
NEAR_CLIP_M = 0.01
GRAVITY_M_S2 = 9.81

# Safe inside protocol segments and MJCF names. \A and \Z, not ^ and $: "$" also matches
# before a final newline, and a world named "x\n" killed the server's accept loop (its NFO line).
NAME_RE = re.compile(r"\A[A-Za-z0-9_.\-]+\Z")
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
class CheckerboardPlacement:
    """A printed calibration checkerboard lying flat on the ground (visual only).

    ``inner_corners`` is (cols, rows) as ``skeye calibrate --board COLSxROWS`` counts them:
    the board has (cols + 1) x (rows + 1) squares of ``square_m``, first square black, on a
    white sheet with a margin of one square. Its columns run along the board's north axis at
    yaw 0. ``position_ned_m`` is the board's centre on the ground; the printed surface lies
    ``PAD_SURFACE_HEIGHT_M`` above it, like a pad's.
    """

    name: str
    inner_corners: tuple[int, int]
    square_m: float
    position_ned_m: Vec3
    yaw_rad: float

    @property
    def sheet_m(self) -> tuple[float, float]:
        """The white sheet's extent (along the columns, along the rows), margins included."""
        cols, rows = self.inner_corners
        return ((cols + 3) * self.square_m, (rows + 3) * self.square_m)


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
    checkerboards: tuple[CheckerboardPlacement, ...] = ()
