"""Render the pictures of docs/camera.md: the same view through the ideal and webcam profiles.

A Hummingbird hovers 0.6 m above the pad world's pad, offset so the pad sits off-centre where
the lens distortion shows; a second pair is rolled at 3 rad/s (motion blur and rolling shutter).
A last webcam picture hovers 0.4 m over the grass beside the pad, one second after its first
frame (auto-exposure settled): the vehicle's soft shadow, the rotor discs' faint one, the
vignetting. Each PNG is a 2/5-size (320 x 240) downscale, to keep the repository small.

Usage: MUJOCO_GL=egl python tools/camera_pictures.py [--out docs/img]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from skeye.sim.cameras import CameraSystem
from skeye.sim.engine import Simulation
from skeye.sim.image_server import FrameBuffer
from skeye.sim.world import load_world


def frame(profile: str, roll_rate_rad_s: float,
          location_ned_m: tuple[float, float, float] = (0.12, -0.10, -0.75),
          after_s: float = 0.0) -> np.ndarray:
    """One frame of the robot's downward camera (RGB), ``after_s`` after its first."""
    sim = Simulation(load_world("pad"), seed=1)
    buffer = FrameBuffer()
    with CameraSystem(sim, buffer, synchronous=True, profile=profile):
        sim.spawn("hummingbird", name="R1", sink=lambda events: None,
                  location_ned_m=location_ned_m, rotation_rpy_rad=(0.0, 0.0, 0.3))
        if roll_rate_rad_s:
            set_body_rate(sim, "R1", (roll_rate_rad_s, 0.0, 0.0))
        for _ in range(200):  # past the webcam's capture latency
            sim.step(1)
            latest = buffer.latest("R1/Down")
            if latest is not None:
                if after_s:
                    watch = buffer.watch("R1/Down")  # every frame rendered: auto-exposure
                    sim.step(round(after_s / sim.dt))
                    buffer.unwatch(watch)
                    latest = buffer.latest("R1/Down")
                    assert latest is not None
                return np.array(latest.rgb)
    raise RuntimeError("no frame")


def set_body_rate(sim: Simulation, robot: str, rate_frd_rad_s: tuple[float, float, float]) -> None:
    """Give a freshly spawned robot a body angular rate (MuJoCo's free joint: local FLU)."""
    import mujoco

    body = mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_BODY, f"robot:{robot}")
    joint = int(sim.model.body_jntadr[body])
    adr = int(sim.model.jnt_dofadr[joint])
    p, q, r = rate_frd_rad_s
    sim.data.qvel[adr + 3:adr + 6] = (p, -q, -r)  # FRD -> FLU


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/img"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    shots = [(profile, rate, suffix, (0.12, -0.10, -0.75), 0.0)
             for profile in ("ideal", "webcam") for rate, suffix in ((0.0, ""), (3.0, "-roll3"))]
    shots.append(("webcam", 0.0, "-shadow", (2.0, 1.2, -0.4), 1.0))
    for profile, rate, suffix, location, after_s in shots:
        rgb = frame(profile, rate, location, after_s)
        small = cv2.resize(rgb, (rgb.shape[1] * 2 // 5, rgb.shape[0] * 2 // 5),
                           interpolation=cv2.INTER_AREA)
        path = args.out / f"camera-{profile}{suffix}.png"
        cv2.imwrite(str(path), cv2.cvtColor(small, cv2.COLOR_RGB2BGR),
                    [cv2.IMWRITE_PNG_COMPRESSION, 9])
        print(path, path.stat().st_size, "bytes")


if __name__ == "__main__":
    main()
