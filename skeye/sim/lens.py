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
  Each sample's map is converted to OpenCV's fixed-point form before its remap (half the cost
  of a remap through float maps).
* Exposure and vignetting: the remapped signal is multiplied, in one pass, by the frame's
  brightness (its exposure time and gain against the model's nominal ones:
  :mod:`skeye.sim.exposure`, auto-exposure) and by the lens's relative illumination
  ``cos^n`` of each pixel's field angle; the frame's mean luma is metered here, before noise.
* Noise: EMVA 1288's photon-transfer model, ``var(DN) = K * mean(DN) + K^2 sigma_d^2`` with
  ``K = system_gain_dn_per_e * gain`` (the frame's gain), drawn from a seeded bank of normal
  deviates (a frame's offset into the bank comes from the seed and the frame number:
  deterministic).
* Output: JPEG-coded (from BGR, as a camera's encoder codes its YCbCr) and decoded at
  ``jpeg_quality`` (the webcam's MJPEG), else raw; the JPEG bytes are kept with the frame, so
  an image-server client asking for JPEG at the camera's quality gets the camera's own stream.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from skeye.robots.camera_model import CameraModel
from skeye.sim.exposure import Exposure, nominal

_CV: Any = cv2  # for calls the OpenCV stubs do not describe (a None second map)
_LUMA_RGB = np.array([0.299, 0.587, 0.114], dtype=np.float32)
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
        self.map_xy = np.ascontiguousarray(np.stack([self.map_x, self.map_y], axis=2))
        # Relative illumination cos^n of each pixel's field angle (cos = 1 / |(x, y, 1)|).
        self.vignetting: np.ndarray | None = None
        if model.vignetting_exponent > 0.0:
            r2 = self.ray_x.astype(np.float64) ** 2 + self.ray_y.astype(np.float64) ** 2
            fall = (1.0 + r2) ** (-model.vignetting_exponent / 2.0)
            self.vignetting = np.repeat(fall[:, :, None], 3, axis=2).astype(np.float32)
        # The coarse grid of the motion term, at cv2.resize's sample positions.
        gw, gh = max(2, w // _GRID_STEP_PX), max(2, h // _GRID_STEP_PX)
        gu = (np.arange(gw) + 0.5) * (w / gw) - 0.5
        gv = (np.arange(gh) + 0.5) * (h / gh) - 0.5
        guu, gvv = np.meshgrid(gu, gv)
        grays = undistort(model, np.stack([guu.ravel(), gvv.ravel()], axis=1))
        self.grid_x = grays[:, 0].reshape(gh, gw)
        self.grid_y = grays[:, 1].reshape(gh, gw)
        self.grid_tau = np.repeat(((gv - (h - 1) / 2.0) * model.line_time_s)[:, None], gw, axis=1)
        self._luts: dict[float, np.ndarray] = {}
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

    def blur_length_px(self, motion: Motion, exposure_s: float | None = None) -> float:
        """The longest image path of a point during one row's exposure (pixels); the model's
        exposure time unless given (auto-exposure varies it)."""
        half = (self.model.exposure_s if exposure_s is None else exposure_s) / 2.0
        ax, ay = self._shift(motion, self.grid_tau - half)
        bx, by = self._shift(motion, self.grid_tau + half)
        return float(np.max(np.hypot(bx - ax, by - ay)))

    def maps(self, motion: Motion, tau_offset: float) -> tuple[np.ndarray, np.ndarray]:
        """Full-size remap maps (x, y) for rows read at ``tau_i + tau_offset``."""
        xy = self._maps_xy(motion, tau_offset)
        return xy[..., 0], xy[..., 1]

    def _maps_xy(self, motion: Motion, tau_offset: float) -> np.ndarray:
        """:meth:`maps` as one two-channel map (what cv2.remap and cv2.convertMaps take)."""
        sx, sy = self._shift(motion, self.grid_tau + tau_offset)
        grid = np.stack([sx, sy], axis=2).astype(np.float32)
        shift = cv2.resize(grid, (self.model.width, self.model.height),
                           interpolation=cv2.INTER_LINEAR)
        return cv2.add(self.map_xy, shift)

    def apply(self, render: np.ndarray, motion: Motion, frame_number: int,
              exposure: Exposure | None = None, render_gain: float = 1.0) -> np.ndarray:
        """The camera's output frame (H x W x 3 uint8, RGB) from the wide render."""
        return self.process(render, motion, frame_number, exposure, render_gain).rgb

    def process(self, render: np.ndarray, motion: Motion, frame_number: int,
                exposure: Exposure | None = None, render_gain: float = 1.0,
                stream: tuple[int, ...] = ()) -> LensOutput:
        """The frame from the wide render (RGB uint8) taken with ``exposure`` (the model's
        nominal settings if None); ``render_gain`` scales the render's values into signal
        (the simulator renders with dimmed lights for headroom, skeye.sim.cameras);
        ``stream``: the camera's own noise (:meth:`add_noise`)."""
        model = self.model
        if exposure is None:
            exposure = nominal(model)
        moving = any(abs(c) > 1e-9 for c in (*motion.omega_rad_s, *motion.velocity_m_s))
        scale = exposure.brightness * render_gain
        if not moving or (exposure.exposure_s == 0.0 and model.line_time_s == 0.0):
            image = cv2.remap(render, *self.fixed_maps, cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REPLICATE)
            image = self._gain(image, scale)
        else:
            samples = 1
            if exposure.exposure_s > 0.0:
                blur = self.blur_length_px(motion, exposure.exposure_s)
                samples = min(MAX_BLUR_SAMPLES, max(1, math.ceil(blur)))
            acc: np.ndarray | None = None
            for i in range(samples):
                offset = exposure.exposure_s * ((i + 0.5) / samples - 0.5)
                # one two-channel float map, to OpenCV's fixed-point maps (the stubs want two)
                maps = _CV.convertMaps(self._maps_xy(motion, offset), None, cv2.CV_16SC2)
                warped = cv2.remap(render, maps[0], maps[1], cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_REPLICATE)
                if samples == 1:
                    acc = warped
                elif acc is None:
                    acc = warped.astype(np.float32)
                else:
                    cv2.accumulate(warped, acc)
            assert acc is not None
            image = self._gain(acc, scale / samples)
        # The mean luma (Y of JPEG's YCbCr, ITU-R BT.601 weights, RGB order) auto-exposure
        # meters, on every 4th pixel of every 4th row.
        mean_dn = float(np.mean(image[::4, ::4].reshape(-1, 3) @ _LUMA_RGB))
        if model.noisy:
            image = self.add_noise(image, frame_number, exposure.gain, stream)
        jpeg: bytes | None = None
        if model.jpeg_quality:
            bgr = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
            ok, data = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, model.jpeg_quality])
            decoded = cv2.imdecode(data, cv2.IMREAD_COLOR_RGB) if ok else None
            if decoded is not None:
                image = decoded
                jpeg = data.tobytes()
        return LensOutput(image, jpeg, mean_dn)

    def _gain(self, image: np.ndarray, scale: float) -> np.ndarray:
        """``image * scale * vignetting``, rounded and saturated to uint8 (one pass)."""
        if self.vignetting is not None:
            return cv2.multiply(image, self.vignetting, scale=scale, dtype=cv2.CV_8U)
        if scale == 1.0 and image.dtype == np.uint8:
            return image
        return cv2.convertScaleAbs(image, alpha=scale)

    def add_noise(self, image: np.ndarray, frame_number: int, gain: float | None = None,
                  stream: tuple[int, ...] = ()) -> np.ndarray:
        """Shot and read noise (EMVA 1288) at ``gain`` (the model's if None), deterministic in
        (noise_seed, stream, frame_number). The lens is shared by every camera of its model:
        ``stream`` (whole numbers >= 0, none by default) tells one camera's noise from
        another's (:attr:`skeye.sim.cameras.CameraSpec.noise_stream`)."""
        n = image.size
        if self._bank is None or self._bank.size < n + _BANK_SPARE:
            rng = np.random.default_rng(self.model.noise_seed)
            self._bank = rng.standard_normal(n + _BANK_SPARE, dtype=np.float32)
        offset = int(np.random.default_rng((self.model.noise_seed, *stream, frame_number))
                     .integers(0, _BANK_SPARE))
        noise = self._bank[offset:offset + n].reshape(image.shape)
        sigma = cv2.LUT(image, self._sigma_lut(self.model.gain if gain is None else gain))
        # float noise onto the 8-bit image, rounded and saturated to 0..255
        return cv2.add(image, cv2.multiply(sigma, noise), dtype=cv2.CV_8U)

    def _sigma_lut(self, gain: float) -> np.ndarray:
        """The noise's standard deviation (DN) at each level 0..255, at ``gain``."""
        lut = self._luts.get(gain)
        if lut is None:
            k = self.model.system_gain_dn_per_e * gain
            levels = np.arange(256, dtype=np.float64)
            lut = np.sqrt(k * levels + (k * self.model.read_noise_e) ** 2).astype(np.float32)
            lut = lut.reshape(1, 256)
            if len(self._luts) > 64:
                self._luts.clear()
            self._luts[gain] = lut
        return lut


@dataclass(frozen=True, eq=False)
class LensOutput:
    """One processed frame: its pixels (RGB), the MJPEG bytes they were decoded from (None
    for a raw camera) and the mean level auto-exposure metered (DN, before noise)."""

    rgb: np.ndarray
    jpeg: bytes | None
    mean_dn: float


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
