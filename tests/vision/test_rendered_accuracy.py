"""Detector accuracy on frames rendered by the simulator at known poses (docs/landing-pad.md).

Each pose is a robot spawned in the air with that position and attitude; its first frame is
rendered from exactly that state (before the controller moves it). Truth: the camera's height
above the pad plane and the pad centre's offset in the level body frame.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import cv2
import numpy as np
import pytest

from skeye.sim import frames
from skeye.sim.cameras import CameraSystem
from skeye.sim.engine import Simulation
from skeye.sim.image_server import FrameBuffer
from skeye.sim.world import PAD_SURFACE_HEIGHT_M, load_world
from skeye.vision.detector import detect

FOV = 1.309
CAMERA_FRD = np.array([0.0, 0.0, 0.035])

# (camera height m, north m, east m, roll rad, pitch rad): heights 0.3-2.0, offsets towards
# the image edge, tilt up to 15 degrees.
POSES = [
    (0.30, 0.0, 0.0, 0.0, 0.0),
    (0.35, 0.03, -0.02, 0.05, -0.05),
    (0.50, 0.10, 0.05, 0.0, 0.0),
    (0.50, -0.05, 0.0, 0.26, 0.0),
    (0.75, 0.20, -0.25, 0.0, 0.0),
    (1.00, 0.0, 0.0, 0.0, 0.26),
    (1.00, -0.35, 0.40, 0.0, 0.0),
    (1.00, 0.10, -0.10, -0.18, 0.18),
    (1.50, 0.55, -0.30, 0.0, 0.0),
    (1.50, -0.20, 0.20, 0.26, -0.1),
    (2.00, 0.0, 0.0, 0.0, 0.0),
    (2.00, 0.90, -1.10, 0.0, 0.0),
    (2.00, -0.30, 0.50, 0.1, 0.26),
]


@pytest.fixture(scope="module")
def render() -> Iterator:
    sim = Simulation(load_world("pad"), seed=2)
    buffer = FrameBuffer()
    cams = CameraSystem(sim, buffer, synchronous=True, profile="ideal")
    count = [0]

    def shot(height, north, east, roll, pitch):
        count[0] += 1
        name = f"P{count[0]}"
        rot = frames.quat_to_matrix(frames.euler_to_quat(roll, pitch, 0.0))
        cam_offset = rot @ CAMERA_FRD
        # Place the body so the camera is at (north, east) at `height` above the pad plane.
        body = (north - cam_offset[0], east - cam_offset[1],
                -PAD_SURFACE_HEIGHT_M - height - cam_offset[2])
        sim.spawn("hummingbird", name=name, sink=lambda events: None,
                  location_ned_m=body, rotation_rpy_rad=(roll, pitch, 0.0))
        sim.step(1)
        frame = buffer.latest(f"{name}/Down")
        sim.remove(name)
        return cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2GRAY)

    yield shot
    cams.close()


@pytest.mark.parametrize("pose", POSES, ids=[f"h{p[0]}_n{p[1]}_e{p[2]}_r{p[3]}_p{p[4]}"
                                             for p in POSES])
def test_height_within_1_percent_and_offset_within_1_cm(render, pose):
    height, north, east, roll, pitch = pose
    grey = render(height, north, east, roll, pitch)
    est = detect(grey, FOV, roll_rad=roll, pitch_rad=pitch)
    assert est.found, pose
    assert abs(est.height_m - height) / height <= 0.01, (est.height_m, height)
    # The pad (at the origin) relative to the camera, level frame (yaw 0: forward = north).
    fwd, right = est.offset_body_m
    assert math.hypot(fwd - (0.0 - north), right - (0.0 - east)) <= 0.01, (est.offset_body_m,)


def test_no_detection_without_the_pad(render):
    """World views without the pad: grass, a yard with buildings; no false detections."""
    views = [render(1.0, 6.0, 6.0, 0.0, 0.0), render(2.0, -8.0, 3.0, 0.1, -0.1),
             render(0.5, 3.0, -4.0, 0.0, 0.2)]
    noisy = np.clip(views[0].astype(float) + np.random.default_rng(1).normal(0, 12, views[0].shape),
                    0, 255).astype(np.uint8)
    for grey in [*views, noisy, np.full_like(views[0], 128)]:
        assert not detect(grey, FOV).found


def test_a_border_seen_only_in_the_corners_does_not_veto_the_rest(render):
    """Low over the pad (0.32 m) the outermost ring shows only in the image's corners; once
    its few edge points fell to the outlier cut, the whole detection used to fail although
    three rings were perfect (E1 lost 0-2 frames per run this way). The frame is E1 seed 1's
    at t = 2.034 s, with the slightly wrong attitude the INS gave the pilot."""
    sim = Simulation(load_world("pad"), seed=2)
    buffer = FrameBuffer()
    cams = CameraSystem(sim, buffer, synchronous=True, profile="ideal")
    try:
        body = (-0.00105, 0.01486, -0.35803)
        rpy = (0.00084, 0.00118, 0.0013)
        sim.spawn("hummingbird", name="E1", sink=lambda events: None, location_ned_m=body,
                  rotation_rpy_rad=rpy)
        sim.step(1)
        grey = cv2.cvtColor(buffer.latest("E1/Down").rgb, cv2.COLOR_RGB2GRAY)
    finally:
        cams.close()
    rot = frames.quat_to_matrix(frames.euler_to_quat(*rpy))
    camera_height = -(body[2] + (rot @ CAMERA_FRD)[2]) - PAD_SURFACE_HEIGHT_M
    est = detect(grey, FOV, roll_rad=-0.0036, pitch_rad=0.0015)
    assert est.found
    assert abs(est.height_m - camera_height) / camera_height <= 0.01
    assert len(est.rings) >= 2
