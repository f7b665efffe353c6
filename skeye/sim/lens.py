"""The camera model's image path: a wide pinhole render remapped through the lens and sensor.

How this works (docs/camera.md): for a :class:`~skeye.robots.camera_model.CameraModel` with
distortion, the simulator renders a square-pixel pinhole image (focal ``max(fx, fy)``) just wide
enough to hold every output pixel's undistorted ray plus a margin for motion. :class:`Lens`
computes once, with ``cv2.undistortPoints``, each output pixel's undistorted normalised ray
``r`` and its place in that render (the base map, as ``cv2.initUndistortRectifyMap`` would for
the inverse direction). Per frame:

* Motion: the camera's angular rate ``w`` and velocity ``v`` (camera frame, OpenCV axes) at the
  capture instant move a world point seen along ``r`` at time ``tau`` after the capture to
  ``r + tau (v / s + w x r)`` in the captured render (first order; ``s`` the depth along ``r``
  to the flat ground plane z = 0, infinite above the horizon). Row ``i`` is read at
  ``tau_i = (i - (H - 1) / 2) line_time`` (rolling shutter, the capture instant is the middle
  row's), and integrates over ``tau_i +- exposure / 2`` (motion blur): the frame is the mean of
  ``n`` remaps at evenly spread times, ``n`` from the blur length in pixels (1..8). The motion
  term is computed on a coarse grid and upsampled (it is smooth); the static map stays exact.
* Noise: EMVA 1288's photon-transfer model, ``var(DN) = K * mean(DN) + K^2 sigma_d^2`` with
  ``K = system_gain_dn_per_e * gain``, drawn from a seeded bank of normal deviates (a frame's
  offset into the bank comes from the seed and the frame number: deterministic).
* Output: JPEG-coded and decoded at ``jpeg_quality`` (the webcam's MJPEG), else raw.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from skeye.robots.camera_model import CameraModel

MOTION_MARGIN = 0.08  # render this much wider than the lens needs, for motion (fraction)
MAX_BLUR_SAMPLES = 8
_GRID_STEP_PX = 16
_BANK_SPARE = 1 << 16


@dataclass(frozen=True)
class Motion:
    """The camera's motion at the capture instant, OpenCV camera axes (x right, y down,
    z forward): angular rate (rad/s), velocity (m/s), the world's down direction and the
    camera's height above the ground plane (m)."""

    omega_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    down: tuple[float, float, float] = (0.0, 0.0, 1.0)
    height_m: float = 1.0


class Lens:
    """One camera's distortion maps, motion warp, noise and output coding."""

    def __init__(self, model: CameraModel) -> None:
        self.model = model
        w, h = model.width, model.height
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        rays = undistort(model, np.stack([u.ravel(), v.ravel()], axis=1))
        self.ray_x = rays[:, 0].reshape(h, w).astype(np.float32)
        self.ray_y = rays[:, 1].reshape(h, w).astype(np.float32)
        self.focal_px = max(model.fx_px, model.fy_px)
        half_w = float(np.max(np.abs(self.ray_x))) * self.focal_px * (1 + MOTION_MARGIN)
        half_h = float(np.max(np.abs(self.ray_y))) * self.focal_px * (1 + MOTION_MARGIN)
        self.render_width = 2 * math.ceil(half_w + 1)
        self.render_height = 2 * math.ceil(half_h + 1)
        self.render_cx = (self.render_width - 1) / 2.0
        self.render_cy = (self.render_height - 1) / 2.0
        self.map_x = (self.ray_x * self.focal_px + self.render_cx).astype(np.float32)
        self.map_y = (self.ray_y * self.focal_px + self.render_cy).astype(np.float32)
        self.fixed_maps = cv2.convertMaps(self.map_x, self.map_y, cv2.CV_16SC2)
        # The coarse grid of the motion term, at cv2.resize's sample positions.
        gw, gh = max(2, w // _GRID_STEP_PX), max(2, h // _GRID_STEP_PX)
        gu = (np.arange(gw) + 0.5) * (w / gw) - 0.5
        gv = (np.arange(gh) + 0.5) * (h / gh) - 0.5
        guu, gvv = np.meshgrid(gu, gv)
        grays = undistort(model, np.stack([guu.ravel(), gvv.ravel()], axis=1))
        self.grid_x = grays[:, 0].reshape(gh, gw)
        self.grid_y = grays[:, 1].reshape(gh, gw)
        self.grid_tau = np.repeat(((gv - (h - 1) / 2.0) * model.line_time_s)[:, None], gw, axis=1)
        k = model.system_gain_dn_per_e * model.gain
        levels = np.arange(256, dtype=np.float64)
        self.sigma_lut = np.sqrt(k * levels + (k * model.read_noise_e) ** 2).astype(np.float32)
        self._bank: np.ndarray | None = None

    @property
    def render_fovy_deg(self) -> float:
        """MuJoCo's vertical field of view of the wide render (square pixels)."""
        return math.degrees(2.0 * math.atan((self.render_height / 2.0) / self.focal_px))

    def _shift(self, motion: Motion, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Render-pixel displacement of each grid ray at times ``tau`` after the capture."""
        wx, wy, wz = motion.omega_rad_s
        vx, vy, vz = motion.velocity_m_s
        x, y = self.grid_x, self.grid_y
        dn = motion.down[0] * x + motion.down[1] * y + motion.down[2]
        inv_s = np.maximum(dn, 0.0) / max(motion.height_m, 0.01)
        qx = x + tau * (vx * inv_s + wy - wz * y)
        qy = y + tau * (vy * inv_s + wz * x - wx)
        qz = 1.0 + tau * (vz * inv_s + wx * y - wy * x)
        qz = np.maximum(qz, 0.05)
        return (qx / qz - x) * self.focal_px, (qy / qz - y) * self.focal_px

    def blur_length_px(self, motion: Motion) -> float:
        """The longest image path of a point during one row's exposure (pixels)."""
        half = self.model.exposure_s / 2.0
        ax, ay = self._shift(motion, self.grid_tau - half)
        bx, by = self._shift(motion, self.grid_tau + half)
        return float(np.max(np.hypot(bx - ax, by - ay)))

    def maps(self, motion: Motion, tau_offset: float) -> tuple[np.ndarray, np.ndarray]:
        """Full-size remap maps for rows read at ``tau_i + tau_offset``."""
        sx, sy = self._shift(motion, self.grid_tau + tau_offset)
        size = (self.model.width, self.model.height)
        dx = cv2.resize(sx.astype(np.float32), size, interpolation=cv2.INTER_LINEAR)
        dy = cv2.resize(sy.astype(np.float32), size, interpolation=cv2.INTER_LINEAR)
        return self.map_x + dx, self.map_y + dy

    def apply(self, render: np.ndarray, motion: Motion, frame_number: int) -> np.ndarray:
        """The camera's output frame (H x W x 3 uint8) from the wide render."""
        model = self.model
        moving = any(abs(c) > 1e-9 for c in (*motion.omega_rad_s, *motion.velocity_m_s))
        if not moving or (model.exposure_s == 0.0 and model.line_time_s == 0.0):
            image = cv2.remap(render, *self.fixed_maps, cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REPLICATE)
        else:
            samples = 1
            if model.exposure_s > 0.0:
                samples = min(MAX_BLUR_SAMPLES, max(1, math.ceil(self.blur_length_px(motion))))
            acc: np.ndarray | None = None
            for i in range(samples):
                offset = model.exposure_s * ((i + 0.5) / samples - 0.5)
                mx, my = self.maps(motion, offset)
                warped = cv2.remap(render, mx, my, cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_REPLICATE)
                if samples == 1:
                    acc = warped.astype(np.float32)
                elif acc is None:
                    acc = warped.astype(np.float32)
                else:
                    cv2.accumulate(warped, acc)
            assert acc is not None
            image = np.clip(acc / samples + 0.5, 0, 255).astype(np.uint8)
        if model.noisy:
            image = self.add_noise(image, frame_number)
        if model.jpeg_quality:
            ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, model.jpeg_quality])
            decoded = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if ok else None
            if decoded is not None:
                image = decoded
        return image

    def add_noise(self, image: np.ndarray, frame_number: int) -> np.ndarray:
        """Shot and read noise (EMVA 1288), deterministic in (noise_seed, frame_number)."""
        n = image.size
        if self._bank is None or self._bank.size < n + _BANK_SPARE:
            rng = np.random.default_rng(self.model.noise_seed)
            self._bank = rng.standard_normal(n + _BANK_SPARE, dtype=np.float32)
        offset = int(np.random.default_rng((self.model.noise_seed, frame_number))
                     .integers(0, _BANK_SPARE))
        noise = self._bank[offset:offset + n].reshape(image.shape)
        sigma = cv2.LUT(image, self.sigma_lut.reshape(1, 256))
        # float noise onto the 8-bit image, rounded and saturated to 0..255
        return cv2.add(image, cv2.multiply(sigma, noise), dtype=cv2.CV_8U)


def distort(model: CameraModel, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's Brown-Conrady distortion of normalised coordinates."""
    k1, k2, p1, p2, k3 = model.dist_coeffs
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


def undistort(model: CameraModel, pixels: np.ndarray, iterations: int = 40) -> np.ndarray:
    """Undistorted normalised coordinates (N x 2) of distorted pixel positions (N x 2):
    OpenCV's fixed-point iteration (as ``cv2.undistortPoints``), run to convergence."""
    xd = (pixels[:, 0].astype(np.float64) - model.cx_px) / model.fx_px
    yd = (pixels[:, 1].astype(np.float64) - model.cy_px) / model.fy_px
    x, y = xd.copy(), yd.copy()
    if not model.distorted:
        return np.stack([x, y], axis=1)
    k1, k2, p1, p2, k3 = model.dist_coeffs
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        x = (xd - 2.0 * p1 * x * y - p2 * (r2 + 2.0 * x * x)) / radial
        y = (yd - p1 * (r2 + 2.0 * y * y) - 2.0 * p2 * x * y) / radial
    return np.stack([x, y], axis=1)
