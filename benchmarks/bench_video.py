"""The pilot's video port: frames/s served, the latency it adds, and what publish costs.

Run: ``python benchmarks/bench_video.py [--frames N] [--width 800 --height 600] [--clients K]``.
A ``VideoServer`` on a loopback port gets rendered views of the landing pad (800x600 BGR, as
the hummingbird's camera) from this thread, at ``--rate`` frames/s;
``--clients`` viewers subscribe at 1000 frames/s and read everything. Printed: frames published
and served per second, JPEG bytes per frame, the latency added between ``publish`` and a
viewer holding the whole frame (median and 95th percentile, wall clock: encoding + loopback),
and the wall time of one ``publish`` call (what the pilot's vision thread pays).
"""

from __future__ import annotations

import argparse
import socket
import statistics
import threading
import time

import numpy as np

from skeye.cliargs import positive_int
from skeye.pilot.video_server import CameraFrame, VideoServer
from skeye.vision.camera import render_pad_view
from skeye.vision.pad import SKEYE_4
from skeye.wire.video import Detection, Frame, Role, Subscribe, VideoConnection

FOV_H_RAD = 1.309


def _viewer(port: int, got: dict[int, float], sizes: list[int], stop: threading.Event) -> None:
    sock = socket.create_connection(("127.0.0.1", port), timeout=30)
    conn = VideoConnection(Role.CLIENT)
    sock.sendall(conn.send(Subscribe(1000.0)))
    sock.settimeout(0.5)
    try:
        while not stop.is_set():
            try:
                data = sock.recv(1 << 20)
            except TimeoutError:
                continue
            if not data:
                return
            now = time.perf_counter()
            for msg in conn.receive_data(data):
                if isinstance(msg, Frame):
                    got.setdefault(msg.frame_number, now)
                    sizes.append(len(msg.jpeg))
    finally:
        sock.close()


def side(text: str) -> int:
    """``--width`` / ``--height``: a frame's side in pixels, 2 at least (the video port's)."""
    value = positive_int(text)
    if value < 2:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 2 (pixels), got {text!r}")
    return value


def quality(text: str) -> int:
    """``--quality``: a JPEG quality, 1..100."""
    value = positive_int(text)
    if value > 100:
        raise argparse.ArgumentTypeError(f"must be a whole number 1..100, got {text!r}")
    return value


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--width", type=side, default=800)
    ap.add_argument("--height", type=side, default=600)
    ap.add_argument("--clients", type=int, default=1)
    ap.add_argument("--rate", type=float, default=30.0,
                    help="frames/s published (the hummingbird's camera: 30); a high rate shows "
                         "the most the port serves")
    ap.add_argument("--quality", type=quality, default=80)
    args = ap.parse_args()
    if not args.rate > 0 or args.frames < 1 or args.clients < 1:
        ap.error("--rate > 0, --frames >= 1 and --clients >= 1 needed")

    rng = np.random.default_rng(0)
    views = []
    for i in range(10):
        grey = render_pad_view(SKEYE_4, args.width, args.height, FOV_H_RAD, 0.6 + 0.15 * i,
                               (0.05 * i - 0.2, 0.1), noise_sigma=3.0, blur_px=0.7, rng=rng)
        views.append(np.repeat(grey[:, :, None], 3, axis=2))
    stop = threading.Event()
    with VideoServer(port=0, fov_h_rad=FOV_H_RAD, jpeg_quality=args.quality, max_fps=1000.0,
                     max_clients=max(4, args.clients)) as server:
        received = [dict[int, float]() for _ in range(args.clients)]
        sizes: list[int] = []
        threads = [threading.Thread(target=_viewer, args=(server.port, got, sizes, stop),
                                    daemon=True) for got in received]
        for t in threads:
            t.start()
        while sum(1 for c in server.clients() if c.state == "streaming") < args.clients:
            time.sleep(0.01)
        published: dict[int, float] = {}
        publish_s: list[float] = []
        start = time.perf_counter()
        for n in range(1, args.frames + 1):
            frame = CameraFrame(n, n / 30.0, views[n % len(views)], Detection(False), 0.0)
            t0 = time.perf_counter()
            server.publish(frame)
            t1 = time.perf_counter()
            published[n] = t0
            publish_s.append(t1 - t0)
            delay = start + n / args.rate - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        elapsed = time.perf_counter() - start
        time.sleep(0.5)  # the last frames in flight
        stop.set()
        for t in threads:
            t.join(5)
        encoded = server.encoded

    latencies = [got[n] - published[n] for got in received for n in got if n in published]
    served = sum(len(got) for got in received)
    print(f"video port: {args.width}x{args.height} pad views, JPEG quality {args.quality}, "
          f"{args.clients} client(s), publishing {args.rate:g} frames/s")
    print(f"  published {args.frames} frames in {elapsed:.2f} s "
          f"({args.frames / elapsed:.1f} frames/s); encoded {encoded}")
    print(f"  served {served} frames ({served / elapsed / args.clients:.1f} frames/s per client),"
          f" JPEG {statistics.median(sizes) / 1024:.1f} kB median")
    if latencies:
        lat = sorted(latencies)
        print(f"  added latency publish -> viewer: median {statistics.median(lat) * 1e3:.1f} ms,"
              f" 95th percentile {lat[int(0.95 * (len(lat) - 1))] * 1e3:.1f} ms")
    pub = sorted(publish_s)
    print(f"  publish() call: median {statistics.median(pub) * 1e6:.0f} us, "
          f"max {pub[-1] * 1e6:.0f} us (the vision thread's whole cost)")


if __name__ == "__main__":
    main()
