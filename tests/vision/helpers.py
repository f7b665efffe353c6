"""Shared helpers for the vision tests: the reference camera and visibility of rings."""

from __future__ import annotations

import math

import cv2
import numpy as np

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
