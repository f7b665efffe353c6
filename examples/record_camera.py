"""Record the downward camera over the pad as a lossless video, for ``--camera file://``.

Hovers 0.8 m over the pad, records 40 frames into FFV1 in MKV (the very pixels: the pilot's
detector gives the live detections again), and lands. Against a lockstep simulator that is 40
frames in a row at the camera's own frame rate; in realtime, the frames it keeps up with, at
their mean rate, and it says how many of the camera's it passed over. Needs the
simulator's image server: ``skeye sim --image-port 5003`` ($SKEYE_IMAGES). Play it with
``skeye pilot ... --camera 'file://flight.mkv?fov_rad=0.952105'`` (the printed URI).
"""

import os

import cv2

import skeye

sim_address = os.environ.get("SKEYE_SIM", "127.0.0.1:3000")
images = os.environ.get("SKEYE_IMAGES", "127.0.0.1:5003")
path = os.environ.get("SKEYE_VIDEO_OUT", "flight.mkv")
# Said before the flight, so that no recording is lost to it:
if not os.path.isdir(os.path.dirname(path) or ".") or not path.endswith((".mkv", ".avi")):
    raise SystemExit(f"record_camera: cannot write FFV1 video to {path} (a folder that exists, "
                     "a .mkv or .avi)")
try:  # no simulator there, or a bad address: said in one line, not a traceback
    sim = skeye.connect(sim_address, images=images)
except skeye.SkeyeError as exc:
    raise SystemExit(f"record_camera: {exc}") from None
with sim:
    copter = sim.spawn("hummingbird", start="Pad1")
    fov_rad = sim.request("GETCONF", ("Type", "Camera"), ("Name", "Down")).get_float("FOV")
    copter.take_off(0.8)
    frames, times, numbers = [], [], []
    while len(frames) < 40:
        if sim.mode == "lockstep":  # 10 ms at a time, under a frame period: none passed over
            sim.step(max(1, round(0.01 / sim.time_step_s)))
            if copter.camera.latest is None or copter.camera.latest.frame in numbers[-1:]:
                continue
        else:  # realtime: the newest frame when we are ready, as a live pilot gets them
            copter.camera.wait_next()
        image = copter.camera.image()
        if not times or image.time_s > times[-1]:
            frames.append(image.bgr)
            times.append(image.time_s)
            numbers.append(image.frame)
    copter.land()
fps = (len(times) - 1) / (times[-1] - times[0])
missed = numbers[-1] - numbers[0] + 1 - len(numbers)  # the camera's frames not recorded
height, width = frames[0].shape[:2]
writer = cv2.VideoWriter(path, cv2.VideoWriter.fourcc(*"FFV1"), fps, (width, height))
if not writer.isOpened():
    raise SystemExit(f"this OpenCV cannot write FFV1 video to {path}")
for frame in frames:
    writer.write(frame)
writer.release()
print(f"saved {path}: {len(frames)} frames of {width}x{height} at {fps:g} fps"
      + (f" ({missed} of the camera's frames passed over)" if missed else ""))
print(f"play it: skeye pilot ... --camera 'file://{path}?fov_rad={fov_rad!r}'")
