"""The detector with a camera calibration, on simulator frames seen through a distorting lens.

Frames come from the simulator (a wide camera of the reference focal length, so barrel
distortion has content out to the corners) and are distorted here with a known k1
(:func:`tests.vision.helpers.distort_image`). Given the calibration, the detector undistorts
the points it uses; without it, the same frames give the biased heights or misses that
docs/calibration.md reports.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from skeye.errors import LocalProtocolError
from skeye.sim import frames
from skeye.sim.cameras import CameraSystem
from skeye.sim.engine import Simulation
from skeye.sim.image_server import FrameBuffer
from skeye.sim.world import PAD_SURFACE_HEIGHT_M, load_world
from skeye.vision.calibration import CameraCalibration
from skeye.vision.camera import intrinsics
from skeye.vision.detector import detect
from tests.vision.helpers import FOV_H_RAD, H, W, distort_image, wide_camera

ROBOTS = Path(__file__).parents[2] / "skeye/robots"
CAMERA_FRD = np.array([0.0, 0.0, 0.035])
K = intrinsics(W, H, FOV_H_RAD)
K_WIDE, W_WIDE, H_WIDE, FOV_WIDE = wide_camera(K, W, H, 1.5)

Pose = tuple[float, float, float, float, float]  # camera height, north, east, roll, pitch


def lens(k1: float) -> CameraCalibration:
    return CameraCalibration(W, H, float(K[0, 0]), float(K[1, 1]), float(K[0, 2]),
                             float(K[1, 2]), (k1, 0.0, 0.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def render(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Callable[[Pose], np.ndarray]]:
    """The ideal wide frame of a camera at a pose over the pad world."""
    robot_dir = tmp_path_factory.mktemp("robots")
    text = (ROBOTS / "hummingbird.toml").read_text()
    text = text.replace('name = "hummingbird"', 'name = "widecam"', 1)
    text = text.replace(f"width = {W}\nheight = {H}\nfov_h_rad = {FOV_H_RAD}",
                        f"width = {W_WIDE}\nheight = {H_WIDE}\nfov_h_rad = {FOV_WIDE!r}")
    text = text.replace('profile = "webcam"', 'profile = "ideal"')  # the pinhole, distorted here
    (robot_dir / "widecam.toml").write_text(text)
    sim = Simulation(load_world("pad"), seed=2, robot_dirs=(robot_dir,),
                     offscreen_size=(W_WIDE, H_WIDE))
    buffer = FrameBuffer()
    cams = CameraSystem(sim, buffer, synchronous=True)
    count = [0]

    def shot(pose: Pose) -> np.ndarray:
        height, north, east, roll, pitch = pose
        count[0] += 1
        name = f"W{count[0]}"
        off = frames.quat_to_matrix(frames.euler_to_quat(roll, pitch, 0.0)) @ CAMERA_FRD
        body = (north - off[0], east - off[1], -PAD_SURFACE_HEIGHT_M - height - off[2])
        sim.spawn("widecam", name=name, sink=lambda events: None, location_ned_m=body,
                  rotation_rpy_rad=(roll, pitch, 0.0))
        sim.step(1)
        frame = buffer.latest(f"{name}/Down")
        sim.remove(name)
        assert frame is not None
        return cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2GRAY)

    yield shot
    cams.close()


def _errors(est: object, pose: Pose) -> tuple[float, float]:
    """(relative height error, offset error m) of a found estimate."""
    height, north, east, _, _ = pose
    assert est.found  # type: ignore[attr-defined]
    fwd, right = est.offset_body_m  # type: ignore[attr-defined]
    return ((est.height_m - height) / height,  # type: ignore[attr-defined]
            math.hypot(fwd + north, right + east))


# Heights 0.5-2 m; the pad centred, off-centre towards the corner, and under tilt.
POSES: list[Pose] = [
    (0.5, 0.0, 0.0, 0.0, 0.0),
    (0.5, -0.12, 0.15, 0.0, 0.0),
    (1.0, 0.0, 0.0, 0.0, 0.0),
    (1.0, 0.10, -0.08, 0.1, -0.1),
    (1.0, -0.25, 0.30, 0.0, 0.0),
    (1.5, 0.0, 0.0, 0.0, 0.0),
    (1.5, -0.38, 0.45, 0.0, 0.0),
    (2.0, 0.0, 0.0, 0.0, 0.0),
    (2.0, 0.10, -0.08, 0.1, -0.1),
    (2.0, -0.50, 0.60, 0.0, 0.0),
]


@pytest.mark.parametrize("k1", [-0.2, 0.1])
@pytest.mark.parametrize("pose", POSES, ids=[f"h{p[0]}_n{p[1]}_e{p[2]}_r{p[3]}" for p in POSES])
def test_calibrated_detector_is_accurate_through_the_lens(render, pose: Pose, k1: float) -> None:
    grey = distort_image(render(pose), K_WIDE, K, (k1, 0.0, 0.0, 0.0, 0.0), (W, H))
    roll, pitch = pose[3], pose[4]
    est = detect(grey, FOV_H_RAD, roll_rad=roll, pitch_rad=pitch, calibration=lens(k1))
    height_error, offset_error = _errors(est, pose)
    assert abs(height_error) <= 0.01, height_error
    assert offset_error <= 0.01, offset_error


def test_without_the_calibration_the_lens_biases_or_hides_the_pad(render) -> None:
    """The figures docs/calibration.md quotes: k1 = -0.2, the pad centred below the camera."""
    dist = (-0.2, 0.0, 0.0, 0.0, 0.0)
    grey_1m = distort_image(render((1.0, 0.0, 0.0, 0.0, 0.0)), K_WIDE, K, dist, (W, H))
    grey_half = distort_image(render((0.5, 0.0, 0.0, 0.0, 0.0)), K_WIDE, K, dist, (W, H))
    plain = detect(grey_1m, FOV_H_RAD)
    height_error, _ = _errors(plain, (1.0, 0.0, 0.0, 0.0, 0.0))
    assert height_error > 0.005  # barrel distortion shrinks the rings: the pad looks farther
    assert not detect(grey_half, FOV_H_RAD).found  # the rings are no circles any more
    calibrated = detect(grey_1m, FOV_H_RAD, calibration=lens(-0.2))
    assert abs(_errors(calibrated, (1.0, 0.0, 0.0, 0.0, 0.0))[0]) < 0.002


def test_clean_frames_give_the_same_answer_with_a_zero_distortion_calibration(render) -> None:
    """The calibrated path with the ideal pinhole's numbers agrees with the plain one."""
    pose = (1.0, 0.10, -0.08, 0.1, -0.1)
    grey = distort_image(render(pose), K_WIDE, K, (0.0,) * 5, (W, H))
    plain = detect(grey, FOV_H_RAD, roll_rad=0.1, pitch_rad=-0.1)
    cal = detect(grey, FOV_H_RAD, roll_rad=0.1, pitch_rad=-0.1,
                 calibration=CameraCalibration.pinhole(W, H, FOV_H_RAD))
    assert plain.found and cal.found and plain.height_m is not None and cal.height_m is not None
    assert cal.height_m == pytest.approx(plain.height_m, rel=1e-5)
    assert cal.rings == plain.rings
    for a, b in zip(cal.ellipses, plain.ellipses, strict=True):
        assert a.center_px == pytest.approx(b.center_px, abs=0.05)
        assert a.semi_axes_px == pytest.approx(b.semi_axes_px, abs=0.05)


def test_a_calibration_of_another_size_is_refused() -> None:
    grey = np.zeros((240, 320), np.uint8)
    with pytest.raises(LocalProtocolError, match="800x600 images, the frame is 320x240"):
        detect(grey, FOV_H_RAD, calibration=lens(-0.2))
