"""MAVLink beside the AscTec link: command-to-effect latency, telemetry rates, and pad flights
through the MAVLink airframe against the same flights on the simulated airframe.

Run: ``python benchmarks/bench_mavlink.py [--trials 20] [--only link|pad]``.

``link``: a realtime simulator and one pilot serving both links (TCP packets and MAVLink on
``udpout``); the vehicle hovers at 1.5 m and gets a velocity command (0.5 m/s, alternately north
and south) ``--trials`` times over each link: the AscTec link's VELOCITY, MAVLink's offboard
SET_POSITION_TARGET_LOCAL_NED (velocity) in OFFBOARD mode. Command-to-effect latency is the
wall time from sending the command to the first telemetry (NAV_STATUS streamed every 10 ms;
LOCAL_POSITION_NED at 100 Hz) whose velocity is 0.1 m/s in the commanded direction: the
command's path, the pilot, the simulator and the vehicle's own acceleration, the same on both
links; and the time until the pilot's boards took the command (the link's own part). Each
trial starts from rest (below 3 cm/s) holding a zero velocity (a VELOCITY of zero; a
zero offboard setpoint), so both links start from the same state. Then the telemetry each link
delivers per second.

``pad``: pad hold (PAD_MODE HOLD started 0.6 m off the pad at 1.5 m; the first time within
10 cm, the largest offset 10-20 s later) and pad landing (PAD_MODE LAND from 0.5 m off at 2 m;
time to touchdown and distance from the centre) in real time, once on the simulated airframe
(``sim://``: the pilot on the robot) and once through ``mavlink://`` (a companion pilot flying
skeye's own MAVLink vehicle, as it would fly a PX4 flight controller), oracle estimator, ground
truth from the simulator. The ratio MAVLink / simulated is printed per figure.

The machine's load average is printed first: on a shared 2-core machine the figures move with it.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import socket
import statistics
import sys
import tempfile
import threading
import time
from contextlib import ExitStack
from importlib import resources
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("MUJOCO_GL", "egl")

from pymavlink import mavutil

from skeye.cliargs import positive_int
from skeye.control.connection import connect
from skeye.link.vehicle import Vehicle
from skeye.pilot.boards import BoardSettings
from skeye.pilot.cli import camera_fov_rad, camera_vision_factory, open_camera_for
from skeye.pilot.mavlink_airframe import open_mavlink_airframe
from skeye.pilot.mavlink_server import MavlinkServer
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.pilot.vision import PadVision
from skeye.sim.cameras import CameraSystem
from skeye.sim.engine import Simulation
from skeye.sim.image_server import FrameBuffer, ImageServer
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.world import load_world
from skeye.wire.packet_units import velocity_from_si
from skeye.wire.packets import PD, NavState, PadAction, SkeyeMask, encode

M = mavutil.mavlink
ROBOT = "benchcam"


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def robot_dir() -> Path:
    """A hummingbird with a 320x240 ideal camera at 10 frames/s (the tests' camera)."""
    folder = Path(tempfile.mkdtemp())
    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
    text = re.sub(r'(?m)^name = "hummingbird"', f'name = "{ROBOT}"', text, count=1)
    for old, new in (("width = 800", "width = 320"), ("height = 600", "height = 240"),
                     ("rate_hz = 30", "rate_hz = 10"), ('profile = "webcam"', 'profile = "ideal"')):
        text = re.sub(rf"(?m)^{re.escape(old)}$", new, text)
    (folder / f"{ROBOT}.toml").write_text(text, encoding="utf-8")
    return folder


def simulator(stack: ExitStack, images: bool) -> tuple[Any, Any]:
    """A realtime simulator (oracle estimator) and a spawned robot on a connection."""
    sim = Simulation(load_world("pad"), seed=1, robot_dirs=(robot_dir(),), estimator="truth")
    runner = stack.enter_context(SimulationRunner(sim, mode="realtime"))
    server = stack.enter_context(ControlServer(runner, port=0))
    address = None
    if images:
        cameras = CameraSystem(sim, FrameBuffer(), synchronous=False)
        stack.callback(cameras.close)
        image_server = stack.enter_context(ImageServer(cameras.buffer, port=0))
        address = f"127.0.0.1:{image_server.port}"
    conn = stack.enter_context(connect(f"127.0.0.1:{server.port}", images=address))
    return conn, conn.spawn(ROBOT, start="Pad1")


def settings_of(robot: Any) -> BoardSettings:
    mc = robot.motion_config
    return BoardSettings(max_speed_m_s=mc.max_speed_m_s, default_speed_m_s=1.0,
                         max_climb_m_s=mc.max_climb_m_s)


def heartbeat_loop(conn: Any, stop: threading.Event) -> None:
    while not stop.wait(0.5):
        conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)


def mav_wait(conn: Any, kind: str, pred: Any = lambda m: True, timeout_s: float = 60.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        msg = conn.recv_match(type=kind, blocking=True, timeout=0.5)
        if msg is not None and msg.get_srcSystem() == 1 and pred(msg):
            return msg
    raise TimeoutError(f"no {kind}")


def bench_link(trials: int) -> None:
    with ExitStack() as stack:
        conn_sim, robot = simulator(stack, images=False)
        airframe = SimAirframe(conn_sim, robot)
        pilot = stack.enter_context(PilotServer(airframe, port=0, settings=settings_of(robot)))
        port = free_udp_port()
        endpoint = stack.enter_context(MavlinkServer(pilot.boards, pilot.lock,
                                                     [f"udpout://127.0.0.1:{port}"]))
        mav = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255,
                                         source_component=190)
        def drain() -> None:
            # Telemetry that arrived while this script did something else: a full socket
            # buffer would drop the answer to the next command.
            while mav.recv_match(blocking=False) is not None:
                pass

        stop = threading.Event()
        threading.Thread(target=heartbeat_loop, args=(mav, stop), daemon=True).start()
        stack.callback(stop.set)
        vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=10.0))
        vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.01)
        mav_wait(mav, "HEARTBEAT")
        vehicle.take_off(1.5)
        vehicle.wait_state(NavState.HOLDING, timeout_s=60)

        def delivered(before: int, t0: float) -> float:
            """Seconds from ``t0`` until the pilot's boards took the command."""
            deadline = time.monotonic() + 10
            while pilot.boards.motion_changes == before:
                if time.monotonic() > deadline:
                    raise TimeoutError("the command never reached the boards")
                time.sleep(0.0002)
            return time.perf_counter() - t0

        def asctec_trial(sign: float) -> tuple[float, float]:
            packet = encode(velocity_from_si((0.5 * sign, 0.0, 0.0), 0.0, 0.6))  # facing north
            before = pilot.boards.motion_changes
            t0 = time.perf_counter()
            vehicle.send_raw(packet)
            reached = delivered(before, t0)
            while True:
                nav = vehicle.wait_for(PD.NAV_STATUS, timeout_s=10)
                if nav.vx * sign / 1e3 > 0.1:
                    return reached, time.perf_counter() - t0

        for msg_id in (M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,):
            mav.mav.command_long_send(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, 10_000,
                                      0, 0, 0, 0, 0)
            mav_wait(mav, "COMMAND_ACK")
        velocity_mask = 0b0000_0101_1100_0111

        def setpoint(vn: float) -> None:
            mav.mav.set_position_target_local_ned_send(0, 1, 1, M.MAV_FRAME_LOCAL_NED,
                                                       velocity_mask, 0, 0, 0, vn, 0, 0, 0, 0,
                                                       0, 0, 0)

        def mavlink_trial(sign: float) -> tuple[float, float]:
            drain()
            before = pilot.boards.motion_changes
            t0 = time.perf_counter()
            setpoint(0.5 * sign)
            reached = delivered(before, t0)
            while True:
                msg = mav_wait(mav, "LOCAL_POSITION_NED")
                if msg.vx * sign > 0.1:
                    return reached, time.perf_counter() - t0

        def settle() -> None:
            """Until the vehicle is still (below 3 cm/s), holding a zero velocity: each trial
            starts as a MAVLink one does, between offboard velocity setpoints of zero."""
            time.sleep(0.6)  # the move
            vehicle.set_velocity()  # zero, until replaced
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline:
                nav = vehicle.wait_for(PD.NAV_STATUS, timeout_s=10)
                if math.hypot(nav.vx, nav.vy) < 30:  # mm/s
                    return

        asctec: list[tuple[float, float]] = []
        for k in range(trials):
            asctec.append(asctec_trial(1.0 if k % 2 == 0 else -1.0))
            settle()
        drain()
        setpoint(0.0)
        main, sub = 6, 0
        mav.mav.command_long_send(1, 1, M.MAV_CMD_DO_SET_MODE, 0,
                                  M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub, 0, 0, 0, 0)
        mav_wait(mav, "COMMAND_ACK", lambda m: m.command == M.MAV_CMD_DO_SET_MODE)
        mavlink: list[tuple[float, float]] = []
        for k in range(trials):
            mavlink.append(mavlink_trial(1.0 if k % 2 == 0 else -1.0))
            end = time.monotonic() + 0.6
            while time.monotonic() < end:  # offboard setpoints keep coming, as a script sends
                setpoint(0.5 * (1.0 if k % 2 == 0 else -1.0))
                time.sleep(0.05)
            deadline = time.monotonic() + 20  # until still (below 3 cm/s), as settle()
            while time.monotonic() < deadline:
                setpoint(0.0)
                msg = mav_wait(mav, "LOCAL_POSITION_NED")
                if math.hypot(msg.vx, msg.vy) < 0.03:
                    break
        for name, values in (("AscTec VELOCITY -> NAV_STATUS", asctec),
                             ("MAVLink offboard velocity -> LOCAL_POSITION_NED", mavlink)):
            reach = [v[0] * 1e3 for v in values]
            ms = [v[1] * 1e3 for v in values]
            print(f"{name}: command to the boards p50 {statistics.median(reach):.2f} ms, "
                  f"p99 {percentile(reach, 0.99):.2f} ms; command to effect p50 "
                  f"{statistics.median(ms):.0f} ms, p99 {percentile(ms, 0.99):.0f} ms "
                  f"({len(ms)} trials)", flush=True)
        # Telemetry rates: MAVLink's default intervals, and the AscTec stream.
        drain()
        mav.mav.command_long_send(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                  M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 0, 0, 0, 0, 0, 0)
        mav_wait(mav, "COMMAND_ACK")
        counts: dict[str, int] = {}
        t0 = time.monotonic()
        while time.monotonic() - t0 < 5.0:
            msg = mav.recv_match(blocking=True, timeout=0.2)
            if msg is not None and msg.get_srcSystem() == 1:
                counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
        elapsed = time.monotonic() - t0
        print("MAVLink telemetry at the default intervals (messages/s): " + ", ".join(
            f"{k} {v / elapsed:.1f}" for k, v in sorted(counts.items())), flush=True)
        for period_s in (0.001, 0.02):
            vehicle.stream(0, int(SkeyeMask.NAV_STATUS), period_s)
            start = vehicle.parser.messages
            t0 = time.monotonic()
            time.sleep(3.0)
            rate = (vehicle.parser.messages - start) / (time.monotonic() - t0)
            print(f"AscTec NAV_STATUS stream every {period_s * 1e3:g} ms: {rate:.0f} frames/s",
                  flush=True)
        vehicle.stream(0, 0, 0.0)
        print(f"MAVLink endpoint: {endpoint.received} messages in, {endpoint.sent} out",
              flush=True)
        vehicle.land()


def pad_flight(kind: str, airframe_kind: str) -> tuple[float, float]:
    """One realtime pad flight; ``hold``: (first time within 10 cm, largest offset 10-20 s
    later), ``land``: (time to touchdown, distance from the pad's centre)."""
    with ExitStack() as stack:
        conn_sim, robot = simulator(stack, images=True)
        settings = settings_of(robot)
        airframe: Any = SimAirframe(conn_sim, robot)
        fov = camera_fov_rad(conn_sim)

        def robot_vision(boards: Any, lock: Any) -> Any:  # the robot's own camera, sim time
            return PadVision(boards, robot, lock, fov_h_rad=fov)

        vision: Any = robot_vision
        if airframe_kind == "mavlink":
            controller = stack.enter_context(PilotServer(airframe, port=0, settings=settings))
            port = free_udp_port()
            stack.enter_context(MavlinkServer(controller.boards, controller.lock,
                                              [f"udp://127.0.0.1:{port}"]))
            airframe = open_mavlink_airframe(f"mavlink://udpout/127.0.0.1:{port}")
            stack.callback(airframe.close)
            # The companion's camera as `skeye pilot --camera sim://...` opens it: frames on
            # the companion's clock, as a real camera's would be.
            host, image_port = conn_sim.images_address
            camera = open_camera_for(f"sim://{host}:{image_port}/{robot.name}/Down"
                                     f"?fov_rad={fov!r}", airframe, "companion", None, 5.0)
            stack.callback(camera.close)
            vision = camera_vision_factory(camera, camera.fov_h_rad)
        pilot = stack.enter_context(PilotServer(airframe, port=0, settings=settings,
                                                vision=vision))
        vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=10.0))
        vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.05)
        height, offset = (1.5, 0.6) if kind == "hold" else (2.0, 0.5)
        vehicle.take_off(height)
        vehicle.wait_state(NavState.HOLDING, timeout_s=60)
        vehicle.move_by(forward_m=offset)
        vehicle.wait_state(NavState.FLYING, timeout_s=30)
        vehicle.wait_state(NavState.HOLDING, timeout_s=60)

        def off_m() -> float:
            n, e, _ = robot.ground_truth.latest.position_ned_m
            return math.hypot(n, e)

        t0 = time.monotonic()
        if kind == "hold":
            vehicle.pad_mode(PadAction.HOLD, 0.05, 0.3)
            within = math.nan
            worst = 0.0
            while time.monotonic() - t0 < 20.0:
                vehicle.wait_for(PD.NAV_STATUS, timeout_s=10)
                err = off_m()
                now = time.monotonic() - t0
                if math.isnan(within) and err < 0.10:
                    within = now
                if now >= 10.0:
                    worst = max(worst, err)
            return within, worst
        vehicle.pad_mode(PadAction.LAND, 0.05, 0.3)
        vehicle.wait_state(NavState.LANDED, timeout_s=180)
        return time.monotonic() - t0, off_m()


def bench_pad() -> None:
    rows = []
    for kind, names in (("hold", ("within 10 cm after", "largest offset 10-20 s")),
                        ("land", ("landed after", "from the centre"))):
        results = {}
        for airframe in ("sim", "mavlink"):
            results[airframe] = pad_flight(kind, airframe)
            a, b = results[airframe]
            unit_b = f"{b * 100:.1f} cm"
            print(f"pad {kind} on the {airframe} airframe: {names[0]} {a:.1f} s, {names[1]} "
                  f"{unit_b}", flush=True)
        for i, name in enumerate(names):
            sim, mav = results["sim"][i], results["mavlink"][i]
            rows.append(f"pad {kind}, {name}: MAVLink / simulated = {mav / sim:.2f}")
    print("\n".join(rows), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=positive_int, default=20)
    ap.add_argument("--only", choices=("link", "pad"), default=None)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} on "
          f"{os.cpu_count()} cores", flush=True)
    if args.only != "pad":
        bench_link(args.trials)
    if args.only != "link":
        bench_pad()


if __name__ == "__main__":
    main()
