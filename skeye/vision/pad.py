"""Landing pads as data: the same definition makes the simulator texture and the printable pad.

How this works: a pad is a black square with concentric white rings; each ring has its own
inner/outer radius ratio so it can be identified from its two borders alone. Pads are frozen
dataclasses; :func:`render_pad` rasterises one at a given resolution with anti-aliased edges
(area coverage by supersampling), so the texture's ring borders sit where the data says.
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass

import numpy as np

from skeye.errors import ConfigError, InvalidArgument, UnknownName

PAD_SURFACE_HEIGHT_M = 0.001
"""A pad's visible surface lies this far above the point a world file gives (so it never
z-fights the ground); the simulator draws it there and measures height above it."""


MIN_RINGS = 2
"""The fewest rings a pad file may give: the detector reports a pad only when at least two of
its rings are identified and agree on the centre and the scale. (A :class:`PadDefinition` may
have one, as a pattern to draw: the tests render single rings to check they are not taken for
a pad.)"""


@dataclass(frozen=True)
class Ring:
    """One white ring: radii in metres."""

    outer_m: float
    inner_m: float

    @property
    def ratio(self) -> float:
        return self.inner_m / self.outer_m


@dataclass(frozen=True)
class PadDefinition:
    """A square black pad with concentric white rings, outermost first."""

    name: str
    side_m: float
    rings: tuple[Ring, ...]

    def __post_init__(self) -> None:
        if not (math.isfinite(self.side_m) and self.side_m > 0):  # nan, inf: no page, no texture
            raise InvalidArgument(f"pad {self.name!r}: side_m must be a positive finite number, "
                                  f"got {self.side_m}")
        # Ring 1 may reach the square's edge; every other ring needs black between it and the
        # ring before (touching, the two white rings would be one band, naming neither ring).
        previous_inner = self.side_m / 2
        for i, ring in enumerate(self.rings, start=1):
            first = i == 1
            if not (0 < ring.inner_m < ring.outer_m
                    and (ring.outer_m <= previous_inner if first
                         else ring.outer_m < previous_inner)):
                raise InvalidArgument(
                    f"pad {self.name!r}: ring {i} radii ({ring.outer_m}, {ring.inner_m}) "
                    "must satisfy "
                    + (f"0 < inner < outer <= {previous_inner} (inside the square)" if first else
                       f"0 < inner < outer < {previous_inner} (inside the ring before, with "
                       "black between them)"))
            previous_inner = ring.inner_m
        ratios = [r.ratio for r in self.rings]
        if len(set(round(r, 3) for r in ratios)) != len(ratios):
            raise InvalidArgument(f"pad {self.name!r}: ring ratios must be unique, got {ratios}")
        if not self.rings:
            raise InvalidArgument(f"pad {self.name!r}: needs at least one ring")


SKEYE_4 = PadDefinition(
    name="skeye-4",
    side_m=0.60,
    rings=(
        Ring(outer_m=0.280, inner_m=0.238),
        Ring(outer_m=0.200, inner_m=0.150),
        Ring(outer_m=0.130, inner_m=0.078),
        Ring(outer_m=0.055, inner_m=0.022),
    ),
)

PADS: dict[str, PadDefinition] = {SKEYE_4.name: SKEYE_4}


def get_pad(name: str) -> PadDefinition:
    """A built-in pad by name; raises KeyError naming the known pads."""
    try:
        return PADS[name]
    except KeyError:
        raise UnknownName(f"unknown pad {name!r}; known pads: {', '.join(sorted(PADS))}") from None


def render_pad(pad: PadDefinition, pixels: int, supersample: int = 4) -> np.ndarray:
    """Rasterise the pad as a square greyscale image (uint8, 0 black, 255 white).

    Pixel (row, col) covers the square [col, col+1) x [row, row+1) in pixel units; the pad's
    centre is at (pixels/2, pixels/2). Edges are anti-aliased by ``supersample``^2 sub-samples:
    a pixel's value is round(255 x the share of its sub-samples inside a ring). Only pixels that
    a ring edge may cross are sub-sampled; the others are 0 or 255 outright (the same result,
    a few percent of the work: the simulator builds a 2048 px texture at every start).
    """
    if pixels < 8:
        raise InvalidArgument(f"pad texture needs at least 8 pixels, got {pixels}")
    n = pixels * supersample
    coords = (np.arange(n) + 0.5) / n * pad.side_m - pad.side_m / 2  # sub-sample centres
    # A pixel's sub-samples lie within half a pixel diagonal of its centre (plus a margin far
    # above rounding): a pixel whose centre is farther than that from every edge is uniform.
    centres = (np.arange(pixels) + 0.5) / pixels * pad.side_m - pad.side_m / 2
    reach = pad.side_m / pixels * math.sqrt(0.5) + 1e-9
    r = np.hypot(centres[None, :], centres[:, None])
    inside = np.zeros(r.shape, dtype=bool)
    mixed = np.zeros(r.shape, dtype=bool)
    for ring in pad.rings:
        inside |= (r >= ring.inner_m) & (r < ring.outer_m)
        mixed |= (np.abs(r - ring.inner_m) <= reach) | (np.abs(r - ring.outer_m) <= reach)
    img = np.where(inside, 255, 0).astype(np.uint8)
    rows, cols = np.nonzero(mixed)
    step = np.arange(supersample)
    ys = coords[rows[:, None, None] * supersample + step[None, :, None]]
    xs = coords[cols[:, None, None] * supersample + step[None, None, :]]
    sub = np.hypot(xs, ys)  # (mixed pixels, sub-row, sub-column), as the full grid would be
    white = np.zeros(sub.shape, dtype=bool)
    for ring in pad.rings:
        white |= (sub >= ring.inner_m) & (sub < ring.outer_m)
    share = white.sum(axis=(1, 2)) / supersample**2
    img[rows, cols] = np.round(share * 255.0).astype(np.uint8)
    return img


def pad_to_dict(pad: PadDefinition) -> dict[str, object]:
    """The pad as plain data (the same keys a pad TOML file uses)."""
    return {
        "name": pad.name,
        "side_m": pad.side_m,
        "rings": [{"outer_m": r.outer_m, "inner_m": r.inner_m} for r in pad.rings],
    }


def pad_from_dict(data: dict[str, object], source: str = "<dict>") -> PadDefinition:
    """Build a pad from plain data; raises ConfigError naming ``source`` and the bad key."""

    def number(value: object, key: str) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{source}: {key} must be a number, got {value!r}")
        return float(value)

    unknown = set(data) - {"name", "side_m", "rings"}
    if unknown:
        raise ConfigError(f"{source}: unknown keys {sorted(unknown)}; expected name, side_m, rings")
    for key in ("name", "side_m", "rings"):
        if key not in data:
            raise ConfigError(f"{source}: missing key {key!r}")
    name = data["name"]
    if not isinstance(name, str) or not name:
        raise ConfigError(f"{source}: name must be a non-empty string, got {name!r}")
    if not name.isprintable():  # printed on the page and said on the terminal: a newline
        # broke the page's caption, an escape sequence reached the terminal, a NUL was drawn as
        # a missing glyph
        raise ConfigError(f"{source}: name must be printable characters (no newline, tab or "
                          f"control character), got {name!r}")
    side_m = number(data["side_m"], "side_m")
    rings_data = data["rings"]
    if not isinstance(rings_data, list) or not rings_data:
        raise ConfigError(f"{source}: rings must be a non-empty list of [[rings]] tables")
    rings = []
    for i, entry in enumerate(rings_data, start=1):
        if not isinstance(entry, dict) or set(entry) != {"outer_m", "inner_m"}:
            raise ConfigError(f"{source}: rings[{i}] must have exactly outer_m and inner_m")
        rings.append(
            Ring(
                outer_m=number(entry["outer_m"], f"rings[{i}].outer_m"),
                inner_m=number(entry["inner_m"], f"rings[{i}].inner_m"),
            )
        )
    try:
        pad = PadDefinition(name=name, side_m=side_m, rings=tuple(rings))
    except ValueError as exc:
        raise ConfigError(f"{source}: {exc}") from None
    if len(pad.rings) < MIN_RINGS:  # after the radii: a bad ring is named first
        raise ConfigError(
            f"{source}: rings: {len(pad.rings)} ring{'' if len(pad.rings) == 1 else 's'}; the "
            f"detector needs at least {MIN_RINGS} (it reports a pad only when two of its rings "
            "agree on the centre and the scale)")
    return pad


def load_pad(path: str | os.PathLike[str]) -> PadDefinition:
    """A user-defined pad from a TOML file (keys: name, side_m, [[rings]] outer_m/inner_m).

    Rings are listed outermost first; radii in metres. Raises ConfigError naming the file.
    """
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read pad file: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:  # tomllib decodes the bytes itself
        raise ConfigError(f"{path}: not valid TOML (not UTF-8 text): {exc}") from None
    return pad_from_dict(data, source=str(path))


def resolve_pad(name_or_path: str) -> PadDefinition:
    """A built-in pad by name, or a pad TOML file by path (anything ending in .toml, in any
    case: ``PAD.TOML`` was looked up as a built-in name, "unknown pad"). A file of another
    name is said to be one, not only an unknown name."""
    if name_or_path.lower().endswith(".toml"):
        return load_pad(name_or_path)
    try:
        return get_pad(name_or_path)
    except KeyError as exc:
        said = str(exc.args[0])
        if os.path.isfile(name_or_path):
            said += f" ({name_or_path} is a file, but a pad file's name ends in .toml)"
        raise ConfigError(said) from None
