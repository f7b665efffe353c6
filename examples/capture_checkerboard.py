"""Photograph the checkerboard world's board from 14 poses, for ``skeye calibrate``.

Needs ``skeye sim --world checkerboard --mode lockstep --image-port 5003`` ($SKEYE_SIM,
$SKEYE_IMAGES; the Hummingbird's webcam, or ``--camera-profile ideal`` for the pinhole); writes
board00.png ...
into $SKEYE_BOARD_DIR (default: the current folder). Each pose is a fresh vehicle whose first
frame, taken before it moves, is kept: the board in the centre, near the corners and edges of
the image, and tilted (docs/calibration.md; the poses are in skeye/validate/calibration.py).
Then:

    skeye calibrate board*.png --board 9x6 --square-mm 25 --out camera.toml
"""

import os
from pathlib import Path

import cv2

from skeye.errors import SkeyeError
from skeye.validate.calibration import capture_board

sim_address = os.environ.get("SKEYE_SIM", "127.0.0.1:3000")
images = os.environ.get("SKEYE_IMAGES", "127.0.0.1:5003")
out = Path(os.environ.get("SKEYE_BOARD_DIR", "."))
try:  # before any view is photographed
    out.mkdir(parents=True, exist_ok=True)
except OSError as exc:
    raise SystemExit(f"capture_checkerboard: no folder {out} to write the frames in: "
                     f"{exc.strerror}") from None

try:  # no simulator there, one not in lockstep, a bad address: said in one line
    frames = capture_board(sim_address, images)
except SkeyeError as exc:
    raise SystemExit(f"capture_checkerboard: {exc}") from None
for i, bgr in enumerate(frames):
    path = out / f"board{i:02d}.png"
    if not cv2.imwrite(str(path), bgr):  # OpenCV says False, never raises, when it cannot write
        raise SystemExit(f"capture_checkerboard: could not write {path}")
    print(f"saved {path}")
