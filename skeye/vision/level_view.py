"""The pad detector's geometry: the level view, sub-pixel border points and circle fits.

How this works: :class:`LevelView` holds one frame's grey image and the pure-rotation
homography ``K R K^-1`` into a virtual level camera (roll and pitch removed); ``sample`` reads
the image bilinearly. :func:`edge_points` casts rays across a predicted border in the level
view and returns where the grey profile crosses the mid-level between its local black and
white, with the right polarity; :func:`fit_circles` fits circles to many point sets at once;
:func:`conic_ellipse` maps a level-view circle back to its image ellipse. The search that uses
them is :mod:`skeye.vision.detector`.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from skeye.errors import LocalProtocolError
from skeye.vision.calibration import CameraCalibration, undistort_points
from skeye.vision.camera import (
    camera_to_level,
    focal_length_px,
    intrinsics,
    principal_point_px,
)

MIN_CONTRAST = 30.0  # grey levels between a border's black and white along a ray
SAMPLES_PER_RAY = 13
STEP_FRACTION = 0.5  # of the local contrast, between the two halves of a ray's window


_OUTSIDE = -1.0e4  # an image coordinate far outside any frame


class LevelView:
    """One frame's image and camera geometry; maps between image and level-view pixels.

    Without a calibration the camera is the ideal pinhole of ``fov_h_rad`` (the simulator's)
    and the level view is the homography ``K R K^-1`` of the image. With one, the level view is
    an undistorted pinhole camera with the calibration's principal point and square pixels of
    focal length ``fx``: image points go there by ``cv2.undistortPoints`` (with the level
    rotation), level points come back through OpenCV's forward distortion model - only the
    points the detector looks at, never the whole image.
    """

    def __init__(self, grey: np.ndarray, fov_h_rad: float, roll: float, pitch: float, tilt: bool,
                 calibration: CameraCalibration | None = None):
        self.grey = grey
        self.flat = grey.reshape(-1)
        self.h, self.w = grey.shape
        self.cal = calibration
        self.hom: np.ndarray | None = None  # image -> level (pinhole camera with tilt only)
        self.hom_inv: np.ndarray | None = None
        if calibration is not None:
            calibration.check_size(self.w, self.h)
            self.f = calibration.fx
            self.cx, self.cy = calibration.cx, calibration.cy
            rot = camera_to_level(roll, pitch) if tilt else np.eye(3)
            k_level = np.array(((self.f, 0.0, self.cx), (0.0, self.f, self.cy), (0.0, 0.0, 1.0)))
            self._rot = rot
            self._k_level = k_level
            self._k = calibration.camera_matrix()
            self._dist = calibration.dist_coeffs()
            self._level_to_ray = rot.T @ np.linalg.inv(k_level)
            self._r_max = calibration.max_radius()
            return
        self.f = focal_length_px(self.w, fov_h_rad)
        self.cx, self.cy = principal_point_px(self.w, self.h)
        if tilt:
            k = intrinsics(self.w, self.h, fov_h_rad)
            hom = k @ camera_to_level(roll, pitch) @ np.linalg.inv(k)
            self.hom = hom
            self.hom_inv = np.linalg.inv(hom)

    @staticmethod
    def _apply(hom: np.ndarray | None, x: np.ndarray, y: np.ndarray) -> tuple[Any, Any]:
        if hom is None:
            return x, y
        w = hom[2, 0] * x + hom[2, 1] * y + hom[2, 2]
        return (
            (hom[0, 0] * x + hom[0, 1] * y + hom[0, 2]) / w,
            (hom[1, 0] * x + hom[1, 1] * y + hom[1, 2]) / w,
        )

    def to_level(self, x: np.ndarray, y: np.ndarray) -> tuple[Any, Any]:
        if self.cal is None:
            return self._apply(self.hom, x, y)
        xa, ya = np.asarray(x, np.float64), np.asarray(y, np.float64)
        pts = np.stack((xa.ravel(), ya.ravel()), axis=1).reshape(-1, 1, 2)
        out = undistort_points(pts, self._k, self._dist, self._rot, self._k_level).reshape(-1, 2)
        return out[:, 0].reshape(xa.shape), out[:, 1].reshape(ya.shape)

    def to_image(self, x: np.ndarray, y: np.ndarray) -> tuple[Any, Any]:
        if self.cal is None:
            return self._apply(self.hom_inv, x, y)
        m = self._level_to_ray
        xa, ya = np.asarray(x, np.float64), np.asarray(y, np.float64)
        z = m[2, 0] * xa + m[2, 1] * ya + m[2, 2]
        front = z > 1e-9
        z = np.where(front, z, 1.0)
        xn = (m[0, 0] * xa + m[0, 1] * ya + m[0, 2]) / z
        yn = (m[1, 0] * xa + m[1, 1] * ya + m[1, 2]) / z
        # Past the radius where the distortion polynomial folds back, a ray is not in the image.
        valid = front & (xn * xn + yn * yn < self._r_max * self._r_max)
        u, v = self.cal.distort_normalized(np.where(valid, xn, 0.0), np.where(valid, yn, 0.0))
        return np.where(valid, u, _OUTSIDE), np.where(valid, v, _OUTSIDE)

    def image_ellipse(
        self, cx: float, cy: float, r: float
    ) -> tuple[tuple[float, float], tuple[float, float], float]:
        """The image ellipse of a level-view circle: centre, (major, minor) semi-axes, angle.

        Exact (a conic) for the pinhole camera; with lens distortion the image curve is no
        ellipse, and this is the least-squares ellipse through 72 of its points.
        """
        if self.cal is None:
            return conic_ellipse(self.hom, cx, cy, r)
        t = np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)
        u, v = self.to_image(cx + r * np.cos(t), cy + r * np.sin(t))
        seen = u > _OUTSIDE / 2  # points past the lens's valid radius do not count
        if seen.sum() < 6:
            cu, cv_ = self.to_image(np.array(cx), np.array(cy))
            return (float(cu), float(cv_)), (r, r), 0.0
        pts = np.column_stack((u[seen], v[seen])).astype(np.float32)
        (ex, ey), (a, b), deg = cv2.fitEllipse(pts)
        angle = math.radians(deg) if a >= b else math.radians(deg) + math.pi / 2.0
        return (float(ex), float(ey)), (max(a, b) / 2.0, min(a, b) / 2.0), angle % math.pi

    def sample(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bilinear grey values at image points (float), and whether each point is inside."""
        inside = (x >= 0) & (x <= self.w - 1) & (y >= 0) & (y <= self.h - 1)
        xc = np.clip(x, 0, self.w - 1)
        yc = np.clip(y, 0, self.h - 1)
        x0 = np.minimum(xc.astype(np.intp), self.w - 2)
        y0 = np.minimum(yc.astype(np.intp), self.h - 2)
        fx = xc - x0
        fy = yc - y0
        i = y0 * self.w + x0
        f = self.flat
        top = f[i] * (1.0 - fx) + f[i + 1] * fx
        bot = f[i + self.w] * (1.0 - fx) + f[i + self.w + 1] * fx
        return top * (1.0 - fy) + bot * fy, inside


_RAY_CACHE: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def ray_dirs(n: int) -> tuple[np.ndarray, np.ndarray]:
    if n not in _RAY_CACHE:
        t = np.arange(n) * (2.0 * math.pi / n)
        _RAY_CACHE[n] = (np.cos(t).astype(np.float32), np.sin(t).astype(np.float32))
    return _RAY_CACHE[n]


_RAY_STEPS = np.linspace(-1.0, 1.0, SAMPLES_PER_RAY)
_RAY_INDEX = np.arange(SAMPLES_PER_RAY - 1, dtype=np.float32)


def edge_points(
    view: LevelView,
    centres: np.ndarray,
    radii_px: np.ndarray,
    polarity: np.ndarray,
    halfwidth_px: np.ndarray,
    n_rays: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sub-pixel border crossings along rays from each border's centre (level view).

    ``centres`` is (B, 2), the other arrays (B,). Returns level-view points (B, n_rays, 2) and
    a validity mask (B, n_rays).
    """
    cos_t, sin_t = ray_dirs(n_rays)
    k = SAMPLES_PER_RAY
    b = len(radii_px)
    t = _RAY_STEPS
    rad = (radii_px[:, None] + halfwidth_px[:, None] * t[None, :]).astype(np.float32)  # (B,K)
    ccx = centres[:, 0, None, None].astype(np.float32)
    ccy = centres[:, 1, None, None].astype(np.float32)
    lx = ccx + rad[:, None, :] * cos_t[None, :, None]  # (B,N,K)
    ly = ccy + rad[:, None, :] * sin_t[None, :, None]
    ix, iy = view.to_image(lx, ly)
    ix = np.asarray(ix, dtype=np.float32).reshape(b * n_rays, k)
    iy = np.asarray(iy, dtype=np.float32).reshape(b * n_rays, k)
    # Bilinear sampling (OpenCV's fixed-point weights: 1/32 px, far below our error budget).
    prof = cv2.remap(view.grey, ix, iy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    # A homography maps segments to segments: a ray is inside when both its ends are.
    ends_x = ix[:, :: k - 1]
    ends_y = iy[:, :: k - 1]
    inside = ((ends_x >= 0) & (ends_y >= 0) & (ends_x <= view.w - 1) & (ends_y <= view.h - 1)).all(
        axis=1
    )
    lo = prof.min(axis=1)
    hi = prof.max(axis=1)
    midlevel = 0.5 * (lo.astype(np.float32) + hi)
    pol = np.repeat(polarity.astype(np.float32), n_rays)
    d = (prof - midlevel[:, None]) * pol[:, None]
    d0 = d[:, :-1]
    d1 = d[:, 1:]
    cross = (d0 < 0) & (d1 >= 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        pos = _RAY_INDEX + d0 / (d0 - d1)
    mid = (k - 1) / 2.0
    dist = np.where(cross, np.abs(pos - mid), np.float32(np.inf))
    j = np.argmin(dist, axis=1)
    rows = np.arange(b * n_rays)
    best = pos[rows, j]
    # A real border is a step: the two halves of the window differ by most of the contrast,
    # with the right sign. Texture and noise cross the mid-level too, but are no step.
    half = k // 2
    rise = (
        prof[:, half + 1 :].mean(axis=1, dtype=np.float32)
        - prof[:, :half].mean(axis=1, dtype=np.float32)
    ) * pol
    contrast = hi.astype(np.float32) - lo
    ok = inside & cross[rows, j] & (contrast >= MIN_CONTRAST) & (rise >= STEP_FRACTION * contrast)
    best = np.where(ok, best, mid)
    step = 2.0 * halfwidth_px / (k - 1)
    r_edge = radii_px[:, None] + (best.reshape(b, n_rays) - mid) * step[:, None]
    pts = np.empty((b, n_rays, 2))
    pts[..., 0] = centres[:, 0, None] + r_edge * cos_t
    pts[..., 1] = centres[:, 1, None] + r_edge * sin_t
    return pts, ok.reshape(b, n_rays), inside.reshape(b, n_rays)


def fit_circles(
    pts: np.ndarray, ok: np.ndarray, ref: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Algebraic (Kasa) circle fits of many point sets at once.

    ``pts`` (B, N, 2) with mask ``ok`` (B, N); ``ref`` (B, 2) a point near each centre (for
    conditioning). Returns centre x, centre y, radius and RMS radial residual, each (B,);
    radius 0 and RMS inf where a set has fewer than 5 points or is degenerate.
    """
    w = ok.astype(np.float64)
    x = (pts[..., 0] - ref[:, 0, None]) * w
    y = (pts[..., 1] - ref[:, 1, None]) * w
    z = x * x + y * y
    n = w.sum(axis=1)
    sx, sy, sz = x.sum(axis=1), y.sum(axis=1), z.sum(axis=1)
    sxx, syy, sxy = (x * x).sum(axis=1), (y * y).sum(axis=1), (x * y).sum(axis=1)
    a = np.empty((len(n), 3, 3))
    a[:, 0, 0], a[:, 0, 1], a[:, 0, 2] = sxx, sxy, sx
    a[:, 1, 0], a[:, 1, 1], a[:, 1, 2] = sxy, syy, sy
    a[:, 2, 0], a[:, 2, 1], a[:, 2, 2] = sx, sy, n
    rhs = np.stack(((x * z).sum(axis=1), (y * z).sum(axis=1), sz), axis=1)
    good = (n >= 5) & (np.abs(np.linalg.det(a)) > 1e-9)
    a[~good] = np.eye(3)
    sol = np.linalg.solve(a, rhs[..., None])[..., 0]
    cx = sol[:, 0] / 2.0
    cy = sol[:, 1] / 2.0
    r2 = sol[:, 2] + cx * cx + cy * cy
    good &= r2 > 0
    r = np.sqrt(np.where(good, r2, 0.0))
    res = (np.hypot(x - cx[:, None], y - cy[:, None]) - r[:, None]) * w
    with np.errstate(divide="ignore", invalid="ignore"):
        rms = np.sqrt((res * res).sum(axis=1) / n)
    rms = np.where(good, rms, np.inf)
    return cx + ref[:, 0], cy + ref[:, 1], r, rms


def conic_ellipse(
    hom: np.ndarray | None, cx: float, cy: float, r: float
) -> tuple[tuple[float, float], tuple[float, float], float]:
    """The image ellipse of a level-view circle: centre, (major, minor) semi-axes, angle."""
    if hom is None:
        return (cx, cy), (r, r), 0.0
    q = np.array(((1.0, 0.0, -cx), (0.0, 1.0, -cy), (-cx, -cy, cx * cx + cy * cy - r * r)))
    q = hom.T @ q @ hom
    a, b, c = float(q[0, 0]), float(q[0, 1]), float(q[1, 1])
    d, e, f = float(q[0, 2]), float(q[1, 2]), float(q[2, 2])
    det = a * c - b * b
    ex = (b * e - c * d) / det
    ey = (b * d - a * e) / det
    f0 = f + d * ex + e * ey
    # Eigenvalues of [[a, b], [b, c]]; the smaller one belongs to the major axis.
    mean = 0.5 * (a + c)
    half = math.hypot(0.5 * (a - c), b)
    lam_small, lam_big = mean - half, mean + half
    if f0 > 0:  # the conic may come out with either overall sign
        lam_small, lam_big, f0 = -lam_big, -lam_small, -f0
    major = math.sqrt(max(-f0 / lam_small, 0.0))
    minor = math.sqrt(max(-f0 / lam_big, 0.0))
    # Direction of the major axis: eigenvector of the smaller |eigenvalue|.
    angle = 0.5 * math.atan2(2.0 * b, a - c) + math.pi / 2.0
    angle %= math.pi
    return (ex, ey), (major, minor), angle


def to_grey(image: np.ndarray) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise LocalProtocolError(f"image must be a numpy array, got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise LocalProtocolError(f"image must be uint8, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 3 and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    elif image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY)
    elif image.ndim != 2:
        raise LocalProtocolError(
            f"image must be greyscale (H, W) or BGR (H, W, 3), got shape {image.shape}"
        )
    if image.shape[0] < 16 or image.shape[1] < 16:
        raise LocalProtocolError(
            f"image too small for detection: {image.shape[1]}x{image.shape[0]}"
        )
    return np.ascontiguousarray(image)
