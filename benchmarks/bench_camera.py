"""Camera benchmark: frames/s and render-to-receipt latency from the real simulator.

Starts ``skeye sim --mode realtime --image-port 0`` as its own process, spawns a Hummingbird
hovering over the pad (downward camera 800x600, 30 fps), and streams frames (``SKEYE STREAM``
with META on) to 1 and 4 clients in RAW, JPEG quality 85 and PNG, once per camera profile
(``--camera-profile ideal`` and ``webcam``, docs/camera.md). Latency is receipt time minus
the wall time of the frame's sim time, its capture instant (the sim-to-wall offset comes from
PING answers; in real time the clock runs at 1x), so it counts rendering, the lens and sensor
model, the webcam's capture latency, encoding and transfer. Also prints the simulator's
real-time factor seen by the clients, the renderer (MUJOCO_GL) used, and the webcam profile's
frame rate as a ratio to the ideal one measured in the same run (the machine may be shared).

Usage: python benchmarks/bench_camera.py [--seconds 5] [--fps 30] [--clients 1 4]
       [--formats raw jpeg png] [--profiles ideal webcam]
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

from skeye.control.image_client import ImageClient
from skeye.processes import start_skeye, stop_process

try:  # run from a checkout without installing
    from tests.sim.conftest import LineClient
except ImportError:  # pragma: no cover
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    from tests.sim.conftest import LineClient


@contextmanager
def sim_process(profile: str) -> Iterator[tuple[int, int, str]]:
    proc, found = start_skeye(
        ["sim", "--mode", "realtime", "--port", "0", "--image-port", "0",
         "--camera-profile", profile],
        [r"control protocol on [\d.]+:(\d+)", r"image server on [\d.]+:(\d+) \(MUJOCO_GL=(\w+)"],
        "skeye sim",
    )
    try:
        yield int(found[0].group(1)), int(found[1].group(1)), found[1].group(2)
    finally:
        stop_process(proc)


def clock_offset(c: LineClient) -> float:
    """wall - sim, from the fastest of several PINGs (real-time mode)."""
    best = None
    for i in range(20):
        t0 = time.time()
        c.send(f"PING {{Id o{i}}}")
        res = c.read_until(lambda m, i=i: m.type == "RES" and m.get("Id") == f"o{i}")[1]
        t1 = time.time()
        offset = (t0 + t1) / 2 - float(res.require("Time"))
        if best is None or (t1 - t0) < best[0]:
            best = (t1 - t0, offset)
    assert best is not None
    return best[1]


def stream(port: int, fmt: str, fps: float, seconds: float, offset: float,
           out: list[tuple[int, float]]) -> None:
    with ImageClient("127.0.0.1", port, timeout_s=10) as img:
        img.select_camera("R1/Down")
        img.set_format(fmt, quality=85)
        img.set_meta(True)
        start = time.time()
        for frame in img.stream(fps):
            now = time.time()
            assert frame.meta is not None
            out.append((frame.meta.frame_number, now - (frame.meta.sim_time_s + offset)))
            if now - start > seconds:
                break


def pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] * 1000.0


def run_profile(profile: str, args: argparse.Namespace) -> dict[str, float]:
    """Stream every format to each client count; the RAW x1 frame rate and p50 latency."""
    summary: dict[str, float] = {}
    with sim_process(profile) as (control_port, image_port, gl):
        c = LineClient(control_port)
        c.expect("NFO")
        c.answer("INIT {ClassName hummingbird} {Name R1} {Location 0,0,-1.0}", "INIT")
        time.sleep(1.0)
        offset = clock_offset(c)
        print(f"profile {profile}: renderer MuJoCo offscreen, MUJOCO_GL={gl}; "
              f"{os.cpu_count()} cores; camera 800x600 at {args.fps:g} fps requested; "
              "simulator in real time")
        for fmt in args.formats:
            for n in args.clients:
                results: list[list[tuple[int, float]]] = [[] for _ in range(n)]
                t0 = time.time()
                c.send("PING {Id s0}")
                s0 = float(c.read_until(lambda m: m.get("Id") == "s0")[1].require("Time"))
                threads = [threading.Thread(target=stream, args=(image_port, fmt, args.fps,
                                                                 args.seconds, offset, r))
                           for r in results]
                for t in threads:
                    t.start()
                for t in threads:
                    t.join()
                c.send("PING {Id s1}")
                s1 = float(c.read_until(lambda m: m.get("Id") == "s1")[1].require("Time"))
                rtf = (s1 - s0) / (time.time() - t0)
                rates = [len(r) / args.seconds for r in results]
                lat = [x[1] for r in results for x in r]
                print(f"  {fmt.upper():4s} q85 x{n}: {min(rates):5.1f}-{max(rates):5.1f} "
                      f"frames/s per client, latency p50 {pct(lat, 0.5):5.1f} ms p99 "
                      f"{pct(lat, 0.99):6.1f} ms, sim real-time factor {rtf:.2f}")
                if fmt == args.formats[0] and n == args.clients[0]:
                    summary = {"fps": min(rates), "p50_ms": pct(lat, 0.5)}
        c.close()
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--clients", type=int, nargs="+", default=[1, 4])
    parser.add_argument("--formats", nargs="+", choices=("raw", "jpeg", "png"),
                        default=["raw", "jpeg", "png"])
    parser.add_argument("--profiles", nargs="+", choices=("ideal", "webcam"),
                        default=["ideal", "webcam"])
    args = parser.parse_args()
    summaries = {profile: run_profile(profile, args) for profile in args.profiles}
    if "ideal" in summaries and "webcam" in summaries and summaries["ideal"]["fps"] > 0:
        ideal, webcam = summaries["ideal"], summaries["webcam"]
        print(f"webcam / ideal ({args.formats[0].upper()} x{args.clients[0]}): frame rate "
              f"{webcam['fps']:.1f} / {ideal['fps']:.1f} = {webcam['fps'] / ideal['fps']:.2f}; "
              f"latency p50 {webcam['p50_ms']:.1f} ms vs {ideal['p50_ms']:.1f} ms")


if __name__ == "__main__":
    main()
