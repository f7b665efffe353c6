"""Landing-pad detector: concentric rings -> pad centre, height and offset.

How this works:

1. **Level view.** With the vehicle's roll and pitch given, every image point used below is
   moved by the pure-rotation homography ``K R K^-1`` into a virtual level camera (same
   intrinsics, image plane parallel to the pad). There the rings are exact circles whose common
   centre is the projection of the pad's centre. Without roll and pitch the camera is taken as
   level (the homography is the identity). With a camera calibration (``skeye calibrate``) the
   level camera is the undistorted one: image points reach it through ``cv2.undistortPoints``
   and level points go back through the lens model, so only the points looked at are
   undistorted, never the whole image (:class:`skeye.vision.level_view.LevelView`).
2. **Coarse search.** The grey image is halved (area average), thresholded (Otsu; an adaptive
   threshold is tried when Otsu finds nothing), and its contours are taken with their two-level
   hierarchy. A white ring is a white component whose largest hole is a roughly concentric
   circle; components touching the image border are skipped here.
3. **Sub-pixel borders.** For each candidate, rays are cast from its centre across each border
   in the level view; the full-resolution grey profile is sampled along each ray (bilinear) and
   the border is where it crosses the mid-level between its local black and white, with the
   right polarity, nearest the expected radius. Circles are fitted to these points.
4. **Identification.** A ring is named by its inner/outer radius ratio (nearest ratio of the
   pad within a tolerance). Identified rings must be concentric and agree on the scale
   (pixels per metre); the largest agreeing group wins. From its centre and scale the other
   borders' radii are predicted and looked for along rays that stay inside the image, so rings
   cut by the image edge still count when both their borders are found where predicted (by at
   least half of those rays: motion blur wipes out the rays along the motion).
5. **Joint fit.** All border points of the identified rings are fitted together (Gauss-Newton)
   to concentric circles of radii ``s * r_m``: a common centre and one scale ``s``. Larger
   borders carry more weight, as they should (blur and pixel effects shrink small ones most).
   Height ``h = f / s`` (``f * r_m / r_px`` combined over all borders); the offset follows from
   the centre. One round of outlier rejection follows; a ring one of whose borders keeps fewer
   than five points after it (the outermost ring, seen only in the image's corners when the
   camera is low) leaves the fit instead of failing the detection. So does a ring one of whose
   borders disagrees with the joint fit (bias or scatter over its limit: blur shifts a thin
   ring's borders, a rolling shutter shears a large ring), the worst first, while two remain.
   With a camera calibration, a seed group that fails all this is fitted once more with a
   shear along the image rows (a rolling shutter during a sideways motion; at most
   ``_MAX_SHEAR``); without one that model is not tried, as an uncorrected lens makes
   off-centre rings look sheared.

The geometry of steps 1 and 3 (level view, border points, circle fits) is
:mod:`skeye.vision.level_view`.

Invariants: ``found`` needs at least two identified rings that pass every check; otherwise
the estimate says "not found" with all figures ``None`` - never a guess. Nothing is rounded.
"""

from __future__ import annotations

import itertools
import math
import numbers
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from skeye.errors import LocalProtocolError
from skeye.vision.calibration import CameraCalibration
from skeye.vision.camera import (
    level_offset_to_body,
)
from skeye.vision.level_view import (
    LevelView,
    edge_points,
    fit_circles,
    to_grey,
)
from skeye.vision.pad import SKEYE_4, PadDefinition

# Tunables (pixels are full-resolution pixels of the level view).
_MAX_BORDER_RMS_PX = 0.5  # scatter of one border's points about the joint fit
_BORDER_RMS_PER_PX = 0.006  # ... or this fraction of its radius, whichever is larger
_CANDIDATE_RAYS = 48
_FINAL_RAYS = 64
_MAX_CANDIDATES = 24
_MIN_RING_PX = 4.0  # outer radius below which a ring is not looked at
_MIN_BORDER_PX = 2.0  # predicted border radius below which it is not looked for
_CONFIRM_SHARE = 0.5  # of a border's in-image rays that must find it where predicted
_MAX_SHEAR = 0.05  # rolling-shutter shear accepted, px of row shift per row (30 px over 600)


@dataclass(frozen=True)
class BorderEllipse:
    """One identified ring border as it appears in the (possibly tilted) image."""

    ring: int  # 1 = outermost
    border: str  # "outer" or "inner"
    center_px: tuple[float, float]
    semi_axes_px: tuple[float, float]  # (major, minor)
    angle_rad: float  # of the major axis, from image +u towards +v

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "ring": self.ring,
            "border": self.border,
            "center_px": list(self.center_px),
            "semi_axes_px": list(self.semi_axes_px),
            "angle_rad": self.angle_rad,
        }


@dataclass(frozen=True)
class PadEstimate:
    """What one frame says about the pad.

    ``offset_cam_m`` is the pad centre's (x right, y down) offset from the point straight below
    the camera, at the pad plane, in the level camera frame (the camera frame itself when no
    roll/pitch was given); ``offset_body_m`` is the same offset as (forward, right) in the
    level, yaw-aligned body frame. ``height_m`` is the camera's height above the pad plane.
    """

    found: bool
    center_px: tuple[float, float] | None
    height_m: float | None
    offset_cam_m: tuple[float, float] | None
    offset_body_m: tuple[float, float] | None
    rings: tuple[int, ...]
    ellipses: tuple[BorderEllipse, ...]
    quality: float

    def to_json_dict(self) -> dict[str, Any]:
        """The docs/landing-pad.md command-line JSON form, plus ``offset_body_m``."""

        def pair(p: tuple[float, float] | None) -> list[float] | None:
            return None if p is None else [float(p[0]), float(p[1])]

        return {
            "found": self.found,
            "center_px": pair(self.center_px),
            "height_m": self.height_m,
            "offset_cam_m": pair(self.offset_cam_m),
            "offset_body_m": pair(self.offset_body_m),
            "rings": list(self.rings),
            "quality": self.quality,
        }


NOT_FOUND = PadEstimate(
    found=False,
    center_px=None,
    height_m=None,
    offset_cam_m=None,
    offset_body_m=None,
    rings=(),
    ellipses=(),
    quality=0.0,
)


@dataclass(frozen=True)
class _Border:
    ring: int  # 1-based
    outer: bool
    radius_m: float
    polarity: float  # +1: grey rises going outwards (black inside), -1: falls
    gap_m: float  # distance to the nearest other border (or the square's edge, or the centre)


def _pad_borders(pad: PadDefinition) -> list[_Border]:
    radii = sorted([x for r in pad.rings for x in (r.outer_m, r.inner_m)] + [pad.side_m / 2, 0.0])
    out = []
    for i, ring in enumerate(pad.rings, start=1):
        for outer, r in ((True, ring.outer_m), (False, ring.inner_m)):
            gap = min(abs(r - x) for x in radii if x != r)
            out.append(_Border(i, outer, r, -1.0 if outer else 1.0, gap))
    return out


def _adaptive(small: np.ndarray) -> np.ndarray:
    block = max(15, (min(small.shape) // 6) | 1)
    return cv2.adaptiveThreshold(
        small, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY, block, -8
    )


@dataclass
class _Candidate:
    cx: float
    cy: float
    r_outer: float
    r_inner: float


def _disc(
    view: LevelView, contour: np.ndarray, sx: float, sy: float
) -> tuple[float, float, float, float]:
    """A coarse contour's centre, equal-area radius and roundness, in level-view pixels.

    Roundness is the equal-area radius over half the larger extent (1 for a circle).
    """
    p = contour.reshape(-1, 2).astype(np.float64)
    lx, ly = view.to_level((p[:, 0] + 0.5) * sx - 0.5, (p[:, 1] + 0.5) * sy - 0.5)
    lp = np.column_stack((lx, ly)).astype(np.float32)
    m = cv2.moments(lp)
    area = abs(m["m00"])
    if area <= 0:
        return 0.0, 0.0, 0.0, 0.0
    r = math.sqrt(area / math.pi)
    _, _, bw, bh = cv2.boundingRect(lp)
    return m["m10"] / m["m00"], m["m01"] / m["m00"], r, 2.0 * r / max(bw, bh, 1e-9)


def _coarse_candidates(
    view: LevelView, binary: np.ndarray, scale_x: float, scale_y: float, tilt_known: bool
) -> list[_Candidate]:
    """Ring-like white components (one big, round, concentric hole) of the coarse image."""
    contours, hierarchy = cv2.findContours(binary, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    if hierarchy is None or not contours:
        return []
    hier = hierarchy[0]
    lens = np.fromiter((len(c) for c in contours), dtype=np.intp, count=len(contours))
    min_outer = max(8, int(2.0 * _MIN_RING_PX / max(scale_x, scale_y)))
    tops = np.nonzero((hier[:, 3] < 0) & (hier[:, 2] >= 0) & (lens >= min_outer))[0]
    if tops.size == 0:
        return []
    tops = tops[np.argsort(-lens[tops])][: 4 * _MAX_CANDIDATES]
    hs, ws = binary.shape
    out: list[_Candidate] = []
    min_round = 0.85 if tilt_known else 0.6
    for i in tops.tolist():
        bx, by, bw, bh = cv2.boundingRect(contours[i])
        if bx <= 0 or by <= 0 or bx + bw >= ws or by + bh >= hs:
            continue
        j = int(hier[i, 2])
        hole, hole_len = -1, 0
        while j >= 0:
            if lens[j] > hole_len:
                hole, hole_len = j, int(lens[j])
            j = int(hier[j, 0])
        if hole_len < 6:
            continue
        ox, oy, ro, round_o = _disc(view, contours[i], scale_x, scale_y)
        ix, iy, ri, round_i = _disc(view, contours[hole], scale_x, scale_y)
        # Pixel contours run along the white side of a border: half a coarse pixel inside the
        # outer border, outside the hole's.
        ro += 0.5 * scale_x
        ri -= 0.5 * scale_x
        if ro < _MIN_RING_PX or ri <= 0.5:
            continue
        if round_o < min_round or round_i < min_round - 0.15:
            continue
        if math.hypot(ox - ix, oy - iy) > 0.1 * ro + 1.5 * scale_x:
            continue
        if not 0.05 < ri / ro < 0.98:
            continue
        out.append(_Candidate(ox, oy, ro, ri))
        if len(out) >= _MAX_CANDIDATES:
            break
    return out


@dataclass
class _Ring:
    ring: int
    cx: float
    cy: float
    scale: float  # px per metre
    r_outer: float


def _identify(
    view: LevelView, cands: list[_Candidate], pad: PadDefinition, ratio_tol: float
) -> list[_Ring]:
    """Refine every candidate's two borders (one batch) and name its ring by the radius ratio."""
    if not cands:
        return []
    ro0 = np.array([c.r_outer for c in cands])
    ri0 = np.array([c.r_inner for c in cands])
    hw = np.clip(0.35 * (ro0 - ri0), 1.0, 5.0)
    centres = np.repeat(np.array([(c.cx, c.cy) for c in cands]), 2, axis=0)
    radii = np.column_stack((ro0, ri0)).reshape(-1)
    halfw = np.column_stack((hw, np.minimum(hw, 0.6 * ri0))).reshape(-1)
    pol = np.tile((-1.0, 1.0), len(cands))
    pts, ok, _ = edge_points(view, centres, radii, pol, halfw, _CANDIDATE_RAYS)
    cx, cy, r, rms = fit_circles(pts, ok, centres)
    n_ok = ok.sum(axis=1)
    ratios = np.array([ring.ratio for ring in pad.rings])
    found: list[_Ring] = []
    for i in range(len(cands)):
        o, n = 2 * i, 2 * i + 1
        if min(n_ok[o], n_ok[n]) < 0.6 * _CANDIDATE_RAYS or r[n] <= 0 or r[o] <= 0:
            continue
        if rms[o] > 0.5 + 0.02 * r[o] or rms[n] > 0.5 + 0.02 * r[n]:
            continue
        if math.hypot(cx[o] - cx[n], cy[o] - cy[n]) > 0.5 + 0.02 * r[o]:
            continue
        ratio = r[n] / r[o]
        k = int(np.argmin(np.abs(ratios - ratio)))
        if abs(ratios[k] - ratio) > ratio_tol:
            continue
        ring = pad.rings[k]
        scale = (r[o] + r[n]) / (ring.outer_m + ring.inner_m)
        found.append(
            _Ring(k + 1, 0.5 * (cx[o] + cx[n]), 0.5 * (cy[o] + cy[n]), float(scale), float(r[o]))
        )
    return found


def _best_group(rings: list[_Ring]) -> list[_Ring]:
    """The largest set of distinct, concentric rings that agree on the scale."""
    best: list[_Ring] = []
    for seed in sorted(rings, key=lambda r: -r.r_outer):
        group: dict[int, _Ring] = {}
        for r in rings:
            if math.hypot(r.cx - seed.cx, r.cy - seed.cy) > 1.0 + 0.03 * seed.r_outer:
                continue
            if abs(r.scale / seed.scale - 1.0) > 0.04:
                continue
            if r.ring not in group or r.r_outer > group[r.ring].r_outer:
                group[r.ring] = r
        if len(group) > len(best):
            best = list(group.values())
    return best


def _joint_fit(
    pts: np.ndarray, radius_m: np.ndarray, cx: float, cy: float, scale: float, iters: int = 4
) -> tuple[float, float, float, np.ndarray]:
    """Gauss-Newton fit of concentric circles of radii ``scale * radius_m``; residuals (px)."""
    x = pts[:, 0]
    y = pts[:, 1]
    jac = np.empty((3, len(x)))  # rows: -d res / d (cx, cy, scale), signs folded below
    jac[2] = radius_m
    for _ in range(iters):
        dx = x - cx
        dy = y - cy
        dist = np.hypot(dx, dy)
        np.divide(dx, dist, out=jac[0])
        np.divide(dy, dist, out=jac[1])
        res = dist - scale * radius_m
        # With J = -jac^T: (J^T J) step = -J^T res  <=>  (jac jac^T) step = jac res.
        step = np.linalg.solve(jac @ jac.T, jac @ res)
        cx += float(step[0])
        cy += float(step[1])
        scale += float(step[2])
        if abs(step[0]) + abs(step[1]) + abs(step[2]) * float(radius_m[0]) < 1e-5:
            break
    res = np.hypot(x - cx, y - cy) - scale * radius_m
    return cx, cy, scale, res


def _joint_fit_sheared(
    pts: np.ndarray, radius_m: np.ndarray, cx: float, cy: float, scale: float, shear: float,
    iters: int = 6,
) -> tuple[float, float, float, float, np.ndarray]:
    """As :func:`_joint_fit`, with the points sheared along x by ``shear`` px per px of y about
    the centre (a rolling shutter during a sideways motion shifts each row by an amount
    growing linearly down the frame): residuals of ``hypot(x - cx - shear (y - cy), y - cy)``.
    """
    x = pts[:, 0]
    y = pts[:, 1]
    jac = np.empty((4, len(x)))  # rows: -d res / d (cx, cy, scale, shear)
    jac[2] = radius_m
    for _ in range(iters):
        dy = y - cy
        dx = x - cx - shear * dy
        dist = np.hypot(dx, dy)
        jac[0] = dx / dist
        jac[1] = (dy - shear * dx) / dist
        jac[3] = dx * dy / dist
        res = dist - scale * radius_m
        step = np.linalg.solve(jac @ jac.T, jac @ res)
        cx += float(step[0])
        cy += float(step[1])
        scale += float(step[2])
        shear += float(step[3])
        if abs(step[0]) + abs(step[1]) + abs(step[2]) * float(radius_m[0]) < 1e-5:
            break
    dy = y - cy
    res = np.hypot(x - cx - shear * dy, dy) - scale * radius_m
    return cx, cy, scale, shear, res


def detect(
    image: np.ndarray,
    fov_h_rad: float,
    pad: PadDefinition = SKEYE_4,
    roll_rad: float | None = None,
    pitch_rad: float | None = None,
    calibration: CameraCalibration | None = None,
) -> PadEstimate:
    """Find the pad in one frame from the downward camera.

    Args:
        image: greyscale (H, W) or BGR (H, W, 3) uint8 frame.
        fov_h_rad: the camera's horizontal field of view (float, radians, never rounded).
        pad: the pad to look for.
        roll_rad, pitch_rad: the vehicle's attitude (body FRD, ZYX; see
            :mod:`skeye.vision.camera`), both or neither. When given, the tilt is compensated
            and offsets are in the level frame; when not, the camera is taken as level.
        calibration: the camera's calibration (``skeye calibrate``). When given, its camera
            matrix and lens distortion replace the ideal pinhole of ``fov_h_rad``: the points
            the detector uses are undistorted, the image itself is not.

    Returns:
        A :class:`PadEstimate`; ``found`` is False (with every figure None) unless at least
        two rings were identified and agree.
    """
    if (roll_rad is None) != (pitch_rad is None):
        raise LocalProtocolError("give both roll_rad and pitch_rad, or neither")
    for name, value in (("roll_rad", roll_rad), ("pitch_rad", pitch_rad)):
        if value is not None and (isinstance(value, bool)
                                  or not isinstance(value, numbers.Real)):  # was a TypeError
            raise LocalProtocolError(f"{name} must be a number of radians, got "
                                     f"{type(value).__name__} {value!r}")
        if value is not None and not (math.isfinite(value) and abs(value) < math.pi / 2):
            raise LocalProtocolError(f"{name} must be finite and within (-pi/2, pi/2), got {value}")
    grey = to_grey(image)
    tilt = roll_rad is not None
    view = LevelView(grey, fov_h_rad, roll_rad or 0.0, pitch_rad or 0.0, tilt, calibration)

    h, w = grey.shape
    if min(h, w) >= 200:
        small = cv2.resize(grey, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
    else:
        small = grey
    sx = w / small.shape[1]
    sy = h / small.shape[0]
    ratios = sorted(r.ratio for r in pad.rings)
    spacing = min((b - a for a, b in itertools.pairwise(ratios)), default=0.2)
    ratio_tol = min(0.035, 0.4 * spacing)
    borders = _pad_borders(pad)

    _, otsu = cv2.threshold(small, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    for binary in (otsu, None):
        if binary is None:
            binary = _adaptive(small)
        cands = _coarse_candidates(view, binary, sx, sy, tilt)
        group = _best_group(_identify(view, cands, pad, ratio_tol))
        if group:
            est = _finish(view, pad, borders, group)
            if not est.found and calibration is not None:
                # A rolling shutter's shear, the last thing to try; only with the lens known:
                # off the image centre an uncorrected lens distorts the rings much like a shear
                # and would pass with a biased height.
                est = _finish(view, pad, borders, group, sheared=True)
            if est.found:
                return est
    return NOT_FOUND


def _finish(
    view: LevelView, pad: PadDefinition, borders: list[_Border], group: list[_Ring],
    sheared: bool = False,
) -> PadEstimate:
    """From a seed group of identified rings: look for the rest, fit jointly, check, report."""
    wts = np.array([g.r_outer for g in group])
    cx = float(np.average([g.cx for g in group], weights=wts))
    cy = float(np.average([g.cy for g in group], weights=wts))
    scale = float(np.average([g.scale for g in group], weights=wts))

    radius_m = np.array([b.radius_m for b in borders])
    ring_of = np.array([b.ring for b in borders])
    r_px = radius_m * scale
    look = np.nonzero(r_px >= _MIN_BORDER_PX)[0]
    if look.size == 0:
        return NOT_FOUND
    hw = np.minimum(
        np.clip(0.4 * np.array([b.gap_m for b in borders]) * scale, 0.75, 5.0), 0.6 * r_px
    )
    centres = np.tile((cx, cy), (look.size, 1))
    pol = np.array([b.polarity for b in borders])
    pts, ok, inside = edge_points(view, centres, r_px[look], pol[look], hw[look], _FINAL_RAYS)

    # A border is confirmed when enough rays found it where the seed predicts; a ring is
    # identified when both of its borders are confirmed.
    dist = np.hypot(pts[..., 0] - cx, pts[..., 1] - cy)
    near = ok & (np.abs(dist - r_px[look, None]) <= (0.75 + 0.015 * r_px[look, None]))
    n_near = near.sum(axis=1)
    confirmed = (n_near >= 10) & (n_near >= _CONFIRM_SHARE * inside.sum(axis=1))
    per_ring = np.bincount(ring_of[look][confirmed], minlength=len(pad.rings) + 1)
    rings = [i for i in range(1, len(pad.rings) + 1) if per_ring[i] == 2]
    if len(rings) < 2:
        return NOT_FOUND
    use = confirmed & np.isin(ring_of[look], rings)
    sel = near & use[:, None]
    all_pts = pts[sel]
    border_idx = np.broadcast_to(np.arange(look.size)[:, None], sel.shape)[sel]
    all_rm = radius_m[look][border_idx]
    shear = 0.0
    if sheared:
        cx, cy, scale, shear, res = _joint_fit_sheared(all_pts, all_rm, cx, cy, scale, shear)
    else:
        cx, cy, scale, res = _joint_fit(all_pts, all_rm, cx, cy, scale)
    # One round of outlier rejection, then refit.
    keep = np.abs(res) <= max(0.5, 4.5 * float(np.median(np.abs(res))))
    if keep.sum() < 20:
        return NOT_FOUND
    all_pts, all_rm, border_idx = all_pts[keep], all_rm[keep], border_idx[keep]
    # A border left with too few points after that cut (say one seen only in the image's
    # corners, at low height) drops its ring from the fit, not the whole detection.
    counts = np.bincount(border_idx, minlength=look.size)
    thin = np.unique(ring_of[look][use & (counts < 5)])
    if thin.size:
        rings = [r for r in rings if r not in thin]
        if len(rings) < 2:
            return NOT_FOUND
        use = use & ~np.isin(ring_of[look], thin)
        mask = use[border_idx]
        all_pts, all_rm, border_idx = all_pts[mask], all_rm[mask], border_idx[mask]
        if mask.sum() < 20:
            return NOT_FOUND
    # Every border used must agree with the joint model on its own. A ring one of whose
    # borders does not (blur or lens shift a thin ring's borders; a rolling shutter shears
    # a large ring) leaves the fit, the worst first, while two rings remain; a clean frame
    # never gets here with a disagreeing border, so its fit is unchanged.
    while True:
        if sheared:
            cx, cy, scale, shear, res = _joint_fit_sheared(
                all_pts, all_rm, cx, cy, scale, shear, iters=3)
        else:
            cx, cy, scale, res = _joint_fit(all_pts, all_rm, cx, cy, scale, iters=2)
        if not (scale > 0 and math.isfinite(cx) and math.isfinite(cy)):
            return NOT_FOUND
        counts = np.bincount(border_idx, minlength=look.size)
        used = use & (counts > 0)
        if (counts[use] < 5).any():
            return NOT_FOUND
        n = np.maximum(counts, 1)
        bias = np.bincount(border_idx, weights=res, minlength=look.size) / n
        sq = np.bincount(border_idx, weights=res * res, minlength=look.size) / n
        r_b = scale * radius_m[look]
        # Limits grow with the border's radius: an attitude error of a few milliradians bends
        # a 300 px border (low heights) by about a pixel; small, distant rings keep the
        # 0.5 px floor.
        excess = np.maximum(
            np.abs(bias) / (0.5 + 0.015 * r_b),
            np.sqrt(sq) / np.maximum(_MAX_BORDER_RMS_PX, _BORDER_RMS_PER_PX * r_b),
        )
        excess = np.where(used, excess, 0.0)
        if excess.max() <= 1.0:
            break
        worst = int(ring_of[look][int(np.argmax(excess))])
        rings = [r for r in rings if r != worst]
        if len(rings) < 2:
            return NOT_FOUND
        use = use & (ring_of[look] != worst)
        mask = use[border_idx]
        all_pts, all_rm, border_idx = all_pts[mask], all_rm[mask], border_idx[mask]
        if mask.sum() < 20:
            return NOT_FOUND
    if abs(shear) > _MAX_SHEAR:
        return NOT_FOUND
    r_used = scale * radius_m[look][used]
    rms = float(np.sqrt(np.mean(res * res)))
    if rms > max(1.0, _BORDER_RMS_PER_PX * float(r_used.max())):
        return NOT_FOUND

    height_m = view.f / scale
    x_m = (cx - view.cx) / view.f * height_m
    y_m = (cy - view.cy) / view.f * height_m
    ucx, ucy = view.to_image(np.array(cx), np.array(cy))
    ellipses = []
    for ring_no in rings:
        ring = pad.rings[ring_no - 1]
        for name, r_m in (("outer", ring.outer_m), ("inner", ring.inner_m)):
            c, axes, ang = view.image_ellipse(cx, cy, scale * r_m)
            ellipses.append(BorderEllipse(ring_no, name, c, axes, ang))
    rings_term = 1.0 - 0.5 ** len(rings)
    fit_term = 1.0 / (1.0 + (rms / 0.5) ** 2)
    return PadEstimate(
        found=True,
        center_px=(float(ucx), float(ucy)),
        height_m=float(height_m),
        offset_cam_m=(float(x_m), float(y_m)),
        offset_body_m=level_offset_to_body((float(x_m), float(y_m))),
        rings=tuple(rings),
        ellipses=tuple(ellipses),
        quality=float(rings_term * fit_term),
    )
