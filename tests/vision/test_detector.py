"""Detector accuracy on exact synthetic renders, robustness, and no false positives."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from skeye.errors import LocalProtocolError
from skeye.vision.camera import camera_to_level, focal_length_px, intrinsics, render_pad_view
from skeye.vision.detector import NOT_FOUND, PadEstimate, detect
from skeye.vision.pad import SKEYE_4, PadDefinition, Ring

from .helpers import FOV_H_RAD, H, W, grass, rings_fully_in_view

HEIGHT_TOL_REL = 0.01  # docs/landing-pad.md: at most 1 %
OFFSET_TOL_M = 0.01  # and 1 cm


def _check(est: PadEstimate, h_m: float, offset_m: tuple[float, float]) -> None:
    assert est.found, "pad not found"
    assert est.height_m is not None and est.offset_cam_m is not None
    assert abs(est.height_m - h_m) / h_m <= HEIGHT_TOL_REL, est.height_m
    err = math.hypot(est.offset_cam_m[0] - offset_m[0], est.offset_cam_m[1] - offset_m[1])
    assert err <= OFFSET_TOL_M, est.offset_cam_m
    assert est.offset_body_m == pytest.approx((-offset_m[1], offset_m[0]), abs=OFFSET_TOL_M)
    assert 0.0 < est.quality <= 1.0
    assert len(est.rings) >= 2 and list(est.rings) == sorted(set(est.rings))
    assert len(est.ellipses) == 2 * len(est.rings)


@pytest.mark.parametrize("h_m", [0.3, 0.45, 0.7, 1.0, 1.4, 2.0])
def test_level_heights_centred(h_m):
    img = render_pad_view(SKEYE_4, W, H, FOV_H_RAD, h_m, (0.0, 0.0))
    est = detect(img, FOV_H_RAD)
    _check(est, h_m, (0.0, 0.0))
    # Goal is 0.5 %; on exact renders it does much better.
    assert est.height_m == pytest.approx(h_m, rel=0.002)
    f = focal_length_px(W, FOV_H_RAD)
    assert est.center_px == pytest.approx((399.5, 299.5), abs=0.3)
    expected = {i for i, r in enumerate(SKEYE_4.rings, 1) if f * r.outer_m / h_m < 299}
    assert expected <= set(est.rings)


@pytest.mark.parametrize(
    "h_m,fx,fy",
    [(0.3, 0.55, 0.0), (0.6, -0.7, 0.6), (1.0, 0.8, -0.7), (1.5, -0.9, -0.8), (2.0, 0.92, 0.9)],
)
def test_offsets_towards_the_image_edge(h_m, fx, fy):
    # fx, fy: fraction of the half field of view at the pad plane.
    half_w = h_m * math.tan(FOV_H_RAD / 2)
    off = (fx * half_w, fy * 0.75 * half_w)
    img = render_pad_view(SKEYE_4, W, H, FOV_H_RAD, h_m, off, background=200)
    assert rings_fully_in_view(h_m, off), "test case must keep one ring in view"
    _check(detect(img, FOV_H_RAD), h_m, off)


@pytest.mark.parametrize(
    "h_m,off,roll,pitch,yaw",
    [
        (0.35, (0.02, -0.03), 0.26, 0.0, 0.3),
        (0.8, (0.1, 0.15), -0.2, 0.26, 1.0),
        (1.2, (-0.3, 0.1), 0.26, -0.26, 2.0),
        (2.0, (0.4, -0.5), -0.26, -0.2, 0.7),
        (1.6, (-0.2, -0.2), 0.1, 0.15, 0.0),
    ],
)
def test_tilt_up_to_15_degrees_is_compensated(h_m, off, roll, pitch, yaw):
    img = render_pad_view(
        SKEYE_4, W, H, FOV_H_RAD, h_m, off, roll_rad=roll, pitch_rad=pitch, yaw_rad=yaw
    )
    est = detect(img, FOV_H_RAD, roll_rad=roll, pitch_rad=pitch)
    _check(est, h_m, off)
    # The reported image centre is the projection of the pad centre.
    level = detect(img, FOV_H_RAD)  # without attitude: taken as level
    if level.found:
        assert level.offset_cam_m is not None
        err_l = math.hypot(level.offset_cam_m[0] - off[0], level.offset_cam_m[1] - off[1])
        assert err_l > 0.02, "ignoring a 15 degree tilt should show in the offset"


def test_tilted_centre_px_is_the_pad_centre_projection():
    roll, pitch, h_m, off = 0.2, -0.15, 1.0, (0.1, 0.05)
    img = render_pad_view(SKEYE_4, W, H, FOV_H_RAD, h_m, off, roll_rad=roll, pitch_rad=pitch)
    est = detect(img, FOV_H_RAD, roll_rad=roll, pitch_rad=pitch)
    pc = camera_to_level(roll, pitch).T @ np.array([off[0], off[1], h_m])
    uv = (intrinsics(W, H, FOV_H_RAD) @ pc)[:2] / pc[2]
    assert est.center_px == pytest.approx(tuple(uv), abs=0.3)
    # Ellipses are the projected circles: concentric only in the level view, so their image
    # centres differ slightly, and they are not circles.
    outer1 = next(e for e in est.ellipses if e.ring == 1 and e.border == "outer")
    assert outer1.semi_axes_px[0] > outer1.semi_axes_px[1] * 1.01


@pytest.mark.parametrize(
    "h_m,noise,blur,seed",
    [(0.4, 10.0, 0.0, 1), (1.0, 8.0, 1.2, 2), (2.0, 10.0, 1.5, 3), (2.0, 0.0, 2.0, 4)],
)
def test_noise_and_blur(h_m, noise, blur, seed):
    rng = np.random.default_rng(seed)
    off = (0.1, -0.08)
    img = render_pad_view(
        SKEYE_4, W, H, FOV_H_RAD, h_m, off, noise_sigma=noise, blur_px=blur, background=90, rng=rng
    )
    _check(detect(img, FOV_H_RAD), h_m, off)


def test_pad_on_grass_texture():
    rng = np.random.default_rng(11)
    img = render_pad_view(SKEYE_4, W, H, FOV_H_RAD, 1.3, (-0.2, 0.1), background=grass(rng))
    _check(detect(img, FOV_H_RAD), 1.3, (-0.2, 0.1))


def test_partial_view_uses_rings_cut_by_the_edge():
    # Low and off-centre: rings 1 and 2 are cut by the image border, 3 and 4 in full view.
    h_m, off = 0.4, (0.12, 0.05)
    full = rings_fully_in_view(h_m, off)
    assert 1 not in full and 2 not in full and {3, 4} <= set(full)
    est = detect(render_pad_view(SKEYE_4, W, H, FOV_H_RAD, h_m, off), FOV_H_RAD)
    _check(est, h_m, off)
    assert 2 in est.rings  # found along the rays that stay inside the image


def test_bgr_input_gives_the_same_answer():
    grey = render_pad_view(SKEYE_4, W, H, FOV_H_RAD, 1.1, (0.05, 0.02))
    bgr = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    a, b = detect(grey, FOV_H_RAD), detect(bgr, FOV_H_RAD)
    assert a.found and a == b


def test_other_pad_definition():
    pad = PadDefinition(
        "three",
        1.0,
        (Ring(0.45, 0.36), Ring(0.3, 0.165), Ring(0.12, 0.036)),  # ratios 0.8, 0.55, 0.3
    )
    img = render_pad_view(pad, W, H, FOV_H_RAD, 2.0, (0.3, 0.2))
    est = detect(img, FOV_H_RAD, pad=pad)
    _check(est, 2.0, (0.3, 0.2))
    assert est.rings == (1, 2, 3)
    assert not detect(img, FOV_H_RAD).found  # not the skeye-4 pad


# --- frames without a pad: never a guess ---------------------------------------------------


def _no_pad_frames() -> list[tuple[str, np.ndarray]]:
    rng = np.random.default_rng(2024)
    frames: list[tuple[str, np.ndarray]] = []
    for i in range(3):
        frames.append((f"uniform noise {i}", rng.integers(0, 256, (H, W), dtype=np.uint8)))
        frames.append((f"grass {i}", grass(rng, blob_px=(3, 6, 12)[i])))
    frames.append(("blank", np.full((H, W), 128, np.uint8)))
    f = focal_length_px(W, FOV_H_RAD)
    for k in range(4):  # a single ring of the pad, alone, at several heights
        ring = SKEYE_4.rings[k]
        single = PadDefinition("single", 0.6, (ring,))
        img = render_pad_view(single, W, H, FOV_H_RAD, 0.4 + 0.45 * k, (0.05, 0.0))
        frames.append((f"single ring {k + 1}", img))
    # Two of the pad's rings, right sizes, but not concentric.
    img = np.full((H, W), 128, np.uint8)
    s = f / 1.2
    for k, c in ((1, (300, 300)), (2, (340, 310))):
        r = SKEYE_4.rings[k]
        cv2.circle(img, c, round(s * r.outer_m), 255, -1, cv2.LINE_AA)
        cv2.circle(img, c, round(s * r.inner_m), 0, -1, cv2.LINE_AA)
    frames.append(("non-concentric rings", img))
    # Concentric rings of the pad's ratios but the wrong relative size.
    img = np.zeros((H, W), np.uint8)
    for k, sc in ((1, 1.0), (2, 1.2)):
        r = SKEYE_4.rings[k]
        cv2.circle(img, (400, 300), round(s * sc * r.outer_m), 255, -1, cv2.LINE_AA)
        cv2.circle(img, (400, 300), round(s * sc * r.inner_m), 0, -1, cv2.LINE_AA)
    frames.append(("rings of the wrong relative size", img))
    # Other circle targets: concentric rings with ratios far from the pad's.
    for t in range(4):
        img = np.full((H, W), int(rng.integers(40, 200)), np.uint8)
        c = (int(rng.integers(200, 600)), int(rng.integers(200, 400)))
        radius = float(rng.uniform(60, 180))
        for k in range(5):
            cv2.circle(img, c, round(radius), 255 if k % 2 == 0 else 0, -1, cv2.LINE_AA)
            radius *= (0.5, 0.68, 0.92)[(t + k) % 3]
        frames.append((f"dartboard {t}", img))
    # A checkerboard and a grid of discs.
    yy, xx = np.mgrid[0:H, 0:W]
    frames.append(("checkerboard", (((xx // 40 + yy // 40) % 2) * 255).astype(np.uint8)))
    discs = np.zeros((H, W), np.uint8)
    for cx in range(60, W, 120):
        for cy in range(60, H, 120):
            cv2.circle(discs, (cx, cy), 45, 255, -1, cv2.LINE_AA)
            cv2.circle(discs, (cx, cy), 20, 0, -1, cv2.LINE_AA)
    frames.append(("grid of annuli", discs))
    return frames


NO_PAD = _no_pad_frames()


@pytest.mark.parametrize("name,img", NO_PAD, ids=[n for n, _ in NO_PAD])
def test_no_pad_no_detection(name, img):
    est = detect(img, FOV_H_RAD)
    assert est == NOT_FOUND, name
    assert detect(img, FOV_H_RAD, roll_rad=0.1, pitch_rad=-0.1) == NOT_FOUND, name


def test_pad_mostly_out_of_view_is_not_found():
    img = render_pad_view(SKEYE_4, W, H, FOV_H_RAD, 1.0, (0.3, 0.2), roll_rad=0.26, pitch_rad=0.26)
    assert rings_fully_in_view(1.0, (0.3, 0.2), 0.26, 0.26) == []
    assert detect(img, FOV_H_RAD, roll_rad=0.26, pitch_rad=0.26) == NOT_FOUND


# --- API ------------------------------------------------------------------------------------


def test_json_form():
    img = render_pad_view(SKEYE_4, W, H, FOV_H_RAD, 1.0, (0.1, 0.2))
    d = detect(img, FOV_H_RAD).to_json_dict()
    assert set(d) == {
        "found",
        "center_px",
        "height_m",
        "offset_cam_m",
        "offset_body_m",
        "rings",
        "quality",
    }
    assert d["found"] is True and d["rings"] == [1, 2, 3, 4]
    assert len(d["center_px"]) == 2 and len(d["offset_cam_m"]) == 2
    assert isinstance(d["height_m"], float) and 0 < d["quality"] <= 1
    assert NOT_FOUND.to_json_dict() == {
        "found": False,
        "center_px": None,
        "height_m": None,
        "offset_cam_m": None,
        "offset_body_m": None,
        "rings": [],
        "quality": 0.0,
    }


def test_ellipses_are_the_ring_borders():
    h_m = 1.0
    est = detect(render_pad_view(SKEYE_4, W, H, FOV_H_RAD, h_m), FOV_H_RAD)
    f = focal_length_px(W, FOV_H_RAD)
    for e in est.ellipses:
        ring = SKEYE_4.rings[e.ring - 1]
        r_m = ring.outer_m if e.border == "outer" else ring.inner_m
        assert e.semi_axes_px == pytest.approx((f * r_m / h_m,) * 2, rel=0.003)
        assert e.center_px == pytest.approx((399.5, 299.5), abs=0.3)


@pytest.mark.parametrize(
    "image,kwargs,match",
    [
        (np.zeros((600, 800), np.float32), {}, "uint8"),
        (np.zeros((600, 800, 2), np.uint8), {}, "shape"),
        (np.zeros((8, 8), np.uint8), {}, "too small"),
        (np.zeros((600, 800), np.uint8), {"roll_rad": 0.1}, "both"),
        (np.zeros((600, 800), np.uint8), {"roll_rad": 2.0, "pitch_rad": 0.0}, "roll_rad"),
        ("not an image", {}, "numpy"),
    ],
)
def test_bad_input_raises(image, kwargs, match):
    with pytest.raises(LocalProtocolError, match=match):
        detect(image, FOV_H_RAD, **kwargs)


def test_bad_fov_raises():
    with pytest.raises(LocalProtocolError, match="field of view"):
        detect(np.zeros((600, 800), np.uint8), 0.0)


def test_a_fov_roll_or_pitch_that_is_no_number_is_said_so():
    # The string "1.3" was said as "must be in (0, pi) rad, got 1.3"; a string roll was a
    # TypeError from math.isfinite.
    grey = np.zeros((600, 800), np.uint8)
    with pytest.raises(LocalProtocolError, match=r"field of view must be a number .* str '1\.3'"):
        detect(grey, "1.3")  # type: ignore[arg-type]
    for kw in ({"roll_rad": "0.1", "pitch_rad": 0.0}, {"roll_rad": 0.0, "pitch_rad": True}):
        with pytest.raises(LocalProtocolError, match="_rad must be a number of radians"):
            detect(grey, 1.3, **kw)
