"""World textures: the landing pad and the procedural grounds, generated deterministically.

How this works: each texture is rendered from data (the pad's rings, a seeded noise field) and
encoded as PNG; the same inputs give the same bytes every time (cached), handed to MuJoCo as
assets by :func:`skeye.sim.world.build_mjcf`.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from skeye.errors import ConfigError
from skeye.sim.world_model import GROUND_TEXTURES, PAD_TEXTURE_PX, Vec3
from skeye.vision.pad import PadDefinition, render_pad

# ----------------------------------------------------------------------------------------------
# Textures (deterministic)


@functools.lru_cache(maxsize=8)
def pad_texture_png(pad: PadDefinition, pixels: int = PAD_TEXTURE_PX) -> bytes:
    """The pad as an RGB PNG (grey levels), rendered from the pad's data."""
    grey = render_pad(pad, pixels, supersample=2)
    return _png(np.dstack([grey, grey, grey]))


CHECKER_SQUARE_PX = 64  # texture pixels per checkerboard square


@functools.lru_cache(maxsize=8)
def checkerboard_texture_png(cols: int, rows: int) -> bytes:
    """A printed calibration board: (cols + 1) x (rows + 1) squares, the first black, on white
    paper with a one-square margin (OpenCV's corner finder needs a white border). Rows of the
    image run along the board's columns (texture u = the board's north axis at yaw 0)."""
    n = CHECKER_SQUARE_PX
    across, down = cols + 3, rows + 3  # squares along the sheet, margins included
    u = np.arange(across * n) // n  # square index along the sheet
    v = np.arange(down * n) // n
    ui, vi = np.meshgrid(u, v)
    board = (ui >= 1) & (ui <= cols + 1) & (vi >= 1) & (vi <= rows + 1)
    black = board & ((ui + vi) % 2 == 0)
    grey = np.where(black, 0, 255).astype(np.uint8)
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
