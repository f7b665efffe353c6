"""Pinhole camera model, frames, and an exact synthetic renderer of the pad for tests.

How this works: a camera is its resolution and its horizontal field of view as a float in
radians (the USARSim convention); the focal length in pixels follows, and nothing is rounded
(the paper's 2-5 % height error came from an integer field of view).

Pixel convention (OpenCV index coordinates): the pixel with index (u, v) (column u, row v) has
its centre at the point (u, v) and covers [u-0.5, u+0.5) x [v-0.5, v+0.5). The principal point
is the image centre, ((W-1)/2, (H-1)/2).

Frames:

- camera frame C (OpenCV): x = image right, y = image down, z = optical axis.
- body frame B (FRD): x forward, y right, z down. The camera looks straight down: image up is
  body forward, image right is body right, the optical axis is body down
  (:data:`DOWNWARD_CAMERA_TO_BODY`).
- level frame L: the camera frame with the vehicle's roll and pitch removed (yaw kept). Its z
  axis is vertical (down), its x/y axes lie in the pad plane, along image right/down of a
  level camera. "Offset at the pad plane" always means x/y of the pad centre in L, in metres;
  the height is its z.

Attitude: roll about body x, pitch about body y, ZYX order (yaw, then pitch, then roll), so a
body vector v maps to the level (yaw-aligned) body frame as ``Ry(pitch) @ Rx(roll) @ v``.
Positive pitch is nose up: the belly, and with it the downward camera's axis, swings forward,
so a pad straight below the vehicle appears below the image centre. Positive roll is right
wing down: the axis swings left, and the pad straight below appears right of the centre.

Renderer: :func:`render_pad_view` maps every (super)sample's ray to the pad plane and evaluates
the pattern there analytically, so the image is exact for the pinhole model, tilt included; its
only approximation is the pixel-area integral by ``supersample``^2 samples.
"""

from __future__ import annotations

import math
import numbers

import cv2
import numpy as np

from skeye.errors import LocalProtocolError
from skeye.vision.pad import PadDefinition

#: Rotation camera -> body for the default downward camera (columns: camera axes in body).
DOWNWARD_CAMERA_TO_BODY = np.array(
    (
        (0.0, -1.0, 0.0),
        (1.0, 0.0, 0.0),
        (0.0, 0.0, 1.0),
    )
)


def _check_fov(fov_h_rad: float) -> float:
    """The field of view as a float; any real number (numpy's included), not a bool."""
    if isinstance(fov_h_rad, bool) or not isinstance(fov_h_rad, numbers.Real):
        # (said as "must be in (0, pi) rad, got 1.3" for the string "1.3")
        raise LocalProtocolError(f"horizontal field of view must be a number of radians, got "
                                 f"{type(fov_h_rad).__name__} {fov_h_rad!r}")
    if not 0.0 < fov_h_rad < math.pi:
        raise LocalProtocolError(
            f"horizontal field of view must be in (0, pi) rad, got {fov_h_rad}"
        )
    return float(fov_h_rad)


def focal_length_px(width_px: int, fov_h_rad: float) -> float:
    """Focal length in pixels: ``(width / 2) / tan(fov_h / 2)``, never rounded."""
    fov = _check_fov(fov_h_rad)
    if width_px <= 0:
        raise LocalProtocolError(f"image width must be positive, got {width_px}")
    half_tan = math.tan(fov / 2.0)
    f = (width_px / 2.0) / half_tan if half_tan > 0.0 else math.inf
    if not math.isfinite(f):  # heights and offsets would come out inf and nan
        raise LocalProtocolError(
            f"horizontal field of view {fov_h_rad} rad is too small: the focal length of a "
            f"{width_px} px wide image overflows")
    return f


def fov_v_rad(width_px: int, height_px: int, fov_h_rad: float) -> float:
    """Vertical field of view from the horizontal one and the aspect ratio (square pixels)."""
    if height_px <= 0:
        raise LocalProtocolError(f"image height must be positive, got {height_px}")
    return 2.0 * math.atan(height_px / 2.0 / focal_length_px(width_px, fov_h_rad))


def principal_point_px(width_px: int, height_px: int) -> tuple[float, float]:
    """Image centre in OpenCV index coordinates: ((W-1)/2, (H-1)/2)."""
    return ((width_px - 1) / 2.0, (height_px - 1) / 2.0)


def intrinsics(width_px: int, height_px: int, fov_h_rad: float) -> np.ndarray:
    """The 3x3 camera matrix K."""
    f = focal_length_px(width_px, fov_h_rad)
    cx, cy = principal_point_px(width_px, height_px)
    return np.array(((f, 0.0, cx), (0.0, f, cy), (0.0, 0.0, 1.0)))


def body_to_level(roll_rad: float, pitch_rad: float) -> np.ndarray:
    """Rotation body FRD -> level yaw-aligned body frame: ``Ry(pitch) @ Rx(roll)`` (ZYX)."""
    cr, sr = math.cos(roll_rad), math.sin(roll_rad)
    cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
    rx = np.array(((1.0, 0.0, 0.0), (0.0, cr, -sr), (0.0, sr, cr)))
    ry = np.array(((cp, 0.0, sp), (0.0, 1.0, 0.0), (-sp, 0.0, cp)))
    return ry @ rx


def camera_to_level(
    roll_rad: float, pitch_rad: float, camera_to_body: np.ndarray = DOWNWARD_CAMERA_TO_BODY
) -> np.ndarray:
    """Rotation camera C -> level camera L (the camera as it would be with roll = pitch = 0)."""
    return camera_to_body.T @ body_to_level(roll_rad, pitch_rad) @ camera_to_body


def level_homography(
    width_px: int, height_px: int, fov_h_rad: float, roll_rad: float, pitch_rad: float
) -> np.ndarray:
    """Pure-rotation homography ``K R K^-1`` from image pixels to a virtual level camera's.

    In the level image the pad plane is parallel to the image plane, so circles stay circles
    and their centres are the projections of the pad's centre.
    """
    k = intrinsics(width_px, height_px, fov_h_rad)
    return k @ camera_to_level(roll_rad, pitch_rad) @ np.linalg.inv(k)


def level_offset_to_body(offset_level_m: tuple[float, float]) -> tuple[float, float]:
    """(x right, y down) in the level camera frame -> (forward, right) in the level body frame.

    Uses the downward mount: image up is body forward.
    """
    x, y = offset_level_m
    return (-y, x)


def render_pad_view(
    pad: PadDefinition,
    width: int,
    height: int,
    fov_h_rad: float,
    height_m: float,
    offset_m: tuple[float, float] = (0.0, 0.0),
    roll_rad: float = 0.0,
    pitch_rad: float = 0.0,
    yaw_rad: float = 0.0,
    supersample: int = 3,
    noise_sigma: float = 0.0,
    blur_px: float = 0.0,
    background: float | np.ndarray = 128.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Render what the downward camera sees of a pad lying flat below it (uint8 grey).

    Args:
        pad: the pad (black square, white rings; outside the square is ``background``).
        width, height: image size in pixels.
        fov_h_rad: horizontal field of view.
        height_m: height of the camera's centre above the pad plane.
        offset_m: the pad centre relative to the point straight below the camera, in the level
            frame L (x = image right, y = image down of the level camera), metres. With
            roll = pitch = 0 this is the offset from the camera axis at the pad plane.
        roll_rad, pitch_rad: vehicle attitude, body FRD, ZYX (see the module docstring).
        yaw_rad: the vehicle's heading relative to the pad's edges: rotates the pad square
            about its centre (the rings are symmetric; L is yaw-aligned).
        supersample: samples per pixel along each axis, averaged (pixel-area integral).
        noise_sigma: standard deviation of added Gaussian noise, in grey levels; needs ``rng``.
        blur_px: standard deviation of a Gaussian blur, in pixels (applied before noise).
        background: a grey level, or a (height, width) uint8/float image, for everything
            outside the pad square (and above the horizon).
        rng: the random generator for the noise.
    """
    if width < 2 or height < 2:
        raise LocalProtocolError(f"image must be at least 2x2 pixels, got {width}x{height}")
    if height_m <= 0:
        raise LocalProtocolError(f"height must be positive, got {height_m} m")
    if supersample < 1:
        raise LocalProtocolError(f"supersample must be >= 1, got {supersample}")
    if noise_sigma < 0 or blur_px < 0:
        raise LocalProtocolError("noise_sigma and blur_px must be >= 0")
    if noise_sigma > 0 and rng is None:
        raise LocalProtocolError("noise_sigma > 0 needs a seeded rng")
    bg = np.asarray(background, dtype=np.float32)
    if bg.ndim == 2 and bg.shape != (height, width):
        raise LocalProtocolError(f"background image must be {height}x{width}, got {bg.shape}")
    if bg.ndim not in (0, 2):
        raise LocalProtocolError("background must be a grey level or a greyscale image")

    k_inv = np.linalg.inv(intrinsics(width, height, fov_h_rad))
    m = (camera_to_level(roll_rad, pitch_rad) @ k_inv).astype(np.float32)  # pixel -> L ray
    s = supersample
    sub = (np.arange(s, dtype=np.float32) + 0.5) / s - 0.5
    us = (np.arange(width, dtype=np.float32)[:, None] + sub[None, :]).reshape(1, -1)
    vs = (np.arange(height, dtype=np.float32)[:, None] + sub[None, :]).reshape(-1, 1)
    # Rows of the super-sampled grid: vs varies down, us across (pixel-major, sub-sample minor).
    dz = m[2, 0] * us + m[2, 1] * vs + m[2, 2]
    ground = dz > 1e-6
    t = np.float32(height_m) / np.where(ground, dz, np.float32(1.0))
    cyaw, syaw = math.cos(yaw_rad), math.sin(yaw_rad)
    # Pad coordinates (rotated by -yaw about the pad centre) of each sample's ground point.
    a = (cyaw * m[0] + syaw * m[1]).astype(np.float32)
    b = (-syaw * m[0] + cyaw * m[1]).astype(np.float32)
    ox = np.float32(cyaw * offset_m[0] + syaw * offset_m[1])
    oy = np.float32(-syaw * offset_m[0] + cyaw * offset_m[1])
    qx = (a[0] * us + a[1] * vs + a[2]) * t - ox
    qy = (b[0] * us + b[1] * vs + b[2]) * t - oy
    del t, dz
    half = np.float32(pad.side_m / 2.0)
    inside = ground & (np.abs(qx) < half) & (np.abs(qy) < half)
    r2 = qx * qx + qy * qy
    del qx, qy
    # Border radii squared, ascending: a sample is white when an odd number of borders lie at
    # or below its radius (inner border inclusive, outer border exclusive).
    edges = np.array(
        sorted(x * x for ring in pad.rings for x in (ring.inner_m, ring.outer_m)), dtype=np.float32
    )
    white = (np.searchsorted(edges, r2, side="right") % 2 == 1) & inside
    # Box average over each pixel's sub-samples (INTER_AREA with an integer factor is exact).
    size = (width, height)
    frac_white = cv2.resize(white.astype(np.float32), size, interpolation=cv2.INTER_AREA)
    frac_bg = 1.0 - cv2.resize(inside.astype(np.float32), size, interpolation=cv2.INTER_AREA)
    img = 255.0 * frac_white.astype(np.float64) + bg.astype(np.float64) * frac_bg
    if blur_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), sigmaX=blur_px, sigmaY=blur_px)
    if noise_sigma > 0:
        assert rng is not None
        img = img + rng.normal(0.0, noise_sigma, size=img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)
