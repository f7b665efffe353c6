"""Pad hold and landing in real time, vision as slow as this machine makes it (issue 18).

Run: ``MUJOCO_GL=egl python benchmarks/bench_pad_realtime.py [--camera webcam|ideal]
[--flights hold land land4] [--trace]``.

What it does: with ``--camera webcam`` it first calibrates the simulated webcam as a user would
(:func:`skeye.validate.calibration.calibrate_simulated_camera`, a lockstep simulator of the
checkerboard world). Then each flight starts its own real-time ``skeye sim`` (pad world, the
chosen camera profile, images served, every line recorded) and ``skeye pilot`` (pad vision on
the served frames, with the calibration; in real time a detection is used when it is done, so
its latency is this machine's), and flies a ground client over the packet protocol:

- ``hold``: spawned 0.6 m north of the pad centre, take off to 1.5 m, PAD_MODE 1 (deadband
  0.05 m, 0.3 m/s) for 30 s of sim time;
- ``land``: spawned 3 m east of the pad, take off to 4.5 m, PAD_MODE 2 (land on the pad);
- ``land4``: spawned 4 m east, yaw -60 deg after the take-off to 4.5 m, PAD_MODE 2.

Figures from the simulator's recording (ground truth, never the pilot's view): for the hold, the
time after which the vehicle stays within 0.1 m of the pad centre and the largest offset in the
last 10 s; for a landing, the time from PAD_MODE to landed and the landed distance from the
centre. The age of the detections (the PAD reports' frame time against the pilot's sim time
when they arrived) is printed beside them.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import threading
import time
from contextlib import ExitStack
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from skeye.link.vehicle import Vehicle
from skeye.processes import start_skeye, stop_process
from skeye.validate.calibration import calibrate_simulated_camera
from skeye.validate.experiments import ground_truth
from skeye.wire.packet_units import nav_status_to_si, pad_report_to_si
from skeye.wire.packets import NavState, PadReport, SkeyeMask

FLIGHTS = {  # spawn (north, east), take-off height, yaw after take-off, PAD_MODE, sim-time limit
    "hold": ((0.6, 0.0), 1.5, 0.0, 1, 30.0),
    "land": ((0.0, 3.0), 4.5, 0.0, 2, 90.0),
    "land4": ((0.0, 4.0), 4.5, math.radians(-60.0), 2, 90.0),
}


def sim_time(vehicle: Vehicle) -> float:
    status = vehicle.nav_status()
    return nav_status_to_si(status).time_s if status is not None else 0.0


def fly(name: str, camera: str, calibration: Path | None, workdir: Path,
        trace: bool = False) -> str:
    (north, east), height_m, yaw_rad, mode, limit_s = FLIGHTS[name]
    record = workdir / f"{name}.rec"
    ages: list[float] = []
    lock = threading.Lock()
    with ExitStack() as stack:
        sim, found = start_skeye(
            ["sim", "--mode", "realtime", "--port", "0", "--image-port", "0", "--seed", "1",
             "--camera-profile", camera, "--record", str(record)],
            [r"control protocol on [\d.]+:(\d+)", r"image server on [\d.]+:(\d+)"], "skeye sim")
        stack.callback(stop_process, sim)
        args = ["pilot", "--sim", f"127.0.0.1:{found[0].group(1)}", "--port", "0",
                "--images", f"127.0.0.1:{found[1].group(1)}",
                "--location", f"{north},{east},0", "--link-timeout", "30"]
        if calibration is not None:
            args += ["--calibration", str(calibration)]
        pilot, pfound = start_skeye(args, [r"ground control on (tcp://[\d.]+:\d+)"],
                                    "skeye pilot")
        stack.callback(stop_process, pilot)
        vehicle = stack.enter_context(Vehicle.open(pfound[0].group(1), timeout_s=30.0))
        vehicle.stream(0, int(SkeyeMask.NAV_STATUS | SkeyeMask.PAD), 0.05)

        def on_packet(msg: object) -> None:
            if isinstance(msg, PadReport) and msg.found:
                report = pad_report_to_si(msg)
                with lock:
                    ages.append(sim_time(vehicle) - report.frame_time_s)

        vehicle.take_off(height_m)
        vehicle.wait_state(NavState.HOLDING, timeout_s=120)
        if yaw_rad:
            vehicle.move_by(yaw_rad=yaw_rad)
            vehicle.wait_state(NavState.HOLDING, timeout_s=60)
        vehicle.add_callback(on_packet)
        start = sim_time(vehicle)
        vehicle.pad_mode(mode, deadband_m=0.05, max_speed_m_s=0.3)
        deadline = time.monotonic() + limit_s * 20 + 60  # wall-clock backstop only
        while sim_time(vehicle) < start + limit_s and time.monotonic() < deadline:
            status = vehicle.nav_status()
            if mode == 2 and status is not None and status.state is NavState.LANDED:
                break
            time.sleep(0.1)
        end = sim_time(vehicle)
        last_status = vehicle.nav_status()
        landed = last_status is not None and last_status.state is NavState.LANDED
    track = [(t, n, e, d) for t, n, e, d, _c in ground_truth(record) if t >= start]
    truth = [(t, math.hypot(n, e)) for t, n, e, _d in track]
    if trace:
        due = start
        for t, n, e, d in track:
            if t >= due:
                print(f"  {name} t+{t - start:5.1f} s: north {n:+.2f} m, east {e:+.2f} m, "
                      f"height {-d:.2f} m", flush=True)
                due += 5.0
    with lock:
        age = (f"detection age median {statistics.median(ages) * 1e3:.0f} ms, p90 "
               f"{sorted(ages)[int(0.9 * (len(ages) - 1))] * 1e3:.0f} ms ({len(ages)} reports)"
               if ages else "no detection reported")
    start_off = truth[0][1]
    if mode == 1:
        settled = 0.0
        for t, d in truth:
            if d > 0.1:
                settled = t - start
        last = max(d for t, d in truth if t >= end - 10.0)
        return (f"{name}: started {start_off:.2f} m off; within 0.1 m from {settled:.1f} s on "
                f"(of {end - start:.0f} s); largest offset in the last 10 s {last * 100:.1f} cm; "
                f"{age}")
    verdict = (f"landed after {end - start:.1f} s, {truth[-1][1] * 100:.1f} cm from the centre"
               if landed else f"NOT landed within {limit_s:.0f} s of sim time, "
               f"{truth[-1][1]:.2f} m from the centre")
    return f"{name}: from {start_off:.2f} m, {verdict}; {age}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--camera", choices=("webcam", "ideal"), default="webcam")
    ap.add_argument("--flights", nargs="+", choices=sorted(FLIGHTS), default=list(FLIGHTS))
    ap.add_argument("--trace", action="store_true",
                    help="print the true position every 5 s of each flight")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="skeye-pad-rt-") as tmp:
        calibration = None
        if args.camera != "ideal":
            calibration, _ = calibrate_simulated_camera(Path(tmp) / "calibration", args.camera)
        for name in args.flights:
            print(fly(name, args.camera, calibration, Path(tmp), args.trace), flush=True)


if __name__ == "__main__":
    main()
