"""Simulator benchmark: lockstep real-time factor and control-protocol latency.

Runs ``skeye sim --mode lockstep`` as its own process (as users run it) and measures:

- real-time factor with 1 vehicle, every non-camera sensor streamed to a reading client;
- real-time factor with 10 vehicles (10 connections, each with its robot and stream);
- PING round-trip latency p50/p99 over loopback;
- DRIVE-to-effect latency p50/p99: DRIVE immediately followed by PING; the server handles a
  connection's lines in order and returns from DRIVE only once the engine has applied it, so the
  PING's answer marks the moment the new set-point is in effect;
- the real-time factor of the same 1-vehicle flight stepped in this process, without server or
  sockets (``skeye.sim.engine.Simulation`` with a sink that keeps the typed readings), and with
  those readings encoded as protocol lines: what TCP and the client cost, by difference.

Each real-time factor is measured ``--repeats`` times (fresh robots each time) and printed as
the best and the median: on a shared machine the slowest runs measure the neighbours, and the
best run is the one closest to what the code costs (as ``timeit`` reports its minimum).

The simulator's hot path is compiled with mypyc (skeye.native); a second simulator process runs
the same code from its Python sources (``SKEYE_PURE_PYTHON=1``), and the two are measured
alternately, so the printed speed-up is a ratio taken within one run (``--no-pure`` skips it).

The built-in robots' boards (controller, motor model) run at 250 Hz on the 1 kHz physics step;
``--board-rate 1000`` measures a copy of the Hummingbird whose board runs at every physics step.

The Hummingbird's IMU carries its in-flight vibration (docs/physics.md), so every figure is with
vibration on; the in-process runs are repeated, alternately, on a copy of the Hummingbird whose
IMU vibration is zero, and the on / off ratio printed: what the vibration model costs.

Usage: python benchmarks/bench_sim.py [--sim-seconds 20] [--timestep 0.001] [--repeats 3]
       [--board-rate HZ] [--no-pure]
"""

from __future__ import annotations

import argparse
import math
import os
import socket
import statistics
import tempfile
import time
import tomllib
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from importlib import resources
from pathlib import Path

from skeye import native
from skeye.cliargs import float_at_least, positive_float, positive_int
from skeye.errors import SkeyeError
from skeye.processes import start_skeye, stop_process

STEP_S = 0.5  # sim seconds per STEP of the lockstep runs


def robot_dir_with_board_rate(folder: Path, board_rate_hz: float) -> str:
    """Write a copy of the Hummingbird whose board runs at ``board_rate_hz``; return its class."""
    text = (resources.files("skeye.robots") / "hummingbird.toml").read_text()
    name = f"hummingbird_board{board_rate_hz:g}"
    lines = []
    for line in text.splitlines():
        if line.startswith("name ="):
            line = f'name = "{name}"'
        elif line.startswith("board_rate_hz"):
            line = f"board_rate_hz = {board_rate_hz:g}"
        lines.append(line)
    text = "\n".join(lines) + "\n"
    assert tomllib.loads(text)["board_rate_hz"] == board_rate_hz
    (folder / f"{name}.toml").write_text(text)
    return name


def robot_dir_without_vibration(folder: Path) -> str:
    """Write a copy of the Hummingbird whose IMU has no vibration; return its class."""
    text = (resources.files("skeye.robots") / "hummingbird.toml").read_text()
    name = "hummingbird_still"
    lines = []
    in_imu = False
    for line in text.splitlines():
        if line.startswith("name ="):
            line = f'name = "{name}"'
        if line.startswith("type ="):
            in_imu = line.split("=")[1].strip().strip('"') in ("Accelerometer", "Gyro")
        lines.append(line)
        if in_imu and line.startswith("name ="):
            lines += ["vibration_rotor = 0", "vibration_blade_pass = 0",
                      "vibration_broadband = 0"]
    text = "\n".join(lines) + "\n"
    sensors = tomllib.loads(text)["sensors"]
    assert sum(1 for s in sensors if s.get("vibration_rotor") == 0) == 2
    (folder / f"{name}.toml").write_text(text)
    return name


@contextmanager
def sim_process(timestep: float, pure: bool = False, robot_dir: str | None = None,
                estimator: str | None = None) -> Iterator[int]:
    extra = ["--robot-dir", robot_dir] if robot_dir else []
    if estimator is not None:
        extra += ["--estimator", estimator]
    proc, found = start_skeye(
        ["sim", "--mode", "lockstep", "--port", "0", "--timestep", str(timestep), *extra],
        [r"127\.0\.0\.1:(\d+)"], "skeye sim",
        env={native.PURE_PYTHON_ENV: "1" if pure else "0"},
    )
    try:
        yield int(found[0].group(1))
    finally:
        stop_process(proc)


class Conn:
    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port))
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.buf = b""
        self.lines = 0
        self.wait_for(b"NFO")

    def send(self, text: str) -> None:
        self.sock.sendall(text.encode() + b"\r\n")

    def wait_for(self, marker: bytes) -> bytes:
        """Read lines until one starts with ``marker``; count the others."""
        while True:
            *complete, self.buf = self.buf.split(b"\r\n")
            for i, line in enumerate(complete):
                if line.startswith(marker):
                    self.lines += i
                    self.buf = b"\r\n".join([*complete[i + 1 :], self.buf])
                    return line
            self.lines += len(complete)
            data = self.sock.recv(1 << 20)
            if not data:
                raise ConnectionError("simulator closed the connection")
            self.buf += data

    def spawn(self, robot_class: str, name: str, location: str) -> None:
        """INIT a robot; a refusal (ERR) is raised with the simulator's reason, not waited out."""
        self.send(f"INIT {{ClassName {robot_class}}} {{Name {name}}} {{Location {location}}}")
        while True:
            line = self.wait_for(b"")
            if line.startswith(b"RES {Command INIT}"):
                return
            if line.startswith(b"ERR {Command INIT}"):
                raise RuntimeError(f"simulator refused INIT {robot_class}: {line.decode()}")
            self.lines += 1  # a stream line, counted as wait_for counts those it skips

    def drain(self) -> None:
        self.sock.setblocking(False)
        try:
            while True:
                data = self.sock.recv(1 << 20)
                if not data:
                    break
                self.lines += data.count(b"\r\n")
        except BlockingIOError:
            pass
        finally:
            self.sock.setblocking(True)


def measure_rtf(
    port: int, vehicles: int, sim_seconds: float, timestep: float, robot_class: str
) -> tuple[float, int]:
    conns = [Conn(port) for _ in range(vehicles)]
    for i, c in enumerate(conns):
        c.spawn(robot_class, f"B{i}", f"{i * 2.0},0,-1.5")
    driver = conns[0]
    steps_per_call = round(STEP_S / timestep)
    calls = int(sim_seconds / STEP_S)
    start = time.perf_counter()
    for _ in range(calls):
        driver.send(f"STEP {{Count {steps_per_call}}}")
        driver.wait_for(b"RES {Command STEP}")
        for c in conns[1:]:
            c.drain()
    wall = time.perf_counter() - start
    lines = sum(c.lines for c in conns)
    for c in conns:
        c.sock.close()
    time.sleep(0.3)
    return calls * steps_per_call * timestep / wall, lines


def measure_latency(port: int, samples: int, robot_class: str) -> tuple[list[float], list[float]]:
    c = Conn(port)
    c.spawn(robot_class, "L1", "0,0,-1")
    ping, drive = [], []
    for i in range(samples):
        t = time.perf_counter()
        c.send(f"PING {{Id p{i}}}")
        c.wait_for(f"RES {{Command PING}} {{Id p{i}}}".encode())
        ping.append(time.perf_counter() - t)
        t = time.perf_counter()
        c.send(f"DRIVE {{LinearVelocity {0.1 * (i % 5):.1f}}}\r\nPING {{Id d{i}}}")
        c.wait_for(f"RES {{Command PING}} {{Id d{i}}}".encode())
        drive.append(time.perf_counter() - t)
        if i % 50 == 0:
            c.send("STEP {Count 10}")
            c.wait_for(b"RES {Command STEP}")
    c.sock.close()
    return ping, drive


def reference_loop_ms() -> float:
    """A fixed pure-Python workload (best of 5), printed with the figures: on a shared machine
    it tells a slow run of the code from a run on a slow moment of the machine."""
    best = math.inf
    for _ in range(5):
        start = time.perf_counter()
        x = 0.0
        for i in range(300_000):
            x += (i * 0.5) ** 0.5
        best = min(best, time.perf_counter() - start)
    return best * 1000.0


def measure_in_process_rtf(
    n: int, sim_seconds: float, timestep: float, robot_class: str,
    robot_dir: str | None = None, *, encode: bool = False,
) -> tuple[float, int]:
    """Step ``n`` vehicles in this process for ``sim_seconds``: (real-time factor, readings).

    No server, runner or socket: each robot's sink keeps its readings (``encode``: as protocol
    lines, through the server's encoder)."""
    from skeye.sim.engine import Simulation
    from skeye.sim.readings import Event
    from skeye.sim.stream import text_sink
    from skeye.sim.world import load_world

    events: list[Event] = []
    chunks: list[bytes] = []
    dirs = (Path(robot_dir),) if robot_dir else ()
    sim = Simulation(load_world("pad"), seed=1, timestep_s=timestep, robot_dirs=dirs)
    for i in range(n):
        sink = text_sink(chunks.append) if encode else events.extend
        sim.spawn(robot_class, name=f"B{i}", sink=sink, location_ned_m=(i * 2.0, 0.0, -1.5))
    steps = round(sim_seconds / timestep)
    started = time.perf_counter()
    for _ in range(0, steps, 100):  # as a client's STEP {Count 100} would
        sim.step(100)
    wall_s = time.perf_counter() - started
    count = sum(chunk.count(b"\n") for chunk in chunks) if encode else len(events)
    return sim.time_s / wall_s, count


def pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] * 1000.0


# --sim-seconds: at least one lockstep STEP (a shorter run measured nothing)
sim_seconds = float_at_least(STEP_S, "one STEP of the lockstep runs")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sim-seconds", type=sim_seconds, default=20.0)
    parser.add_argument("--timestep", type=positive_float, default=0.001)
    parser.add_argument("--samples", type=positive_int, default=2000)
    parser.add_argument("--repeats", type=positive_int, default=3)
    parser.add_argument("--no-pure", action="store_true",
                        help="skip the pure-Python simulator (no speed-up ratio)")
    parser.add_argument("--estimator", choices=("onboard", "truth"), default=None,
                        help="the boards' estimator (skeye sim --estimator; default: the robot "
                        "file's)")
    parser.add_argument("--board-rate", type=positive_float, default=None, metavar="HZ",
                        help="fly a Hummingbird whose board runs at HZ (default: its own 250 Hz)")
    args = parser.parse_args()
    try:
        run(args)
    except SkeyeError as exc:  # the simulator refused what it was given (--timestep 1)
        parser.exit(1, f"bench_sim: {exc}\n")


def run(args: argparse.Namespace) -> None:
    with ExitStack() as stack:
        robot_class, robot_dir, board = "hummingbird", None, "250 Hz (the robot's own)"
        if args.board_rate is not None:
            robot_dir = stack.enter_context(tempfile.TemporaryDirectory(prefix="skeye-bench-"))
            robot_class = robot_dir_with_board_rate(Path(robot_dir), args.board_rate)
            board = f"{args.board_rate:g} Hz"
        print(f"machine: {os.cpu_count()} cores; physics step {args.timestep * 1000:g} ms; "
              f"board {board}; estimator {args.estimator or 'per robot file'}; lockstep")
        status = native.decide(environ={})
        print(status.describe())  # what the (compiled) simulator process will run
        print(f"CPU reference loop before: {reference_loop_ms():.1f} ms (lower = faster machine)")
        port = stack.enter_context(
            sim_process(args.timestep, robot_dir=robot_dir, estimator=args.estimator)
        )
        pure_port = None
        if not args.no_pure and status.compiled:
            pure_port = stack.enter_context(
                sim_process(args.timestep, pure=True, robot_dir=robot_dir,
                            estimator=args.estimator)
            )
        for n, target in ((1, 50.0), (10, 5.0)):
            runs, pure_runs = [], []
            for _ in range(max(1, args.repeats)):  # alternate, so both see the same host
                runs.append(measure_rtf(port, n, args.sim_seconds, args.timestep, robot_class))
                if pure_port is not None:
                    pure_runs.append(
                        measure_rtf(pure_port, n, args.sim_seconds, args.timestep, robot_class)
                    )
            rtfs = [rtf for rtf, _ in runs]
            print(
                f"real-time factor, {n:2d} vehicle(s), all non-camera sensors streamed: "
                f"best {max(rtfs):6.1f}x  median {statistics.median(rtfs):6.1f}x  "
                f"(target >= {target:g}x; runs {', '.join(f'{r:.1f}' for r in rtfs)}; "
                f"{runs[0][1]} lines received per run)"
            )
            if pure_runs:
                pure = [rtf for rtf, _ in pure_runs]
                print(
                    f"  same code from its Python sources: best {max(pure):6.1f}x  median "
                    f"{statistics.median(pure):6.1f}x; compiled / pure "
                    f"{statistics.median(rtfs) / statistics.median(pure):.2f} (medians)"
                )
        ping, drive = measure_latency(port, args.samples, robot_class)
        print(
            f"PING round trip:       p50 {pct(ping, 0.5):.3f} ms  p99 {pct(ping, 0.99):.3f} ms"
            f"  (target p99 < 2 ms; {len(ping)} samples)"
        )
        print(
            f"DRIVE-to-effect:       p50 {pct(drive, 0.5):.3f} ms  p99 {pct(drive, 0.99):.3f} ms"
            f"  (target p99 < 2 ms)"
        )
        print(f"mean PING {statistics.mean(ping) * 1000:.3f} ms")
        for encode in (False, True):
            runs_in = [measure_in_process_rtf(1, args.sim_seconds, args.timestep, robot_class,
                                              robot_dir, encode=encode)
                       for _ in range(max(1, args.repeats))]
            rtfs = [rtf for rtf, _ in runs_in]
            what = "readings encoded as lines" if encode else "typed readings kept"
            print(f"in-process, 1 vehicle, no TCP, {what}: best {max(rtfs):6.1f}x  median "
                  f"{statistics.median(rtfs):6.1f}x  ({runs_in[0][1]} per run; "
                  f"{native.status().describe()} in this process)")
        if args.board_rate is None:
            still_dir = stack.enter_context(tempfile.TemporaryDirectory(prefix="skeye-bench-"))
            still = robot_dir_without_vibration(Path(still_dir))
            on, off = [], []
            for _ in range(max(1, args.repeats)):  # alternate, so both see the same host
                on.append(measure_in_process_rtf(1, args.sim_seconds, args.timestep,
                                                 robot_class, robot_dir)[0])
                off.append(measure_in_process_rtf(1, args.sim_seconds, args.timestep, still,
                                                  still_dir)[0])
            print(f"in-process, 1 vehicle, IMU vibration on: median {statistics.median(on):6.1f}x"
                  f"; off: median {statistics.median(off):6.1f}x; on / off "
                  f"{statistics.median(on) / statistics.median(off):.2f}")
    print(f"CPU reference loop after: {reference_loop_ms():.1f} ms")


if __name__ == "__main__":
    main()
