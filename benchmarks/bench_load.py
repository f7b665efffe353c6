"""Load benchmark: many control and image clients at once against one real-time simulator.

Starts ``skeye sim --image-port 0`` (real time) as its own process, connects ``--control``
clients (each INITs a hummingbird and reads its whole stream on its own thread) and ``--image``
clients (each streams JPEG frames of one robot's down camera at 30 frames/s), then measures over
``--seconds``:

- real-time factor: sim time advance / wall time, from PING answers at the start and the end;
- PING round trip p50/max while loaded;
- stream lines per control client per second, and lines the simulator dropped (none expected);
- frames per second received by each image client.

Usage: python benchmarks/bench_load.py [--control 20] [--image 8] [--seconds 30]
"""

from __future__ import annotations

import argparse
import json
import re
import socket
import statistics
import sys
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from skeye.cliargs import positive_float, positive_int
from skeye.cliargs import seed as non_negative_int
from skeye.control.image_client import ImageClient
from skeye.processes import start_skeye, stop_process


class ControlClient:
    def __init__(self, port: int, index: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=30)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.index = index
        self.lines = 0
        self.pings: dict[str, tuple[float, float]] = {}  # id -> (sent wall, answered sim time)
        self.sent: dict[str, float] = {}
        self.rtt_s: list[float] = []
        self.init_ok = threading.Event()
        self.closed = False
        self._buf = b""
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def send(self, text: str) -> None:
        self.sock.sendall(text.encode() + b"\r\n")

    def _read(self) -> None:
        try:
            while True:
                data = self.sock.recv(1 << 20)
                if not data:
                    break
                *lines, self._buf = (self._buf + data).split(b"\r\n")
                now = time.monotonic()
                for line in lines:
                    self.lines += 1
                    if line.startswith(b"RES {Command INIT}"):
                        self.init_ok.set()
                    elif line.startswith(b"RES {Command PING}"):
                        m = re.search(rb"\{Id (\S+)\} \{Time ([\d.]+)\}", line)
                        if m:
                            ident = m.group(1).decode()
                            self.pings[ident] = (now, float(m.group(2)))
                            self.rtt_s.append(now - self.sent.get(ident, now))
        except OSError:
            pass
        self.closed = True

    def ping(self, ident: str, timeout_s: float = 10.0) -> tuple[float, float]:
        self.sent[ident] = time.monotonic()
        self.send(f"PING {{Id {ident}}}")
        deadline = time.monotonic() + timeout_s
        while ident not in self.pings:
            if time.monotonic() > deadline:
                raise TimeoutError(f"no answer to PING {ident}")
            time.sleep(0.001)
        return self.pings[ident]


class ImageStreamer:
    def __init__(self, port: int, camera: str, fps: float) -> None:
        self.client = ImageClient("127.0.0.1", port, timeout_s=30)
        self.client.select_camera(camera)
        self.client.set_format("jpeg", 80)
        self.fps = fps
        self.times: list[float] = []
        self.errors = 0
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        try:
            for _ in self.client.stream(self.fps):
                self.times.append(time.monotonic())
                if self._stop.is_set():
                    break
        except Exception:
            self.errors += 1

    def rate(self, start: float, end: float) -> float:
        return sum(1 for t in self.times if start <= t <= end) / (end - start)

    def close(self) -> None:
        self._stop.set()
        self.thread.join(5)
        self.client.close()


@dataclass
class LoadResult:
    control_clients: int
    image_clients: int
    seconds: float
    rtf: float
    ping_rtt_p50_ms: float
    ping_rtt_max_ms: float
    lines_per_client_s: float
    frames_per_client_s: list[float]
    image_errors: int
    sim_alive: bool
    sim_seconds: float = 0.0  # sim time that passed during the measurement
    lines_per_client_sim_s: float = 0.0  # per second of sim time: independent of host load
    frames_per_client_sim_s: tuple[float, ...] = ()


def run_load(control: int, image: int, seconds: float, fps: float = 30.0,
             sim_seconds: float | None = None) -> LoadResult:
    """Measure for ``seconds`` of wall time or, with ``sim_seconds``, until that much sim time
    has passed (at most ``max(120, 60 * sim_seconds)`` wall seconds: a host too busy to reach
    it gives a result whose ``sim_seconds`` says how far it got)."""
    proc, found = start_skeye(
        ["sim", "--port", "0", "--image-port", "0"],
        [r"control protocol on [\d.]+:(\d+)", r"image server on [\d.]+:(\d+)"],
        "skeye sim",
    )
    ports = {"control": int(found[0].group(1)), "image": int(found[1].group(1))}
    clients: list[ControlClient] = []
    streamers: list[ImageStreamer] = []
    try:
        for i in range(control):
            c = ControlClient(ports["control"], i)
            c.send(
                f"INIT {{ClassName hummingbird}} {{Name L{i}}} "
                f"{{Location {(i % 5) * 3.0},{(i // 5) * 3.0},-2}}"
            )
            clients.append(c)
        for c in clients:
            if not c.init_ok.wait(30):
                raise RuntimeError(f"client {c.index}: INIT not answered")
        for j in range(image):
            streamers.append(ImageStreamer(ports["image"], f"L{j % max(control, 1)}/Down", fps))
        time.sleep(1.0)  # settle
        pinger = clients[0]
        wall0, sim0 = pinger.ping("start")
        lines0 = sum(c.lines for c in clients)
        t_start = time.monotonic()
        n = 0
        wall_limit = seconds if sim_seconds is None else max(120.0, 60.0 * sim_seconds)
        sim_now = sim0
        while time.monotonic() - t_start < wall_limit:
            if sim_seconds is not None and sim_now - sim0 >= sim_seconds:
                break
            time.sleep(0.25)
            n += 1
            sim_now = pinger.ping(f"p{n}", timeout_s=60.0)[1]
        wall1, sim1 = pinger.ping("end")
        t_end = time.monotonic()
        lines = sum(c.lines for c in clients) - lines0
        rtts = [r * 1000 for r in pinger.rtt_s]
        sim_s = max(sim1 - sim0, 1e-9)
        return LoadResult(
            control_clients=control,
            image_clients=image,
            seconds=t_end - t_start,
            rtf=(sim1 - sim0) / (wall1 - wall0),
            ping_rtt_p50_ms=statistics.median(rtts),
            ping_rtt_max_ms=max(rtts),
            lines_per_client_s=lines / max(control, 1) / (t_end - t_start),
            frames_per_client_s=[round(s.rate(t_start, t_end), 2) for s in streamers],
            image_errors=sum(s.errors for s in streamers),
            sim_alive=proc.poll() is None and not any(c.closed for c in clients),
            sim_seconds=sim1 - sim0,
            lines_per_client_sim_s=lines / max(control, 1) / sim_s,
            frames_per_client_sim_s=tuple(
                round(s.rate(t_start, t_end) * (t_end - t_start) / sim_s, 2) for s in streamers
            ),
        )
    finally:
        for s in streamers:
            s.close()
        for c in clients:
            c.sock.close()
        stop_process(proc, timeout_s=10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--control", type=positive_int, default=20)
    parser.add_argument("--image", type=non_negative_int, default=8)
    parser.add_argument("--seconds", type=positive_float, default=30.0)
    parser.add_argument("--fps", type=positive_float, default=30.0)
    args = parser.parse_args()
    result = run_load(args.control, args.image, args.seconds, args.fps)
    print(json.dumps(asdict(result), indent=2))


if __name__ == "__main__":
    main()
