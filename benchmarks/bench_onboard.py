"""What the pilot costs an onboard computer, and how it flies through an AscTec LL board.

``--only cpu``: the pilot as it would run on the vehicle, on this machine: ``skeye pilot``'s
pieces in this process (``PilotServer``, the ``asctec-ll://`` airframe, the ``sim://`` camera
source, the pad vision), the simulator with its emulated LL board in a child process
(``skeye sim --ll-board R1=pty``, lockstep, the Hummingbird's 800x600 camera). A scripted ground
client takes off and holds over the pad (PAD_MODE 1) for ``--hold-s`` of sim time. The CPU time
of every thread of the pilot (Linux ``/proc/self/task``) is split by role: the control loop
(boards, the LL board's cycle in lockstep, the vision's navigation), the LL line's reader,
the vision worker (fetching and detecting frames) and the ground link. Printed: CPU per
control tick (20 Hz) and per camera frame, the detector's own time per frame, the process's
peak memory, and what that is as a share of one core at 20 ticks and 30 frames a second.

``--only hil``: E2's pad hold (0.70 m above the pad, random force F_max 0.3 N, PAD_MODE 1, 5 cm
deadband, 0.3 m/s, ``--e2-s`` of sim time, 20 by default as in ``skeye validate --quick``) and a
pad landing (PAD_MODE 2 from 1.2 m, 0.5 m off the pad), each flown on ``sim://`` and through
the emulated LL board on a pseudo-terminal, same seed, full camera, lockstep with the time
granted by the ground (reproducible), each pad mode started at the same sim time on both (the
random force is a sequence in sim time: both flights meet the same gusts). Printed: std /
max distance from the pad centre, time to land and the miss, per airframe and their ratio
(docs/pilot.md, "On an AscTec LL board").

Usage: ``python benchmarks/bench_onboard.py [--only cpu|hil] [--seeds 1 2 3]``. Figures from
a loaded machine are not CPU budgets: state ``uptime`` with them.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import resource
import shlex
import statistics
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from skeye.cliargs import positive_float
from skeye.cliargs import seed as seed_value
from skeye.hil.cli import parse_ll_board, start_ll_board
from skeye.link.vehicle import Vehicle
from skeye.pilot.airframe import AirframeOptions, open_airframe
from skeye.pilot.cli import camera_vision_factory, open_camera_for, pad_vision_factory
from skeye.pilot.server import PilotServer
from skeye.processes import start_skeye, stop_process
from skeye.wire.packets import NavState, SkeyeMask

TICK_HZ = 20.0
# --only cpu's simulator, and its start-up line naming the pilot's airframe and camera URIs
CPU_SIM = ["sim", "--mode", "lockstep", "--port", "0", "--seed", "1", "--image-port", "0",
           "--ll-board", "R1=pty"]
LL_LINE = r"LL board on \S+ \(skeye pilot --airframe (\S+) --camera (\S+)\)"


def pilot_uris(line: re.Match[str]) -> tuple[str, str]:
    """The airframe and camera URIs of the LL board's start-up line: it quotes them for a shell
    (``'asctec-ll://serial/dev/pts/0?lockstep=1'``)."""
    return shlex.split(line.group(1))[0], shlex.split(line.group(2))[0]
CAMERA_FPS = 30.0


def thread_cpu_s() -> dict[int, tuple[str, float]]:
    """CPU seconds (user + system) of every Python thread of this process, by native id,
    with the thread's name."""
    ticks = os.sysconf("SC_CLK_TCK")
    out = {}
    for thread in threading.enumerate():
        tid = thread.native_id
        try:
            stat = Path(f"/proc/self/task/{tid}/stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        out[int(tid or 0)] = (thread.name, (int(fields[11]) + int(fields[12])) / ticks)
    return out


def role(name: str) -> str:
    if name.startswith("pilot-loop"):
        return "control loop"
    if name.startswith("pilot-vision"):
        return "vision worker"
    if name.startswith("pilot-read") or name.startswith("pilot-send") or name == "pilot-accept":
        return "ground link"
    return ""


def cpu(hold_s: float) -> None:
    sim, found = start_skeye(CPU_SIM, [r"image server on [\d.]+:(\d+)", LL_LINE], "skeye sim")
    try:
        with ExitStack() as stack:
            airframe_uri, camera_uri = pilot_uris(found[1])
            airframe = open_airframe(airframe_uri, AirframeOptions())
            stack.callback(airframe.close)
            camera = open_camera_for(camera_uri, airframe, "R1", None, 30.0)
            stack.callback(camera.close)
            pilot = stack.enter_context(PilotServer(
                airframe, port=0, lockstep=True, lockstep_rate=0, tick_s=1 / TICK_HZ,
                vision=camera_vision_factory(camera, camera.fov_h_rad, lockstep=True)))
            vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=60.0))
            # The LL line's reader is the airframe's Vehicle reader; the ground client's is ours.
            ll_reader = airframe.vehicle._reader.thread.native_id  # type: ignore[attr-defined]
            ground_reader = vehicle._reader.thread.native_id
            vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.05)
            vehicle.take_off(0.62)
            vehicle.wait_state(NavState.HOLDING, timeout_s=300)
            vehicle.pad_mode(1, deadband_m=0.05, max_speed_m_s=0.3)
            vision = pilot.vision
            t0 = airframe.snapshot().time_s
            cpu0, frames0 = thread_cpu_s(), vision.stats.frames
            wall0 = time.monotonic()
            while airframe.snapshot().time_s < t0 + hold_s:
                time.sleep(0.05)
            cpu1, frames1 = thread_cpu_s(), vision.stats.frames
            wall = time.monotonic() - wall0
            sim_s = airframe.snapshot().time_s - t0
            detect_s = vision.stats.processing_s
    finally:
        stop_process(sim)
    per_role: dict[str, float] = {}
    for tid, (name, seconds) in cpu1.items():
        used = seconds - cpu0.get(tid, (name, 0.0))[1]
        label = "LL line reader" if tid == ll_reader else (
            "" if tid == ground_reader else role(name))
        if label:
            per_role[label] = per_role.get(label, 0.0) + used
    ticks = sim_s * TICK_HZ
    frames = frames1 - frames0
    tick_cpu = (per_role.get("control loop", 0.0) + per_role.get("LL line reader", 0.0)
                + per_role.get("ground link", 0.0)) / ticks
    frame_cpu = per_role.get("vision worker", 0.0) / max(1, frames)
    rss_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"pilot on asctec-ll:// (lockstep, {sim_s:.1f} s of sim time in {wall:.1f} s wall, "
          f"{ticks:.0f} control ticks, {frames} frames of 800x600)")
    for label, seconds in sorted(per_role.items()):
        print(f"  {label:15s} {seconds:7.3f} s CPU")
    print(f"CPU per control tick: {tick_cpu * 1e3:.2f} ms (loop + LL line + ground link)")
    print(f"CPU per camera frame: {frame_cpu * 1e3:.1f} ms (fetch + grey + detect; the "
          f"newest frame's fetch + detection took {detect_s * 1e3:.1f} ms of wall time)")
    share = tick_cpu * TICK_HZ + frame_cpu * CAMERA_FPS
    print(f"at {TICK_HZ:g} ticks/s and {CAMERA_FPS:g} frames/s: {share * 100:.0f} % of one core "
          f"of this machine; peak memory of this process {rss_mib:.0f} MiB (the pilot and "
          "the benchmark's ground client; no MuJoCo)")
    print(f"load average now: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


# -- the HIL flights ---------------------------------------------------------------------------
@contextmanager
def flight(kind: str, seed: int) -> Iterator[tuple[Vehicle, PilotServer, list, list]]:
    # The simulator in this process (imported here: the cpu run measures a pilot's memory
    # without MuJoCo, as on the vehicle).
    from skeye.sim.cameras import CameraSystem
    from skeye.sim.engine import Simulation
    from skeye.sim.image_server import FrameBuffer, ImageServer
    from skeye.sim.runner import SimulationRunner
    from skeye.sim.server import ControlServer
    from skeye.sim.world import load_world
    from skeye.wire.wind import make_settings

    with ExitStack() as stack:
        sim = Simulation(load_world("pad"), seed=seed,
                         wind=make_settings("random_force", {"f_max_n": 0.3}))
        runner = stack.enter_context(SimulationRunner(sim, mode="lockstep"))
        buffer = FrameBuffer()
        stack.enter_context(CameraSystem(sim, buffer, synchronous=True))
        control = stack.enter_context(ControlServer(runner, port=0))
        images = stack.enter_context(ImageServer(buffer, port=0))
        truth: list[tuple[float, float, float]] = []

        def sample(s: Simulation) -> None:
            if "R1" in s.robots and (not truth or s.time_s >= truth[-1][0] + 0.02 - 1e-9):
                n, e, _ = s.body_state("R1").pos_ned_m
                truth.append((s.time_s, float(n), float(e)))

        sim.step_hooks.append(sample)
        options = AirframeOptions(images=f"127.0.0.1:{images.port}")
        if kind == "asctec-ll":
            board = start_ll_board(stack, parse_ll_board("R1=pty"), f"127.0.0.1:{control.port}")
            airframe = open_airframe(board.line.client_uri() + "?lockstep=1", options)
            stack.callback(airframe.close)
            assert board.camera is not None
            camera = open_camera_for(
                f"sim://127.0.0.1:{images.port}/R1/{board.camera[0]}?fov_rad={board.camera[1]!r}",
                airframe, "R1", None, 30.0)
            stack.callback(camera.close)
            vision = camera_vision_factory(camera, camera.fov_h_rad, lockstep=True)
        else:
            airframe = open_airframe(f"sim://127.0.0.1:{control.port}", options)
            stack.callback(airframe.close)
            vision = pad_vision_factory(airframe.connection, airframe.robot)  # type: ignore[attr-defined]
        pilot = stack.enter_context(PilotServer(airframe, port=0, lockstep=True, lockstep_rate=0,
                                                ground_clock=True, tick_s=0.05, vision=vision))
        vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=120.0))
        vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.01)
        granted = [airframe.snapshot().time_s]
        yield vehicle, pilot, truth, granted


def run(vehicle: Vehicle, granted: list, seconds: float) -> None:
    granted[0] += seconds
    vehicle.run_until(granted[0], timeout_s=600)


def until(vehicle: Vehicle, pilot: PilotServer, granted: list, state: NavState) -> float:
    limit = granted[0] + 120.0
    while pilot.boards.state is not state:
        if granted[0] > limit:
            raise RuntimeError(f"not {state.name} in 120 s")
        run(vehicle, granted, 0.25)
    return granted[0]


HOLD_FROM_S = 8.0  # sim time PAD_MODE HOLD starts at on both airframes (the same gusts)
LAND_FROM_S = 12.0  # ... and PAD_MODE LAND


def run_to(vehicle: Vehicle, granted: list, time_s: float) -> None:
    if granted[0] > time_s:
        raise RuntimeError(f"already at {granted[0]} s, past {time_s} s")
    run(vehicle, granted, time_s - granted[0])


def e2(kind: str, seed: int, hold_s: float) -> tuple[float, float]:
    with flight(kind, seed) as (vehicle, pilot, truth, granted):
        vehicle.take_off(0.70 - 0.081)
        until(vehicle, pilot, granted, NavState.HOLDING)
        run_to(vehicle, granted, HOLD_FROM_S)
        vehicle.pad_mode(1, deadband_m=0.05, max_speed_m_s=0.3)
        start = granted[0]
        run(vehicle, granted, hold_s)
        d = [math.hypot(n, e) for t, n, e in truth if start <= t <= start + hold_s]
    return statistics.pstdev(d), max(d)


def landing(kind: str, seed: int) -> tuple[float, float]:
    with flight(kind, seed) as (vehicle, pilot, truth, granted):
        vehicle.take_off(1.2)
        until(vehicle, pilot, granted, NavState.HOLDING)
        vehicle.move_by(right_m=0.5, speed_m_s=0.5)
        run(vehicle, granted, 0.25)
        until(vehicle, pilot, granted, NavState.HOLDING)
        run_to(vehicle, granted, LAND_FROM_S)
        start = granted[0]
        vehicle.pad_mode(2, deadband_m=0.05, max_speed_m_s=0.3)
        landed = until(vehicle, pilot, granted, NavState.LANDED)
        _, n, e = truth[-1]
    return landed - start, math.hypot(n, e)


def hil(seeds: list[int], hold_s: float) -> None:
    print(f"E2 pad hold {hold_s:g} s and a pad landing, sim:// vs asctec-ll:// on a pty, "
          "800x600 camera, lockstep")
    for seed in seeds:
        rows = {k: (e2(k, seed, hold_s), landing(k, seed)) for k in ("sim", "asctec-ll")}
        for kind, ((std, mx), (t_land, miss)) in rows.items():
            print(f"seed {seed} {kind:9s}: hold std {std * 100:.2f} cm, max {mx * 100:.2f} cm; "
                  f"landed after {t_land:.2f} s, {miss * 100:.1f} cm off", flush=True)
        (s_std, s_max), (s_t, s_miss) = rows["sim"]
        (h_std, h_max), (h_t, h_miss) = rows["asctec-ll"]
        print(f"seed {seed} ratio asctec-ll/sim: std {h_std / s_std:.2f}, max "
              f"{h_max / s_max:.2f}, landing time {h_t / s_t:.2f}, miss "
              f"{h_miss * 100:.1f} vs {s_miss * 100:.1f} cm", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", choices=("cpu", "hil"), default=None)
    ap.add_argument("--hold-s", type=positive_float, default=20.0, help="cpu: sim seconds measured")
    ap.add_argument("--e2-s", type=positive_float, default=20.0, help="hil: E2 hold, sim seconds")
    ap.add_argument("--seeds", type=seed_value, nargs="+", default=[1])
    args = ap.parse_args()
    print(f"load average at start: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    if args.only in (None, "cpu"):
        cpu(args.hold_s)
    if args.only in (None, "hil"):
        hil(args.seeds, args.e2_s)


if __name__ == "__main__":
    main()
