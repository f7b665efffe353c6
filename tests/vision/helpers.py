"""Shared helpers for the vision tests: the reference camera and visibility of rings."""

from __future__ import annotations

import math

import cv2
import numpy as np

from skeye.robots.camera_model import CameraModel
from skeye.vision.calibration import CameraCalibration, undistort_points
from skeye.vision.camera import camera_to_level, intrinsics
from skeye.vision.pad import SKEYE_4, PadDefinition

FOV_H_RAD = 1.309  # 75 degrees, the paper's camera
W, H = 800, 600


def rings_fully_in_view(
    h_m: float,
    offset_m: tuple[float, float],
    roll_rad: float = 0.0,
    pitch_rad: float = 0.0,
    pad: PadDefinition = SKEYE_4,
    margin_px: float = 3.0,
) -> list[int]:
    """Ring numbers whose outer border projects entirely inside the image."""
    k = intrinsics(W, H, FOV_H_RAD)
    rot = camera_to_level(roll_rad, pitch_rad)
    t = np.linspace(0.0, 2.0 * math.pi, 360, endpoint=False)
    out = []
    for i, ring in enumerate(pad.rings, start=1):
        pts_l = np.stack(
            (
                offset_m[0] + ring.outer_m * np.cos(t),
                offset_m[1] + ring.outer_m * np.sin(t),
                np.full_like(t, h_m),
            )
        )
        pc = rot.T @ pts_l
        uv = (k @ pc)[:2] / pc[2]
        if (
            (uv[0] >= margin_px).all()
            and (uv[0] <= W - 1 - margin_px).all()
            and (uv[1] >= margin_px).all()
            and (uv[1] <= H - 1 - margin_px).all()
        ):
            out.append(i)
    return out


def grass(rng: np.random.Generator, blob_px: int = 6) -> np.ndarray:
    """A grass-like random texture (smooth blobs plus fine grain), uint8."""
    base = rng.normal(0.0, 1.0, (H // blob_px + 1, W // blob_px + 1)).astype(np.float32)
    g = cv2.resize(base, (W, H), interpolation=cv2.INTER_CUBIC)
    g += rng.normal(0.0, 0.6, (H, W)).astype(np.float32)
    g = cv2.GaussianBlur(g, (0, 0), 1.0)
    return np.clip(120.0 + 40.0 * g, 0, 255).astype(np.uint8)


# ----------------------------------------------------------------------------------------------
# Lens distortion applied to ideal (pinhole) frames.
#
# Until the simulator renders through a lens model itself, tests distort the simulator's ideal
# frames here: ``distort_image(ideal, k_ideal, k, dist, size)`` is what a camera with matrix
# ``k`` and OpenCV distortion ``dist`` = (k1, k2, p1, p2, k3) would have seen of the scene the
# ideal pinhole frame (matrix ``k_ideal``) shows. Barrel distortion (k1 < 0) shows more than
# the pinhole's field of view, so the ideal frame comes from a wider camera of the same focal
# length (``wide_camera``). To switch a test to the simulator's own lens model, give the
# robot file's [camera] section the same coefficients and drop the call.


def wide_camera(k: np.ndarray, width: int, height: int, margin: float) -> tuple[
    np.ndarray, int, int, float
]:
    """A pinhole camera with ``k``'s focal length and ``margin`` times the image size:
    (matrix, width, height, horizontal field of view rad) for the simulator to render."""
    w2, h2 = round(width * margin), round(height * margin)
    f = float(k[0, 0])
    k2 = np.array(((f, 0.0, (w2 - 1) / 2.0), (0.0, f, (h2 - 1) / 2.0), (0.0, 0.0, 1.0)))
    return k2, w2, h2, 2.0 * math.atan(w2 / 2.0 / f)


def distortion_maps(
    k_ideal: np.ndarray, k: np.ndarray, dist: tuple[float, ...], size: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """cv2.remap maps: for every pixel of the distorted ``size`` (w, h) image, where it lies in
    the ideal one. A distorted pixel (u, v) is undistorted with ``k`` and ``dist`` (OpenCV's
    model, iterated to convergence) and projected with ``k_ideal``."""
    width, height = size
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    pts = np.stack((u.ravel(), v.ravel()), axis=1).reshape(-1, 1, 2)
    ideal = undistort_points(pts, k, np.asarray(dist, np.float64), None, k_ideal)
    ideal = ideal.reshape(height, width, 2).astype(np.float32)
    return ideal[..., 0], ideal[..., 1]


def distort_image(
    ideal: np.ndarray,
    k_ideal: np.ndarray,
    k: np.ndarray,
    dist: tuple[float, ...],
    size: tuple[int, int],
) -> np.ndarray:
    """The scene of the ideal frame as the distorting camera shows it (bilinear resampling)."""
    mx, my = distortion_maps(k_ideal, k, dist, size)
    return cv2.remap(ideal, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


# ----------------------------------------------------------------------------------------------
# What a webcam does to a frame (greyscale uint8 in, uint8 out; noise takes a seeded rng).


def add_noise(g: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Gaussian sensor noise of ``sigma`` grey levels."""
    noisy = g.astype(np.float64) + rng.normal(0.0, sigma, g.shape)
    return np.clip(np.round(noisy), 0, 255).astype(np.uint8)


def defocus(g: np.ndarray, sigma_px: float) -> np.ndarray:
    """Gaussian blur (defocus, a soft lens) of standard deviation ``sigma_px``."""
    return cv2.GaussianBlur(g, (0, 0), sigma_px)


def vignette(g: np.ndarray, corner_gain: float) -> np.ndarray:
    """Brightness falling with the squared radius to ``corner_gain`` in the corners."""
    h, w = g.shape
    y, x = np.mgrid[0:h, 0:w]
    r2 = ((x - (w - 1) / 2) ** 2 + (y - (h - 1) / 2) ** 2) / (((w - 1) / 2) ** 2
                                                              + ((h - 1) / 2) ** 2)
    return np.clip(np.round(g * (1.0 - (1.0 - corner_gain) * r2)), 0, 255).astype(np.uint8)


def jpeg(g: np.ndarray, quality: int) -> np.ndarray:
    """A JPEG round trip at ``quality``."""
    ok, data = cv2.imencode(".jpg", g, [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)


def dim(g: np.ndarray, gain: float, offset: float = 20.0) -> np.ndarray:
    """Under-exposure: the grey range squeezed to ``offset + gain * g``."""
    return np.clip(np.round(offset + gain * g.astype(np.float64)), 0, 255).astype(np.uint8)


def motion_blur(g: np.ndarray, length_px: float) -> np.ndarray:
    """Horizontal motion blur: a box of ``length_px`` along the image rows."""
    n = math.ceil(length_px) | 1
    length = round(length_px)
    kernel = np.zeros((n, n), np.float32)
    start = (n - length) // 2
    kernel[n // 2, start : start + length] = 1.0
    kernel /= kernel.sum()
    return cv2.filter2D(g, -1, kernel, borderType=cv2.BORDER_REPLICATE)


def rolling_shutter(g: np.ndarray, skew_px: float) -> np.ndarray:
    """A rolling shutter during a sideways motion: the last row shifted ``skew_px`` right of
    the first, linearly in between (the middle row stays)."""
    h, w = g.shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    mx = x - np.float32(skew_px) * (y / (h - 1) - 0.5)
    return cv2.remap(g, mx, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def model_calibration(model: CameraModel) -> CameraCalibration:
    """The calibration a perfect ``skeye calibrate`` would give for this camera model."""
    return CameraCalibration(model.width, model.height, model.fx_px, model.fy_px, model.cx_px,
                             model.cy_px, model.dist_coeffs)


def board_views(width: int, height: int, f_px: float, count: int = 6, cols: int = 9,
                rows: int = 6) -> list[np.ndarray]:
    """Greyscale views of a ``cols`` x ``rows`` inner-corner checkerboard (25 mm squares, one
    square of white margin) through an ideal pinhole of focal length ``f_px``, centred, 0.45 m
    from the board, each tilted another way (up to 0.35 rad) and turned by 0.1 rad more than the
    last: enough views for ``calibrateCamera`` without the simulator. Drawn with
    ``warpPerspective`` (area-averaged) from a 100 px-per-square texture."""
    k = np.array(((f_px, 0.0, (width - 1) / 2), (0.0, f_px, (height - 1) / 2), (0.0, 0.0, 1.0)))
    sq = 100
    tex = np.full(((rows + 3) * sq, (cols + 3) * sq), 255, np.uint8)
    for r in range(rows + 1):
        for c in range(cols + 1):
            if (r + c) % 2 == 0:
                tex[(r + 1) * sq:(r + 2) * sq, (c + 1) * sq:(c + 2) * sq] = 0
    m_per_px = 0.025 / sq
    centre = np.array(((cols + 3) * sq / 2 * m_per_px, (rows + 3) * sq / 2 * m_per_px, 0.0))
    tilts = ((0.0, 0.0), (0.35, 0.0), (-0.35, 0.1), (0.0, 0.35), (0.2, -0.3), (-0.25, -0.25))
    out = []
    for i in range(count):
        ax, ay = tilts[i % len(tilts)]
        rot, _ = cv2.Rodrigues(np.array((ax, ay, 0.1 * i)))
        t = np.array((0.0, 0.0, 0.45)) - rot @ centre
        homography = k @ np.column_stack((rot[:, 0] * m_per_px, rot[:, 1] * m_per_px, t))
        out.append(cv2.warpPerspective(tex, homography, (width, height), flags=cv2.INTER_AREA,
                                       borderValue=128))
    return out
