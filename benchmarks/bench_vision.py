"""Landing-pad detector benchmark: frames/s on one core at 800x600, and accuracy by height.

Run: ``python benchmarks/bench_vision.py [--frames N]``. Frames are exact synthetic renders
(skeye.vision.camera.render_pad_view) with the paper's camera (fov_h 1.309 rad). Speed is
reported as wall-clock and as this thread's CPU time (the latter is robust to a busy machine).
"""

from __future__ import annotations

import argparse
import math
import time

import cv2
import numpy as np

from skeye.cliargs import positive_int
from skeye.vision.calibration import CameraCalibration
from skeye.vision.camera import intrinsics, render_pad_view
from skeye.vision.detector import detect
from skeye.vision.pad import SKEYE_4

FOV_H_RAD = 1.309
W, H = 800, 600


def _frames(rng: np.random.Generator, n: int) -> list[tuple[np.ndarray, dict[str, float]]]:
    out = []
    for _ in range(n):
        h = float(rng.uniform(0.3, 2.0))
        half_w = h * math.tan(FOV_H_RAD / 2)
        off = (float(rng.uniform(-0.3, 0.3)) * half_w, float(rng.uniform(-0.3, 0.3)) * half_w)
        roll, pitch = (float(x) for x in rng.uniform(-0.26, 0.26, 2))
        img = render_pad_view(
            SKEYE_4, W, H, FOV_H_RAD, h, off, roll_rad=roll, pitch_rad=pitch,
            noise_sigma=3.0, blur_px=0.7, background=float(rng.uniform(60, 200)), rng=rng,
        )  # fmt: skip
        out.append((img, {"h": h, "x": off[0], "y": off[1], "roll": roll, "pitch": pitch}))
    return out


def bench_speed(frames: list[tuple[np.ndarray, dict[str, float]]], repeats: int) -> None:
    imgs = [f for f, _ in frames]
    for img, t in frames[:3]:  # warm-up
        detect(img, FOV_H_RAD, roll_rad=t["roll"], pitch_rad=t["pitch"])
    # The same frames with a camera calibration (the ideal camera's numbers plus a mild lens):
    # the cost of undistorting contour points and placing rays through the lens model.
    k = intrinsics(W, H, FOV_H_RAD)
    lens = CameraCalibration(W, H, k[0, 0], k[1, 1], k[0, 2], k[1, 2], (-0.02, 0.0, 0.0, 0.0, 0.0))
    n = 0
    cpu0 = time.thread_time()
    for _ in range(repeats):
        for img, t in frames:
            detect(img, FOV_H_RAD, roll_rad=t["roll"], pitch_rad=t["pitch"], calibration=lens)
            n += 1
    cpu = time.thread_time() - cpu0
    print(f"speed (with roll/pitch and a calibration): {n / cpu:7.1f} frames/s CPU "
          f"({1e3 * cpu / n:.2f} ms/frame CPU)")
    for label, attitude in (("with roll/pitch", True), ("level assumed, level frames", False)):
        if not attitude:
            imgs = [render_pad_view(SKEYE_4, W, H, FOV_H_RAD, t["h"], (t["x"], t["y"]))
                    for _, t in frames]  # fmt: skip
        n = 0
        wall0, cpu0 = time.perf_counter(), time.thread_time()
        for _ in range(repeats):
            for img, (_, t) in zip(imgs, frames, strict=True):
                if attitude:
                    detect(img, FOV_H_RAD, roll_rad=t["roll"], pitch_rad=t["pitch"])
                else:
                    detect(img, FOV_H_RAD)
                n += 1
        wall = time.perf_counter() - wall0
        cpu = time.thread_time() - cpu0
        print(
            f"speed ({label}): {n / wall:7.1f} frames/s wall, {n / cpu:7.1f} frames/s CPU "
            f"({1e3 * cpu / n:.2f} ms/frame CPU), {n} frames 800x600 grey, 1 thread"
        )


def bench_accuracy(rng: np.random.Generator, per_height: int) -> None:
    print("\naccuracy on synthetic frames (noise 3, blur 0.7 px, roll/pitch up to 15 deg given):")
    print(" height_m  found   max|dh|/h   mean|dh|/h  max offset err  mean rings")
    for h in (0.3, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0):
        errs_h, errs_o, rings, found = [], [], [], 0
        for _ in range(per_height):
            half_w = h * math.tan(FOV_H_RAD / 2)
            off = (float(rng.uniform(-0.3, 0.3)) * half_w, float(rng.uniform(-0.3, 0.3)) * half_w)
            roll, pitch = (float(x) for x in rng.uniform(-0.26, 0.26, 2))
            img = render_pad_view(
                SKEYE_4, W, H, FOV_H_RAD, h, off, roll_rad=roll, pitch_rad=pitch,
                noise_sigma=3.0, blur_px=0.7, background=float(rng.uniform(60, 200)), rng=rng,
            )  # fmt: skip
            est = detect(img, FOV_H_RAD, roll_rad=roll, pitch_rad=pitch)
            if not est.found:
                continue
            assert est.height_m is not None and est.offset_cam_m is not None
            found += 1
            errs_h.append(abs(est.height_m - h) / h)
            errs_o.append(math.hypot(est.offset_cam_m[0] - off[0], est.offset_cam_m[1] - off[1]))
            rings.append(len(est.rings))
        if found:
            print(
                f" {h:8.2f}  {found:2d}/{per_height:<2d} {100 * max(errs_h):9.3f} % "
                f"{100 * float(np.mean(errs_h)):9.3f} %  {1000 * max(errs_o):9.2f} mm "
                f"{float(np.mean(rings)):9.1f}"
            )
        else:
            print(f" {h:8.2f}   0/{per_height}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=positive_int, default=20, help="distinct frames for speed")
    parser.add_argument("--repeats", type=positive_int, default=15, help="passes over them")
    parser.add_argument("--per-height", type=positive_int, default=10, help="frames per height")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    rng = np.random.default_rng(12345)
    bench_speed(_frames(rng, args.frames), args.repeats)
    bench_accuracy(rng, args.per_height)


if __name__ == "__main__":
    main()
