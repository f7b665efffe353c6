"""Image server throughput and latency: frames/s and publish-to-receipt latency per client.

A publisher thread renders frames with a pluggable ``frame_source(number) -> (H, W, 3) uint8 RGB``
(synthetic 800x600 gradients by default; the simulator will pass real MuJoCo renders) at a fixed
rate or as fast as it can, into an :class:`ImageServer`. Clients run in their own processes, as
they would in use, stream with META on and note when each frame arrives; latency is receipt
time minus publish time (both CLOCK_MONOTONIC, shared by the processes on Linux).

Run: ``.venv/bin/python benchmarks/bench_image_server.py [--seconds 3]``
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.synchronize import Event as EventType

import cv2
import numpy as np

from skeye.cliargs import positive_float
from skeye.control.image_client import ImageClient
from skeye.sim.image_server import Frame, FrameBuffer, ImageServer
from skeye.wire.images import ImageFormat

FrameSource = Callable[[int], np.ndarray]


def gradient_source(width: int = 800, height: int = 600) -> FrameSource:
    """A synthetic camera: a colour gradient with the frame number drawn in."""
    y, x = np.mgrid[0:height, 0:width]
    base = np.stack(
        [x * 255 // (width - 1), y * 255 // (height - 1), (x + y) * 255 // (width + height - 2)],
        axis=-1,
    ).astype(np.uint8)

    def render(number: int) -> np.ndarray:
        img = base.copy()
        cv2.putText(img, str(number), (40, 320), cv2.FONT_HERSHEY_SIMPLEX, 5, (255, 255, 255), 12)
        return img

    return render


@dataclass(frozen=True)
class Result:
    """One configuration's figures."""

    target_fps: float | None
    kind: str
    clients: int
    publish_fps: float
    client_fps: float  # mean over clients
    latency_p50_ms: float
    latency_p99_ms: float


def _client_main(
    port: int, kind: str, quality: int, seconds: float, start: EventType, out: mp.Queue
) -> None:
    receipts: list[tuple[int, float]] = []
    with ImageClient("127.0.0.1", port, timeout_s=10.0) as client:
        client.set_format(kind, quality)
        client.set_meta(True)
        start.wait()
        end = time.monotonic() + seconds
        for frame in client.stream(1000.0):
            now = time.monotonic()
            assert frame.meta is not None
            receipts.append((frame.meta.frame_number, now))
            if now >= end:
                break
    out.put(receipts)


def run_config(
    frame_source: FrameSource,
    target_fps: float | None,
    kind: str,
    clients: int,
    seconds: float,
    quality: int = 85,
) -> Result:
    """Measure one configuration (``target_fps`` None: publish as fast as possible)."""
    buffer = FrameBuffer()
    published: dict[int, float] = {}
    stop = threading.Event()

    def publish() -> None:
        number = 0
        next_s = time.monotonic()
        while not stop.is_set():
            number += 1
            rgb = frame_source(number)
            published[number] = time.monotonic()
            buffer.publish(Frame("R1/Down", 1, number, number / 30.0, rgb))
            if target_fps is not None:
                next_s += 1.0 / target_fps
                stop.wait(max(0.0, next_s - time.monotonic()))

    ctx = mp.get_context("spawn")
    start = ctx.Event()
    out: mp.Queue = ctx.Queue()
    with ImageServer(buffer, port=0) as server:
        procs = [
            ctx.Process(target=_client_main, args=(server.port, kind, quality, seconds, start, out))
            for _ in range(clients)
        ]
        for proc in procs:
            proc.start()
        publisher = threading.Thread(target=publish, name="bench publisher")
        publisher.start()
        while server.client_count() < clients:
            time.sleep(0.01)
        time.sleep(0.5)  # warm-up: imports done, first frames out
        first = max(published)
        t0 = time.monotonic()
        start.set()
        receipts = [out.get(timeout=seconds + 30.0) for _ in procs]
        t1 = time.monotonic()
        last = max(published)
        stop.set()
        publisher.join()
        for proc in procs:
            proc.join(10.0)
    latencies = [at - published[n] for rec in receipts for n, at in rec if n in published]
    rates = [(len(rec) - 1) / (rec[-1][1] - rec[0][1]) if len(rec) > 1 else 0.0 for rec in receipts]
    lat_ms = np.array(latencies) * 1e3
    return Result(
        target_fps,
        kind,
        clients,
        (last - first) / (t1 - t0),
        float(np.mean(rates)),
        float(np.percentile(lat_ms, 50)),
        float(np.percentile(lat_ms, 99)),
    )


def main(frame_source: FrameSource | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=positive_float, default=3.0,
                        help="measuring time per config")
    args = parser.parse_args()
    source = frame_source or gradient_source()
    print(f"frame {source(1).shape[1]}x{source(1).shape[0]}, {args.seconds:g} s per config")
    print(
        f"{'publisher':>10} {'format':>8} {'clients':>7} {'pub fps':>8} {'client fps':>10} "
        f"{'p50 ms':>7} {'p99 ms':>7}"
    )
    for target in (30.0, None):
        for kind in (ImageFormat.RAW.value, ImageFormat.JPEG.value, ImageFormat.PNG.value):
            for clients in (1, 4):
                r = run_config(source, target, kind.lower(), clients, args.seconds)
                label = "max" if target is None else f"{target:g} fps"
                fmt = "JPEG q85" if kind == "JPEG" else kind
                print(
                    f"{label:>10} {fmt:>8} {clients:>7} {r.publish_fps:8.1f} {r.client_fps:10.1f} "
                    f"{r.latency_p50_ms:7.1f} {r.latency_p99_ms:7.1f}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
