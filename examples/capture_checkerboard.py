"""Photograph the checkerboard world's board from 14 poses, for ``skeye calibrate``.

Needs ``skeye sim --world checkerboard --mode lockstep --image-port 5003`` ($SKEYE_SIM,
$SKEYE_IMAGES); writes board00.png ... into $SKEYE_BOARD_DIR (default: the current folder).
Each pose is a fresh vehicle whose first frame is taken before it moves: the board in the
centre, near the corners and edges of the image, and tilted (docs/calibration.md). Then:

    skeye calibrate board*.png --board 9x6 --square-mm 25 --out camera.toml
"""

import math
import os
import sys
from pathlib import Path

import cv2

import skeye

sim_address = os.environ.get("SKEYE_SIM", "127.0.0.1:3000")
images = os.environ.get("SKEYE_IMAGES", "127.0.0.1:5003")
out = Path(os.environ.get("SKEYE_BOARD_DIR", "."))
CAMERA_DOWN_M = 0.035  # the hummingbird's Down camera sits 35 mm below the body centre
F_PX = 400 / math.tan(1.309 / 2)  # its focal length: 800 px wide, 1.309 rad field of view
H_M = 0.42  # camera height above the board

poses = []  # (north, east, roll, pitch, yaw) of the camera; the board lies at the origin
for u, v, yaw in ((400, 300, 0.0), (250, 180, 0.3), (550, 180, -0.3), (250, 420, -0.3),
                  (550, 420, 0.3), (400, 170, 1.57), (400, 430, 1.57), (230, 300, 0.0),
                  (570, 300, 0.0)):  # where the board's centre appears in the image
    poses.append(((v - 299.5) * H_M / F_PX, -(u - 399.5) * H_M / F_PX, 0.0, 0.0, yaw))
for roll, pitch in ((0.3, 0.0), (-0.3, 0.0), (0.25, 0.25), (-0.25, -0.25), (0.2, -0.2)):
    poses.append((0.0, 0.0, roll, pitch, 0.5))

for i, (north, east, roll, pitch, yaw) in enumerate(poses):
    with skeye.connect(sim_address, images=images) as sim:
        if sim.mode != "lockstep":
            sys.exit("run the simulator with --mode lockstep: a vehicle spawned in the air "
                     "falls in real time before its frame is taken")
        # The body centre lies CAMERA_DOWN_M above the camera along the tilted body z axis
        # (body-to-NED rotation, ZYX: its third column).
        cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
        cy, sy = math.cos(yaw), math.sin(yaw)
        axis = (cy * sp * cr + sy * sr, sy * sp * cr - cy * sr, cp * cr)
        camera = (north, east, -0.001 - H_M)
        body = tuple(c - CAMERA_DOWN_M * a for c, a in zip(camera, axis, strict=True))
        copter = sim.spawn("hummingbird", name=f"Cal{i}", location_ned_m=body,
                           rotation_rpy_rad=(roll, pitch, yaw))
        copter.camera.wait_next()
        image = copter.camera.image()
        path = out / f"board{i:02d}.png"
        cv2.imwrite(str(path), image.bgr)
        print(f"saved {path} (frame {image.frame})")
