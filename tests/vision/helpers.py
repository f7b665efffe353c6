"""Shared helpers for the vision tests: the reference camera and visibility of rings."""

from __future__ import annotations

import math

import cv2
import numpy as np

from skeye.vision.calibration import undistort_points
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
