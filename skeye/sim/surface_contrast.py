"""How much texture each surface of a world shows an optical-flow sensor: one number per geom.

Why: an optical mouse sensor (the ADNS-3080) tracks features of the surface under it; its
surface quality (SQUAL) counts them, and over a plain surface it has none and stops reporting
motion. Rendering what the sensor sees every reading would cost a camera render per sample;
instead each surface's texture is measured once, when the world is built, and the sensor looks
up the number for the geom its boresight ray hits.

How this works: the measure is the RMS contrast of the surface's luminance (standard deviation
over mean, Rec. 601 luma), computed from the very texture MuJoCo shows: the procedural ground
textures and the pad texture are decoded from their PNG bytes; MuJoCo's builtin checker of two
colours a and b has |a - b| / (a + b); a surface of one colour (texture "none", boxes) has 0;
a pad's collision box, whose top face is the pad's textured sheet, has the pad's. Keys are geom
names as :func:`skeye.sim.world.build_mjcf` writes them; a geom not named here (robots) has 0.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from skeye.sim.world_model import Vec3, WorldDescription
from skeye.sim.world_textures import ground_texture_png, pad_texture_png

_LUMA = (0.299, 0.587, 0.114)


def _luma(rgb: Vec3) -> float:
    return _LUMA[0] * rgb[0] + _LUMA[1] * rgb[1] + _LUMA[2] * rgb[2]


@functools.lru_cache(maxsize=16)
def png_contrast(png: bytes) -> float:
    """RMS contrast (std / mean of luminance) of an encoded image; 0 for a black one.

    Cached by the bytes: every :class:`~skeye.sim.engine.Simulation` of a world decodes the
    same textures (a learning environment makes one per episode: 50 ms of decoding each)."""
    grey = cv2.imdecode(np.frombuffer(png, dtype=np.uint8), cv2.IMREAD_GRAYSCALE)
    if grey is None:
        raise ValueError("not an image")
    values = grey.astype(float)
    mean = float(values.mean())
    return float(values.std()) / mean if mean > 0.0 else 0.0


def geom_contrasts(world: WorldDescription) -> dict[str, float]:
    """RMS contrast of each textured surface of ``world``, by geom name."""
    ground = world.ground
    out: dict[str, float] = {}
    if ground.texture == "checker":
        a, b = _luma(ground.rgb), _luma(ground.rgb2)
        out["ground"] = abs(a - b) / (a + b) if a + b > 0.0 else 0.0
    elif ground.texture != "none":
        out["ground"] = png_contrast(ground_texture_png(ground.texture, ground.rgb, ground.rgb2))
    for pad in world.pads:
        contrast = png_contrast(pad_texture_png(pad.pad))
        out[f"pad:{pad.name}"] = contrast
        # The pad's collision box is the same sheet: its top face is the textured plane's
        # height, so a ray may report either geom; both show the pad's texture.
        out[f"pad:{pad.name}:collider"] = contrast
    return out
