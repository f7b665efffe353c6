"""Camera model and the synthetic renderer: conventions pinned down by numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skeye.errors import LocalProtocolError
from skeye.sim.frames import euler_to_quat, quat_to_matrix
from skeye.vision.camera import (
    DOWNWARD_CAMERA_TO_BODY,
    body_to_level,
    camera_to_level,
    focal_length_px,
    fov_v_rad,
    intrinsics,
    level_homography,
    level_offset_to_body,
    principal_point_px,
    render_pad_view,
)
from skeye.vision.pad import SKEYE_4

from .helpers import FOV_H_RAD, H, W


def test_focal_length_is_exact_and_unrounded():
    f = focal_length_px(800, 1.309)
    assert f == pytest.approx(400.0 / math.tan(0.6545), rel=1e-15)
    # 1.309 rad is 75.0002 degrees: an integer-degree FOV would give a different focal length.
    assert f != pytest.approx(focal_length_px(800, math.radians(75)), rel=1e-6)
    assert f != pytest.approx(focal_length_px(800, math.radians(74)), rel=1e-3)


def test_vertical_fov_from_aspect_ratio():
    fv = fov_v_rad(800, 600, 1.309)
    assert math.tan(fv / 2) == pytest.approx(0.75 * math.tan(1.309 / 2), rel=1e-12)
    assert fov_v_rad(800, 800, 1.309) == pytest.approx(1.309, rel=1e-12)


def test_principal_point_is_index_centre():
    assert principal_point_px(800, 600) == (399.5, 299.5)
    k = intrinsics(800, 600, 1.309)
    assert k[0, 2] == 399.5 and k[1, 2] == 299.5 and k[0, 0] == k[1, 1]


@pytest.mark.parametrize("bad", [0.0, -1.0, math.pi, 4.0, float("nan")])
def test_bad_fov_rejected(bad):
    with pytest.raises(LocalProtocolError, match="field of view"):
        focal_length_px(800, bad)


def test_a_numpy_fov_is_a_fov():
    """A float32 field of view (a value read from an array) was refused, with a message that
    contradicted itself: "must be in (0, pi) rad, got 1.309000015258789"."""
    assert focal_length_px(800, np.float32(1.309)) == focal_length_px(800, float(np.float32(1.309)))
    with pytest.raises(LocalProtocolError, match="field of view"):
        focal_length_px(800, True)


@pytest.mark.parametrize("tiny", [1e-308, 5e-324])
def test_a_fov_too_small_for_a_finite_focal_length_is_refused(tiny):
    """In (0, pi), so taken: 5e-324 rad divided by zero (a ZeroDivisionError traceback from
    `skeye vision detect --fov 5e-324`) and 1e-308 rad printed a height of Infinity and offsets
    of NaN, which is no JSON."""
    with pytest.raises(LocalProtocolError, match=f"field of view {tiny} rad is too small"):
        focal_length_px(800, tiny)


def test_downward_mount_axes():
    # Image right = body right, image down = body backward, optical axis = body down.
    assert DOWNWARD_CAMERA_TO_BODY @ np.array([1, 0, 0]) == pytest.approx([0, 1, 0])
    assert DOWNWARD_CAMERA_TO_BODY @ np.array([0, 1, 0]) == pytest.approx([-1, 0, 0])
    assert DOWNWARD_CAMERA_TO_BODY @ np.array([0, 0, 1]) == pytest.approx([0, 0, 1])
    assert np.linalg.det(DOWNWARD_CAMERA_TO_BODY) == pytest.approx(1.0)
    assert level_offset_to_body((0.1, -0.2)) == (0.2, 0.1)  # image up is forward


@pytest.mark.parametrize("roll,pitch", [(0.2, 0.0), (0.0, -0.25), (0.26, 0.17), (-0.1, 0.3)])
def test_attitude_matches_sim_frames(roll, pitch):
    # Same ZYX convention as skeye.sim.frames (body FRD -> NED with yaw 0).
    expected = quat_to_matrix(euler_to_quat(roll, pitch, 0.0))
    assert body_to_level(roll, pitch) == pytest.approx(expected, abs=1e-12)


def _dark_centroid(img: np.ndarray) -> tuple[float, float]:
    """Centroid of the pad square (black) on a white background."""
    w = (255.0 - img.astype(float)) / 255.0
    vs, us = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
    return float((w * us).sum() / w.sum()), float((w * vs).sum() / w.sum())


def test_level_render_puts_pad_where_the_pinhole_says():
    # The centroid of the pad square (white background vs black background tells it apart
    # from the rings) is the pad centre for a level camera. Sub-samples quantise each edge
    # to 1/supersample of a pixel, hence the tolerance.
    w, h, ss = 200, 150, 12
    f = focal_length_px(w, FOV_H_RAD)
    on_white = render_pad_view(
        SKEYE_4, w, h, FOV_H_RAD, 3.0, (0.4, -0.3), background=255, supersample=ss
    )
    on_black = render_pad_view(
        SKEYE_4, w, h, FOV_H_RAD, 3.0, (0.4, -0.3), background=0, supersample=ss
    )
    inside = 1.0 - (on_white.astype(float) - on_black) / 255.0  # 1 on the pad square
    vs, us = np.mgrid[0:h, 0:w]
    u = (inside * us).sum() / inside.sum()
    v = (inside * vs).sum() / inside.sum()
    assert u == pytest.approx((w - 1) / 2 + f * 0.4 / 3.0, abs=0.05)
    assert v == pytest.approx((h - 1) / 2 - f * 0.3 / 3.0, abs=0.05)
    # Area of the square, in pixels, is (f * side / h)^2.
    assert inside.sum() == pytest.approx((f * 0.6 / 3.0) ** 2, rel=5e-3)


def test_white_area_matches_ring_areas():
    f = focal_length_px(W, FOV_H_RAD)
    h = 1.0
    img = render_pad_view(SKEYE_4, W, H, FOV_H_RAD, h, background=0, supersample=4)
    white_px = img.astype(float).sum() / 255.0
    area_m2 = sum(math.pi * (r.outer_m**2 - r.inner_m**2) for r in SKEYE_4.rings)
    assert white_px == pytest.approx(area_m2 * (f / h) ** 2, rel=2e-3)


def test_tilt_directions():
    # Nose up: the pad straight below appears below the centre; right wing down: to the right.
    def centre(roll, pitch):
        img = render_pad_view(
            SKEYE_4,
            200,
            150,
            FOV_H_RAD,
            1.0,
            roll_rad=roll,
            pitch_rad=pitch,
            supersample=1,
            background=255,
        )
        return _dark_centroid(img)

    u0, v0 = centre(0.0, 0.0)
    u, v = centre(0.0, 0.2)
    assert v > v0 + 10 and abs(u - u0) < 1
    u, v = centre(0.2, 0.0)
    assert u > u0 + 10 and abs(v - v0) < 1


def test_level_homography_maps_the_nadir_to_the_principal_point():
    roll, pitch = 0.2, -0.15
    hom = level_homography(W, H, FOV_H_RAD, roll, pitch)
    # The nadir ray in the camera frame is R_CL @ (0, 0, 1).
    d = camera_to_level(roll, pitch).T @ np.array([0.0, 0.0, 1.0])
    p = intrinsics(W, H, FOV_H_RAD) @ (d / d[2])
    q = hom @ p
    assert q[:2] / q[2] == pytest.approx([399.5, 299.5], abs=1e-9)


def test_render_noise_needs_rng_and_is_seeded():
    with pytest.raises(LocalProtocolError, match="rng"):
        render_pad_view(SKEYE_4, 64, 48, FOV_H_RAD, 1.0, noise_sigma=3.0)
    a = render_pad_view(
        SKEYE_4, 64, 48, FOV_H_RAD, 1.0, noise_sigma=3.0, rng=np.random.default_rng(7)
    )
    b = render_pad_view(
        SKEYE_4, 64, 48, FOV_H_RAD, 1.0, noise_sigma=3.0, rng=np.random.default_rng(7)
    )
    assert a.dtype == np.uint8 and a.shape == (48, 64)
    assert np.array_equal(a, b)


def test_render_background_image_and_bad_sizes():
    bg = np.full((48, 64), 77, np.uint8)
    img = render_pad_view(SKEYE_4, 64, 48, FOV_H_RAD, 3.0, background=bg)
    assert img[0, 0] == 77
    with pytest.raises(LocalProtocolError, match="background"):
        render_pad_view(SKEYE_4, 64, 48, FOV_H_RAD, 3.0, background=np.zeros((10, 10)))
    with pytest.raises(LocalProtocolError, match="height"):
        render_pad_view(SKEYE_4, 64, 48, FOV_H_RAD, 0.0)
