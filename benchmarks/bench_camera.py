"""Camera benchmark: frames/s and render-to-receipt latency from the real simulator.

Real time (the default): starts ``skeye sim --mode realtime --image-port 0`` as its own process,
spawns a Hummingbird hovering over the pad (downward camera 800x600, 30 fps), and streams frames
(``SKEYE STREAM`` with META on) to 1 and 4 clients in RAW, JPEG quality 85 and PNG, once per
camera profile (``--camera-profile ideal`` and ``webcam``, docs/camera.md). Latency is receipt
time minus the wall time of the frame's sim time, its capture instant (the sim-to-wall offset
comes from PING answers; in real time the clock runs at 1x), so it counts rendering, the lens
and sensor model, the webcam's capture latency, encoding and transfer. A client's frame rate
is its steady rate, the frames after its first one over the time from the first to the last
(``--seconds`` of them); the wait for the first frame, which includes starting the renderer when
no client watched before, is printed beside it. Also prints the
simulator's real-time factor seen by the clients, the OpenGL renderer the simulator reports,
and the webcam profile's frame rate as a ratio to the ideal one measured in the same run (the
machine may be shared: the load average is printed before and after).

Lockstep (``--lockstep 1 10``): ``skeye sim --mode lockstep`` with N vehicles hovering, each
with its own connection and image client (RAW + META, as the pilot's vision asks); the
benchmark steps the world one camera period at a time and fetches every vehicle's newest frame
after each step, as a sweep or a learner with camera observations does. Prints frames per wall
second (all vehicles together) and the real-time factor.

Stages (``--stages``): in this process, the webcam frame's steps one by one on the
Hummingbird hovering 1 m over the pad (the render without shadows, the soft-shadow term, MuJoCo's
own shadow pass for comparison, the lens still and turning at 0.5 rad/s, the MJPEG code and
decode), each the best and the median of ``--stage-repeats`` alternating rounds.

Usage: python benchmarks/bench_camera.py [--seconds 5] [--fps 30] [--clients 1 4]
       [--formats raw jpeg png] [--profiles ideal webcam] [--lockstep N ...] [--only-lockstep]
       [--stages] [--stage-repeats 10]
"""

from __future__ import annotations

import argparse
import math
import os
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from typing import Any

from skeye.cliargs import positive_float, positive_int
from skeye.control.connection import Connection
from skeye.control.image_client import ImageClient
from skeye.processes import start_skeye, stop_process


def load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f}, {five:.2f}, {fifteen:.2f} ({os.cpu_count()} cores)"


@contextmanager
def sim_process(profile: str, mode: str = "realtime") -> Iterator[tuple[int, int, str]]:
    """``skeye sim`` with an image server; (control port, image port, renderer)."""
    proc, found = start_skeye(
        ["sim", "--mode", mode, "--port", "0", "--image-port", "0", "--camera-profile", profile],
        [r"control protocol on [\d.]+:(\d+)", r"image server on [\d.]+:(\d+)",
         r"camera renderer: (.*)"],
        "skeye sim",
    )
    try:
        yield int(found[0].group(1)), int(found[1].group(1)), found[2].group(1).strip()
    finally:
        stop_process(proc)


def clock_offset(conn: Connection) -> float:
    """wall - sim, from the fastest of several PINGs (real-time mode)."""
    best = None
    for _ in range(20):
        t0 = time.time()
        sim_time = conn.ping()
        t1 = time.time()
        if best is None or (t1 - t0) < best[0]:
            best = (t1 - t0, (t0 + t1) / 2 - sim_time)
    assert best is not None
    return best[1]


def stream(port: int, fmt: str, fps: float, seconds: float, offset: float,
           out: list[tuple[int, float, float]]) -> None:
    """Frames for ``seconds`` after the first one: (frame number, latency s, arrival time s)."""
    with ImageClient("127.0.0.1", port, timeout_s=10) as img:
        img.select_camera("R1/Down")
        img.set_format(fmt, quality=85)
        img.set_meta(True)
        for frame in img.stream(fps):
            now = time.time()
            assert frame.meta is not None
            out.append((frame.meta.frame_number, now - (frame.meta.sim_time_s + offset), now))
            if now - out[0][2] >= seconds:
                break


def pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] * 1000.0


def run_profile(profile: str, args: argparse.Namespace) -> dict[str, float]:
    """Stream every format to each client count; the first format's x1 frame rate and p50."""
    summary: dict[str, float] = {}
    with sim_process(profile) as (control_port, image_port, renderer), \
            Connection(f"127.0.0.1:{control_port}", timeout_s=30) as conn:
        conn.spawn("hummingbird", location_ned_m=(0.0, 0.0, -1.0))
        time.sleep(1.0)
        offset = clock_offset(conn)
        print(f"profile {profile}: renderer {renderer}; camera 800x600 at {args.fps:g} fps "
              "requested; simulator in real time")
        for fmt in args.formats:
            for n in args.clients:
                results: list[list[tuple[int, float, float]]] = [[] for _ in range(n)]
                t0 = time.time()
                s0 = conn.ping()
                threads = [threading.Thread(target=stream, args=(image_port, fmt, args.fps,
                                                                 args.seconds, offset, r))
                           for r in results]
                for t in threads:
                    t.start()
                for t in threads:
                    t.join()
                rtf = (conn.ping() - s0) / (time.time() - t0)
                # The rate counts the intervals between the first frame and the last (the
                # pipeline's steady rate); the wait for the first frame, which includes the
                # renderer's start when nobody was watching before, is printed beside it.
                if any(len(r) < 2 for r in results):
                    raise SystemExit(f"bench_camera: a client got fewer than 2 frames "
                                     f"({[len(r) for r in results]}): no rate to measure")
                rates = [(len(r) - 1) / (r[-1][2] - r[0][2]) for r in results]
                first_s = max(r[0][2] for r in results) - t0
                lat = [x[1] for r in results for x in r]
                print(f"  {fmt.upper():4s} q85 x{n}: {min(rates):5.1f}-{max(rates):5.1f} "
                      f"frames/s per client, latency p50 {pct(lat, 0.5):5.1f} ms p99 "
                      f"{pct(lat, 0.99):6.1f} ms, first frame after {first_s * 1000:.0f} ms, "
                      f"sim real-time factor {rtf:.2f}", flush=True)
                if fmt == args.formats[0] and n == args.clients[0]:
                    summary = {"fps": min(rates), "p50_ms": pct(lat, 0.5)}
    return summary


def run_lockstep(vehicles: int, args: argparse.Namespace) -> None:
    """Step one camera period at a time; after each, every vehicle's newest frame."""
    with sim_process(args.lockstep_profile, "lockstep") as (control_port, image_port, renderer), \
            ExitStack() as stack:
        conns = []
        images = []
        for i in range(vehicles):
            conn = stack.enter_context(Connection(f"127.0.0.1:{control_port}", timeout_s=60))
            conn.spawn("hummingbird", name=f"R{i + 1}",
                       location_ned_m=(2.0 * (i % 5), 2.0 * (i // 5), -1.0 - 0.1 * i))
            conns.append(conn)
            img = stack.enter_context(ImageClient("127.0.0.1", image_port, timeout_s=60))
            img.select_camera(f"R{i + 1}/Down")
            img.set_format("raw")
            img.set_meta(True)
            images.append(img)
        period_steps = round(1.0 / (30.0 * conns[0].time_step_s))
        conns[0].step(period_steps)  # the first frames, and the image clients' selections
        for img in images:
            img.get_frame()
        frames = 0
        last = [0] * vehicles
        s0 = conns[0].ping()
        t0 = time.monotonic()
        while time.monotonic() - t0 < args.seconds:
            conns[0].step(period_steps)
            for i, img in enumerate(images):
                frame = img.get_frame()
                assert frame.meta is not None
                if frame.meta.frame_number > last[i]:
                    frames += 1
                    last[i] = frame.meta.frame_number
        wall = time.monotonic() - t0
        rtf = (conns[0].ping() - s0) / wall
        print(f"lockstep, {args.lockstep_profile} 800x600, {vehicles} vehicle(s), renderer "
              f"{renderer}: {frames / wall:6.1f} frames per wall second ({frames} new frames "
              f"in {wall:.1f} s, every vehicle's newest after each 1/30 s step), real-time "
              f"factor {rtf:.2f}", flush=True)


def run_stages(args: argparse.Namespace) -> None:
    """Each step of a webcam frame, in this process (see the module comment)."""
    import statistics

    import cv2
    import mujoco

    from skeye.sim.cameras import CameraSystem, camera_model_name
    from skeye.sim.engine import Simulation
    from skeye.sim.image_server import FrameBuffer
    from skeye.sim.lens import Motion
    from skeye.sim.render import HEADROOM, ShotRenderer, WorldState, camera_index, camera_motion
    from skeye.sim.world import load_world

    sim = Simulation(load_world("pad"), seed=3)
    with CameraSystem(sim, FrameBuffer(), synchronous=True, profile="webcam"):
        sim.spawn("hummingbird", name="R1", sink=lambda events: None,
                  location_ned_m=(0.1, 0.0, -1.0))
        sim.step(5)
    cam = sim.robots["R1"].cameras[0]
    lens = cam.lens
    assert lens is not None
    name = camera_model_name("R1", "Down")
    state = WorldState(sim.model, sim.data.qpos.copy(), sim.data.qvel.copy(), sim.time_s)
    shots = ShotRenderer()
    print(f"stages: renderer {shots.describe()}; render {cam.render_size[1]}x"
          f"{cam.render_size[0]} for the 800x600 webcam frame")
    shots.render(state, name, cam, 1)  # loads the state, makes the contexts
    data = shots._data
    height, width = cam.render_size
    cam_id = camera_index(sim.model, name)
    plain = shots._renderer(height, width, cam.render_samples)
    own = shots._renderer(height, width, cam.render_samples, 1024)  # MuJoCo's shadow pass

    # MuJoCo's own pass as skeye used it before: a 1024-pixel map over +-4 m of the origin.
    own._mjr_context.shadowClip = 4.0

    def render(renderer: Any, shadows: int) -> Any:
        scene = renderer.scene
        scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = shadows
        renderer.update_scene(data, camera=name)
        for i in range(scene.nlight):  # the world's lights cast shadows in this pass
            if not scene.lights[i].headlight:
                scene.lights[i].castshadow = shadows
        return renderer.render()

    rgb = render(plain, 0)
    still = camera_motion(mujoco, sim.model, data, cam_id)
    turning = Motion(omega_rad_s=(0.3, 0.4, 0.0), height_m=1.0)
    image = lens.apply(rgb, still, 1, None, HEADROOM)
    bgr = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    stages = {
        "render, no shadows": lambda: render(plain, 0),
        "soft-shadow term (3 quarter-size renders)": lambda: shots._shadow_term(
            name, cam_id, height, width, lens.focal_px, 1.0),
        "for comparison: MuJoCo's shadow pass": lambda: render(own, 1),
        "lens, camera still (remap, gain, noise, MJPEG)": lambda: lens.process(
            rgb, still, 1, None, HEADROOM),
        f"lens, turning 0.5 rad/s ({math.ceil(lens.blur_length_px(turning))} blur samples)":
            lambda: lens.process(rgb, turning, 1, None, HEADROOM),
        "MJPEG code + decode (in the lens)": lambda: cv2.imdecode(
            cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 85])[1], cv2.IMREAD_COLOR_RGB),
        "whole frame (ShotRenderer.render)": lambda: shots.render(state, name, cam, 1),
    }
    times: dict[str, list[float]] = {key: [] for key in stages}
    for _ in range(args.stage_repeats):
        for key, fn in stages.items():
            t0 = time.perf_counter()
            for _ in range(3):
                fn()
            times[key].append((time.perf_counter() - t0) / 3 * 1000.0)
    for key, values in times.items():
        print(f"  {key:48s} best {min(values):6.2f} ms, median {statistics.median(values):6.2f} ms")
    shots.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=positive_float, default=5.0)
    parser.add_argument("--fps", type=positive_float, default=30.0)
    parser.add_argument("--clients", type=positive_int, nargs="+", default=[1, 4])
    parser.add_argument("--formats", nargs="+", choices=("raw", "jpeg", "png"),
                        default=["raw", "jpeg", "png"])
    parser.add_argument("--profiles", nargs="+", choices=("ideal", "webcam"),
                        default=["ideal", "webcam"])
    parser.add_argument("--lockstep", type=positive_int, nargs="*", default=[],
                        help="also the lockstep figure with these numbers of vehicles")
    parser.add_argument("--lockstep-profile", choices=("ideal", "webcam"), default="webcam")
    parser.add_argument("--only-lockstep", action="store_true",
                        help="skip the real-time streams")
    parser.add_argument("--stages", action="store_true",
                        help="only the in-process timing of each step of a webcam frame")
    parser.add_argument("--stage-repeats", type=positive_int, default=10)
    args = parser.parse_args()
    print(f"bench_camera: {load()} at the start")
    if args.stages:
        run_stages(args)
    elif not args.only_lockstep:
        summaries = {profile: run_profile(profile, args) for profile in args.profiles}
        if "ideal" in summaries and "webcam" in summaries and summaries["ideal"]["fps"] > 0:
            ideal, webcam = summaries["ideal"], summaries["webcam"]
            print(f"webcam / ideal ({args.formats[0].upper()} x{args.clients[0]}): frame rate "
                  f"{webcam['fps']:.1f} / {ideal['fps']:.1f} = "
                  f"{webcam['fps'] / ideal['fps']:.2f}; latency p50 {webcam['p50_ms']:.1f} ms "
                  f"vs {ideal['p50_ms']:.1f} ms")
    for vehicles in [] if args.stages else args.lockstep:
        run_lockstep(vehicles, args)
    print(f"bench_camera: {load()} at the end")


if __name__ == "__main__":
    main()
