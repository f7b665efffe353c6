"""World textures: the landing pad and the procedural grounds, generated deterministically.

How this works: each texture is rendered from data (the pad's rings, a seeded noise field) and
encoded as PNG; the same inputs give the same bytes every time, handed to MuJoCo as assets by
:func:`skeye.sim.world.build_mjcf`. Rendering them is most of a world's build (about 0.5 s of a
simulator's 0.9 s start), so they are kept twice: in the process (``lru_cache``) and on disk
for later processes (:func:`_kept`, in ``$XDG_CACHE_HOME/skeye/textures/``), keyed by the
texture's inputs, the code that renders it and the numpy and OpenCV versions it ran on, each
file checked against its own digest. A damaged file is rendered again; a cache that cannot be
written is done without.
"""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

import skeye.vision.pad
from skeye.errors import ConfigError
from skeye.outputs import cache_folder
from skeye.sim.world_model import GROUND_TEXTURES, PAD_TEXTURE_PX, Vec3
from skeye.vision.pad import PadDefinition, render_pad

log = logging.getLogger(__name__)

# ----------------------------------------------------------------------------------------------
# The disk cache

KEPT_FILES = 32
"""At most this many textures stay on disk; the oldest go first (a code change keys anew)."""

PARTIAL_AGE_S = 600.0
"""A half-written file (its writer killed before it was put in place) older than this goes."""


@functools.lru_cache(maxsize=1)
def _code_key() -> bytes:
    """What the textures' pixels depend on besides their inputs: this module's and the pad
    renderer's source, numpy's FFT and OpenCV's PNG codec (by version)."""
    digest = hashlib.sha256(f"{np.__version__} {cv2.__version__}".encode())
    for module in (__file__, skeye.vision.pad.__file__):
        digest.update(Path(module).read_bytes())
    return digest.digest()


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def _kept(what: tuple[object, ...], render: Callable[[], bytes]) -> bytes:
    """The PNG ``render()`` makes for ``what`` (a texture's name and every input its pixels
    depend on, by ``repr``), from the disk cache when a whole one is kept there, else rendered
    and kept. A kept file is named ``KIND-KEY-DIGEST.png``, DIGEST its bytes' own (SHA-256), so
    a file cut short or damaged anywhere is known and rendered again."""
    try:
        key = hashlib.sha256(_code_key() + repr(what).encode()).hexdigest()[:32]
        folder = cache_folder("textures")
    except OSError as exc:  # no source to key by, no cache folder: render every time
        log.debug("texture cache off: %s", exc)
        return render()
    stem = f"{what[0]}-{key}"
    try:
        for path in sorted(folder.glob(f"{stem}-*.png")):
            data = path.read_bytes()
            if path.stem == f"{stem}-{_digest(data)}":
                return data
            path.unlink(missing_ok=True)  # damaged: rendered again below
    except OSError:
        pass  # not kept yet, or unreadable: rendered below
    data = render()
    path = folder / f"{stem}-{_digest(data)}.png"
    partial = folder / f".{path.name}.{os.getpid()}.{threading.get_ident()}.partial"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        partial.write_bytes(data)
        os.replace(partial, path)  # whole or not at all; two processes write the same bytes
        _trim(folder)
    except OSError as exc:  # a read-only or full disk: the texture is still made
        log.debug("could not keep texture %s: %s", path, exc)
        try:
            partial.unlink(missing_ok=True)
        except OSError:
            pass  # no folder to have written it in
    return data


def _trim(folder: Path) -> None:
    """Remove the oldest kept textures beyond :data:`KEPT_FILES`, and half-written files older
    than :data:`PARTIAL_AGE_S` (their writers were killed)."""
    files = []
    now = time.time()
    for path in folder.glob("*.png"):
        try:
            files.append((path.stat().st_mtime, path))
        except OSError:
            continue  # removed by another process meanwhile
    for _, path in sorted(files)[:-KEPT_FILES]:
        path.unlink(missing_ok=True)
    for path in folder.glob(".*.partial"):
        try:
            if now - path.stat().st_mtime > PARTIAL_AGE_S:
                path.unlink(missing_ok=True)
        except OSError:
            continue


# ----------------------------------------------------------------------------------------------
# Textures (deterministic)


@functools.lru_cache(maxsize=8)
def pad_texture_png(pad: PadDefinition, pixels: int = PAD_TEXTURE_PX) -> bytes:
    """The pad as an RGB PNG (grey levels), rendered from the pad's data."""

    def render() -> bytes:
        grey = render_pad(pad, pixels, supersample=2)
        return _png(np.dstack([grey, grey, grey]))

    return _kept(("pad", pad, pixels), render)


CHECKER_SQUARE_PX = 64  # texture pixels per checkerboard square


@functools.lru_cache(maxsize=8)
def checkerboard_texture_png(cols: int, rows: int) -> bytes:
    """A printed calibration board: (cols + 1) x (rows + 1) squares, the first black, on white
    paper with a one-square margin (OpenCV's corner finder needs a white border). Rows of the
    image run along the board's columns (texture u = the board's north axis at yaw 0). Not kept
    on disk: it takes a few milliseconds."""
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
    if texture not in ("grass", "concrete"):
        raise ConfigError(f"no procedural texture for ground texture {texture!r}")
    seed = 20240611 + GROUND_TEXTURES.index(texture)
    return _kept(("ground", texture, rgb, rgb2, pixels, seed),
                 lambda: _ground_png(rgb, rgb2, pixels, seed, texture == "grass"))


def _ground_png(rgb: Vec3, rgb2: Vec3, pixels: int, seed: int, grass: bool) -> bytes:
    rng = np.random.default_rng(seed)
    if grass:
        mix = (
            0.55 * _periodic_noise(rng, pixels, 1.0)
            + 0.35 * _periodic_noise(rng, pixels, 6.0)
            + 0.45 * _periodic_noise(rng, pixels, 40.0)
        )
        t = np.clip(0.5 + 0.22 * mix, 0.0, 1.0)
    else:  # concrete
        mix = 0.6 * _periodic_noise(rng, pixels, 0.7) + 0.5 * _periodic_noise(rng, pixels, 30.0)
        t = np.clip(0.5 + 0.2 * mix, 0.0, 1.0)
    a, b = np.array(rgb), np.array(rgb2)
    img = a[None, None, :] * (1.0 - t[..., None]) + b[None, None, :] * t[..., None]
    return _png(np.round(np.clip(img, 0.0, 1.0) * 255.0).astype(np.uint8))
