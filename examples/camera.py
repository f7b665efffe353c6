"""Read the downward camera: take off, grab a few frames, save the last one as a PNG.

Needs the simulator's image server: ``skeye sim --image-port 5003`` ($SKEYE_IMAGES).
"""

import os

import cv2

import skeye

sim_address = os.environ.get("SKEYE_SIM", "127.0.0.1:3000")
images = os.environ.get("SKEYE_IMAGES", "127.0.0.1:5003")
try:  # no simulator there, or a bad address: said in one line, not a traceback
    sim = skeye.connect(sim_address, images=images)
except skeye.SkeyeError as exc:
    raise SystemExit(f"camera: {exc}") from None
with sim:
    copter = sim.spawn("hummingbird", start="Pad1")
    copter.take_off(0.6)
    for _ in range(3):
        copter.camera.wait_next()  # its frame now exists on the image server
        image = copter.camera.image()
        print(f"frame {image.frame} at t={image.time_s:.3f} s: {image.bgr.shape}")
    path = os.environ.get("SKEYE_CAMERA_OUT", "camera.png")
    try:  # OpenCV says False when it cannot write, and raises for a name it has no format for
        saved = cv2.imwrite(path, image.bgr)
    except cv2.error:
        saved = False
    if not saved:
        raise SystemExit(f"camera: could not write {path} (a folder that exists, a .png or .jpg)")
    print(f"saved {path}")
    copter.land()
