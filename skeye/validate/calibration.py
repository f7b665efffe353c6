"""A camera calibration made as a user makes one: the ``checkerboard`` world's board
photographed from 14 poses through the simulator's camera model, then ``skeye calibrate``'s
maths (:func:`skeye.vision.calibration.calibrate`) on the frames.

How this works: each pose is a fresh vehicle spawned in the air in a lockstep simulator, whose
first frame (its spawn state, taken before it moves) is used: the board in the centre of the
image, near its corners and edges, and tilted (OpenCV's advice for pinning the distortion
down). Where the board appears is worked out in pixels from the camera's size and focal
length (asked of the simulator: ``GETCONF`` ``Width``, ``Height``, ``FocalLength``), so a
narrower or wider camera still sees the whole board in every view.
``skeye validate --camera webcam`` uses this when no ``--calibration`` is given;
``examples/capture_checkerboard.py`` does the same for a simulator a user runs.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from skeye.control.motion import MotionConfig
from skeye.errors import SkeyeError
from skeye.image_files import read_image_file
from skeye.processes import scaled_s, start_skeye, stop_process
from skeye.vision.calibration import Board, CalibrationResult, calibrate

BOARD = Board(9, 6, 0.025)  # the checkerboard world's board: 9x6 inner corners, 25 mm squares
CAMERA_DOWN_M = 0.035  # the Hummingbird's Down camera sits 35 mm below the body centre
BOARD_CAMERA_HEIGHT_M = 0.42  # camera height above the board in the level views
TILTED_CAMERA_HEIGHT_M = 0.45
# Where the board's centre appears in a level view, as pixel offsets from the image centre
# (u right, v down) for an 800-pixel-wide image, with the camera's yaw; scaled to other widths.
LEVEL_VIEWS_PX = ((0, 0, 0.0), (-150, -120, 0.3), (150, -120, -0.3), (-150, 120, -0.3),
                  (150, 120, 0.3), (0, -130, 1.57), (0, 130, 1.57), (-170, 0, 0.0),
                  (170, 0, 0.0))
TILTED_VIEWS_RAD = ((0.3, 0.0), (-0.3, 0.0), (0.25, 0.25), (-0.25, -0.25), (0.2, -0.2))
TILTED_YAW_RAD = 0.5

FRAME_WAIT_RATE_HZ = 500.0  # the capturing connection's lockstep period: 2 ms
PROCEDURE_VERSION = 2
"""Raised when the views come out otherwise for the same camera model (part of `skeye up`'s
calibration cache key): 2 since 2026-11-27, the spawn-state frame caught and every camera's
own pixel noise (1 before)."""
VIEW_TRIES = 5  # spawns for one view before giving up (each a new phase of the frame grid)
Pose = tuple[float, float, float, float, float, float]  # camera north, east, down, roll, pitch, yaw


def board_poses(width_px: int, height_px: int, focal_px: float) -> list[Pose]:
    """The camera poses (NED, the board at the origin) of the 14 views, for an image of
    ``width_px`` x ``height_px`` and a focal length of ``focal_px``."""
    scale = min(width_px / 800.0, height_px / 600.0)
    poses: list[Pose] = []
    for du, dv, yaw in LEVEL_VIEWS_PX:
        h = BOARD_CAMERA_HEIGHT_M
        # A level, unyawed camera at (north, east) sees the origin at (du, dv) from the centre:
        # image right is east, image down is south (the camera's top edge points north).
        poses.append((dv * scale * h / focal_px, -du * scale * h / focal_px, -h, 0.0, 0.0, yaw))
    for roll, pitch in TILTED_VIEWS_RAD:
        # Tilted views aim the boresight at the board's centre: the camera stands back along it.
        ax, ay, az = boresight_ned(roll, pitch, TILTED_YAW_RAD)
        h = TILTED_CAMERA_HEIGHT_M
        poses.append((-h * ax / az, -h * ay / az, -h, roll, pitch, TILTED_YAW_RAD))
    return poses


def boresight_ned(roll: float, pitch: float, yaw: float) -> tuple[float, float, float]:
    """The body z axis (the Down camera's boresight) in NED: the third column of the
    body-to-NED rotation (ZYX)."""
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return (cy * sp * cr + sy * sr, sy * sp * cr - cy * sr, cp * cr)


def body_location(pose: Pose) -> tuple[float, float, float]:
    """Where the body centre is for the camera at ``pose``: ``CAMERA_DOWN_M`` above the camera
    along the tilted body z axis."""
    north, east, down, roll, pitch, yaw = pose
    axis = boresight_ned(roll, pitch, yaw)
    camera = (north, east, down - 0.001)  # the board's top face is 1 mm above the ground
    n, e, d = (c - CAMERA_DOWN_M * a for c, a in zip(camera, axis, strict=True))
    return (n, e, d)


def _has_frame(camera: Any) -> bool:
    return camera.latest is not None


Progress = Callable[[str], None]  # told what a long step is doing, for a user who waits


def capture_board(sim_address: str, images_address: str, robot: str = "hummingbird",
                  camera: str = "Down", progress: Progress | None = None) -> list[np.ndarray]:
    """The 14 views' frames (BGR) from a lockstep simulator of the checkerboard world;
    ``progress`` is told of each view taken."""
    import skeye

    frames: list[np.ndarray] = []
    poses = [(0.0, 0.0, -BOARD_CAMERA_HEIGHT_M, 0.0, 0.0, 0.0)]  # the first view: centred
    tries = 0
    while len(frames) < len(poses):
        pose = poses[len(frames)]
        name = f"Cal{len(frames)}"
        # One robot a connection, spawned without stepping (its first readings are not
        # awaited); its clock then steps 2 ms at a time (FRAME_WAIT_RATE_HZ) up to the first
        # frame's arrival, so the spawn-state frame is the newest one when it is fetched.
        # Wall-clock guards stretched with the machine's load: the first frame comes as fast
        # as the lockstep simulator renders, which a busy host slows.
        with skeye.connect(sim_address, images=images_address, timeout_s=scaled_s(10.0),
                           motion=MotionConfig(control_rate_hz=FRAME_WAIT_RATE_HZ)) as sim:
            if sim.mode != "lockstep":
                raise SkeyeError("the simulator must run in lockstep: a vehicle spawned "
                                       "in the air falls in real time before its frame is taken")
            copter = sim.spawn(robot, name=name, location_ned_m=body_location(pose),
                               rotation_rpy_rad=(pose[3], pose[4], pose[5]), wait=False)
            # The spawn-state frame (frame 1): the vehicle still. Later frames see it moving (a
            # tilted vehicle levels itself at once), and the rolling shutter skews those.
            sim.clock.wait_until(partial(_has_frame, copter.camera), sim.timeout_s,
                                 f"the first frame of {name}")
            image = copter.camera.image()
            if image.frame == 1 and not frames:  # the camera's size and focal length
                conf = sim.request("GETCONF", ("Type", "Camera"), ("Name", camera))
                poses = board_poses(int(conf.get_float("Width")),
                                    int(conf.get_float("Height")),
                                    float(conf.get_float("FocalLength")))
        if image.frame != 1:
            # Frame 2 came out with frame 1: a camera's frames are on its grid of sim times,
            # so when the spawn fell just before a grid time, frame 2 was taken a few ms after
            # frame 1, and its capture latency (with its jitter) brought it out as soon. The
            # view is photographed again, from a vehicle spawned later (another phase).
            tries += 1
            if tries >= VIEW_TRIES:
                raise SkeyeError(f"view {len(frames)}: {VIEW_TRIES} spawns gave no spawn-state "
                                 f"frame (the newest was frame {image.frame})")
            continue
        tries = 0
        frames.append(image.bgr)
        if progress is not None:
            of = f" of {len(poses)}" if len(frames) > 1 else ""  # known after the first
            progress(f"view {len(frames)}{of} photographed")
    return frames


def calibrate_simulated_camera(workdir: Path, camera_profile: str, seed: int = 1,
                               robot: str = "hummingbird", progress: Progress | None = None,
                               robot_dirs: tuple[Path, ...] = ()
                               ) -> tuple[Path, CalibrationResult]:
    """Start ``skeye sim`` on the checkerboard world with ``camera_profile``, photograph the
    board, calibrate; the calibration file written (``workdir/camera.toml``) and the result.
    ``progress`` is told of each step (the simulator starting, each view, the solve);
    ``robot_dirs`` are the simulator's ``--robot-dir`` folders, where a ``robot`` that is not a
    built-in is found."""
    workdir.mkdir(parents=True, exist_ok=True)
    if progress is not None:
        progress("starting a lockstep simulator of the checkerboard world")
    sim, found = start_skeye(
        ["sim", "--world", "checkerboard", "--mode", "lockstep", "--port", "0",
         "--image-port", "0", "--seed", str(seed), "--camera-profile", camera_profile,
         *[f"--robot-dir={d}" for d in robot_dirs]],
        [r"control protocol on [\d.]+:(\d+)", r"image server on [\d.]+:(\d+)"], "skeye sim",
        timeout_s=scaled_s(180.0))
    try:
        frames = capture_board(f"127.0.0.1:{found[0].group(1)}",
                               f"127.0.0.1:{found[1].group(1)}", robot, progress=progress)
    finally:
        stop_process(sim)
    if progress is not None:
        progress(f"solving for the lens with OpenCV's calibrateCamera on {len(frames)} views")
    images = []
    for i, bgr in enumerate(frames):
        path = workdir / f"board{i:02d}.png"
        cv2.imwrite(str(path), bgr)
        # read back as `skeye calibrate` reads it, so both give the same calibration
        grey = read_image_file(path, cv2.IMREAD_GRAYSCALE)
        images.append((str(path), grey))
    result = calibrate(images, BOARD)
    out = workdir / "camera.toml"
    result.calibration.save(out)
    print(f"calibrated the {camera_profile} camera on {len(result.used)} of {len(images)} "
          f"views: RMS {result.calibration.rms_px:.3f} px", file=sys.stderr)
    return out, result
