"""``skeye pilot``: the onboard computer's stand-in, serving the vehicle packet protocol.

It connects to a simulator (``--sim``), spawns a robot and serves one ground-control client over
TCP (``--port``, default 7000, bound to 127.0.0.1 unless ``--host``) or a serial line
(``--serial /dev/ttyUSB0 --baud 57600``). When the simulator runs in lockstep the pilot drives
its clock: ``--lockstep-rate`` sim seconds per wall second (1 = real time, 0 = as fast as the
CPU allows).

The flight envelope (``skeye.pilot.envelope``: ceiling above home, radius around home) comes
from the robot class's file (``[envelope]``; a class outside the built-ins is looked up in
``--robot-dir``), else the pilot's defaults (120 m, 500 m); ``--ceiling-m`` and
``--max-radius-m`` override either. The start-up line says which envelope is in force.

With ``--images`` the pilot runs the landing-pad detector on its camera; ``--video-port PORT``
(``skeye up`` gives 7001) also serves those camera frames, each with the pilot's own detection,
to ground control (docs/protocols/video.md; ``skeye ground --video tcp://HOST:PORT``), bound to
``--host`` like the packet port. An onboard ``skeye pilot`` with a real camera serves the same
port the same way.
"""

from __future__ import annotations

import argparse
import logging
import math
import signal
import threading
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path
from typing import Any

from skeye.errors import ConfigError, LinkClosed, LinkTimeout, LocalProtocolError, SkeyeError
from skeye.pilot.airframe import (
    AirframeOptions,
    airframe_scheme,
    open_airframe,
)
from skeye.pilot.boards import BoardSettings
from skeye.pilot.camera import camera_scheme
from skeye.pilot.envelope import FlightEnvelope
from skeye.pilot.server import DEFAULT_PORT, PilotServer
from skeye.pilot.video_server import (
    DEFAULT_MAX_CLIENTS,
    DEFAULT_MAX_FPS,
    DEFAULT_VIDEO_PORT,
    VideoServer,
)
from skeye.processes import EXIT_LOST_SIMULATOR
from skeye.wire.video import DEFAULT_JPEG_QUALITY

log = logging.getLogger(__name__)


def flight_envelope(args: argparse.Namespace) -> tuple[FlightEnvelope, str]:
    """The envelope in force and where it came from (robot file, defaults, options).

    Raises:
        ConfigError: a bad robot file or value, or a class missing from ``--robot-dir``.
    """
    from skeye.robots.config import BUILTIN_ROBOTS, load_robot_config

    dirs = (Path(args.robot_dir),) if args.robot_dir else ()
    short = args.robot.split(".", 1)[1] if args.robot.lower().startswith("usarbot.") else args.robot
    if dirs or short.lower() in BUILTIN_ROBOTS:
        config = load_robot_config(args.robot, dirs, allow_paths=False)
        envelope, source = config.envelope, f"robot file {config.source}"
    else:
        envelope = FlightEnvelope()
        source = "pilot defaults (the robot file is not here: give --robot-dir to use its own)"
    changes = {
        k: v for k, v in (("ceiling_m", args.ceiling_m), ("max_radius_m", args.max_radius_m))
        if v is not None
    }
    if changes:
        envelope = replace(envelope, **changes)  # validated again by __post_init__
        source += " with " + ", ".join(f"--{k.replace('_', '-')} {v:g}" for k, v in changes.items())
    return envelope, source


def airframe_options(args: argparse.Namespace) -> AirframeOptions:
    """The pilot's options as every airframe backend takes them."""
    location = None
    if args.location is not None:
        try:
            north, east, down = (float(v) for v in args.location.split(","))
        except ValueError:
            raise ConfigError(f"--location must be north,east,down in m, got "
                              f"{args.location!r}") from None
        location = (north, east, down)
    return AirframeOptions(
        robot=args.robot, name=args.name, start=args.start, location_ned_m=location,
        images=args.images, timeout_s=args.timeout, frozen_timeout_s=args.sim_frozen_timeout,
        robot_dirs=(args.robot_dir,) if args.robot_dir else (),
    )


def run(args: argparse.Namespace) -> int:
    """Run the pilot until SIGINT/SIGTERM; returns the exit code (0; 1 for an error; 2 for a
    bad option; :data:`EXIT_LOST_SIMULATOR` when the vehicle (simulator or LL board) could not
    be reached, or its link failed)."""
    from skeye.processes import check_ports_free

    airframe_uri = args.airframe or f"sim://{args.sim}"
    try:
        envelope, envelope_source = flight_envelope(args)
        airframe_scheme(airframe_uri)
        options = airframe_options(args)
    except (ConfigError, LocalProtocolError) as exc:
        print(f"skeye pilot: {exc}", flush=True)
        return 2
    if args.video_port is not None:
        problem = video_options_problem(args)
        if problem:
            print(f"skeye pilot: {problem}", flush=True)
            return 2
    camera_uri = args.camera if "://" in args.camera else None
    if camera_uri is not None:
        try:
            camera_scheme(camera_uri)
        except LocalProtocolError as exc:
            print(f"skeye pilot: --camera: {exc}", flush=True)
            return 2
    calibration = None
    if args.calibration is not None:
        from skeye.vision.calibration import load_calibration

        if args.images is None and camera_uri is None:
            print("skeye pilot: --calibration is for the pad vision: it needs --images or "
                  "--camera URI", flush=True)
            return 2
        try:
            calibration = load_calibration(args.calibration)
        except ConfigError as exc:
            print(f"skeye pilot: --calibration: {exc}", flush=True)
            return 2
    try:
        latency_s = vision_latency_s(args.vision_latency_ms)
    except ConfigError as exc:
        print(f"skeye pilot: {exc}", flush=True)
        return 2
    airframe: Any = None
    try:
        ports = [] if args.serial else [("the pilot", args.host, args.port, "--port")]
        if args.video_port is not None:
            ports.append(("the pilot's video", args.host, args.video_port, "--video-port"))
        if ports:  # before the robot is spawned: a taken port leaves nothing behind
            check_ports_free(ports)
        airframe = open_airframe(airframe_uri, options)
        with ExitStack() as stack:
            stack.callback(airframe.close)
            limits = airframe.limits
            settings = BoardSettings(
                link_timeout_s=args.link_timeout,
                land_timeout_s=args.land_timeout,
                max_speed_m_s=limits.max_speed_m_s,
                default_speed_m_s=min(1.0, limits.max_speed_m_s),
                max_climb_m_s=limits.max_climb_m_s,
                envelope=envelope,
            )
            vision = None
            camera_name, fov_h_rad = args.camera, None
            if camera_uri is not None:
                source = open_camera_for(camera_uri, airframe, args.name, calibration,
                                         args.timeout)
                stack.callback(source.close)
                fov_h_rad = source.fov_h_rad
                if calibration is None and fov_h_rad is None:
                    print(f"skeye pilot: --camera {camera_uri}: its field of view is not known: "
                          "add fov_deg= to the URI, or give --calibration camera.toml (skeye "
                          "calibrate)", flush=True)
                    return 2
                if source.lost:
                    print(f"skeye pilot: {source.lost}; the pad modes hold still until it "
                          "gives frames", flush=True)
                camera_name = camera_uri
                vision = camera_vision_factory(source, fov_h_rad, calibration,
                                               lockstep=airframe.lockstep, latency_s=latency_s,
                                               predict=not args.no_vision_prediction)
            elif args.images is not None:
                sim, robot = getattr(airframe, "connection", None), getattr(airframe, "robot", None)
                if sim is None or robot is None:
                    print(f"skeye pilot: --images reads the camera of a robot the pilot spawned "
                          f"(sim://); {airframe_uri} has none: give --camera URI", flush=True)
                    return 2
                fov_h_rad = camera_fov_rad(sim, args.camera)
                camera_name = f"{args.name}/{args.camera}"
                vision = pad_vision_factory(sim, robot, args.camera, calibration,
                                            latency_s=latency_s,
                                            predict=not args.no_vision_prediction)
            lockstep = airframe.lockstep
            tick_s = airframe.control_period_s if lockstep else args.tick
            video = None
            if args.video_port is not None:
                video = VideoServer(
                    host=args.host, port=args.video_port, camera=camera_name,
                    fov_h_rad=fov_h_rad if fov_h_rad is not None else (
                        calibration.fov_h_rad if calibration is not None else 0.0),
                    jpeg_quality=args.video_quality, max_fps=args.video_fps,
                    max_clients=args.video_clients,
                )
                stack.callback(video.close)
            server = PilotServer(
                airframe,
                host=args.host,
                port=None if args.serial else args.port,
                serial_uri=f"serial://{args.serial}?baud={args.baud}" if args.serial else None,
                settings=settings,
                tick_s=tick_s,
                lockstep=lockstep,
                lockstep_rate=args.lockstep_rate,
                ground_clock=args.ground_clock,
                vision=vision,
                video=video,
            )
            stop = threading.Event()
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, lambda *_: stop.set())
            with server:
                mode = f"lockstep x{args.lockstep_rate:g}" if lockstep else "realtime"
                print(
                    f"skeye pilot: {airframe.describe()} ({mode}); "
                    f"ground control on {server.address}; flight envelope: "
                    f"{envelope.describe()} ({envelope_source})"
                    f"{'; video on ' + video.address if video is not None else ''}",
                    flush=True,
                )
                while not stop.wait(0.2):
                    if server.loop_error is not None:
                        raise server.loop_error
                    if video is not None:
                        video.check()  # its thread died: WorkerFailed names the cause
            print("skeye pilot: stopping", flush=True)
    except SkeyeError as exc:
        print(f"skeye pilot: {exc}", flush=True)
        if airframe is None and isinstance(exc, (LinkClosed, LinkTimeout)):
            return EXIT_LOST_SIMULATOR  # the vehicle (or simulator) cannot be reached
        if getattr(airframe, "link_failed", None) is not None or isinstance(exc, LinkClosed):
            return EXIT_LOST_SIMULATOR
        return 1
    return 0


def open_camera_for(uri: str, airframe: Any, robot_name: str, calibration: Any,
                    timeout_s: float) -> Any:
    """Open ``--camera URI`` on the airframe's clock. A ``sim://`` camera of the robot a
    ``sim://`` airframe spawned gets its field of view from the simulator.

    Raises:
        LocalProtocolError / CameraError: a bad URI, or a camera that cannot be opened.
    """
    from skeye.pilot.camera import CameraOptions, open_camera

    fov = None
    sim, robot = getattr(airframe, "connection", None), getattr(airframe, "robot", None)
    if sim is not None and robot is not None and uri.lower().startswith("sim://"):
        from skeye.pilot.camera_sim import parse_sim_camera

        _, _, name, _ = parse_sim_camera(uri, robot.name)
        owner, _, camera = name.partition("/")
        if owner == robot.name:
            fov = camera_fov_rad(sim, camera)
    if airframe.clock_is_sim:
        def clock() -> float:
            return float(airframe.snapshot().time_s)
    else:
        import time

        clock = time.monotonic
    size = (calibration.width_px, calibration.height_px) if calibration is not None else None
    options = CameraOptions(clock=clock, clock_is_sim=airframe.clock_is_sim, robot=robot_name,
                            fov_h_rad=fov, size_px=size, timeout_s=timeout_s)
    return open_camera(uri, options)


def camera_vision_factory(source: Any, fov_h_rad: float | None, calibration: Any = None, *,
                          lockstep: bool = False, latency_s: float | None = 0.0,
                          predict: bool = True, params: Any = None) -> Any:
    """A factory for the pilot's PadVision on a camera source (``--camera URI``): the same
    detector, calibration and latency handling as on the simulator's camera."""
    from skeye.pilot.camera import CameraMount
    from skeye.pilot.vision import PadVision

    def make(boards: Any, lock: Any) -> PadVision:
        return PadVision(boards, CameraMount(source), lock,
                         fov_h_rad=fov_h_rad if fov_h_rad is not None else 0.0,
                         lockstep=lockstep, calibration=calibration, latency_s=latency_s,
                         predict=predict, params=params)

    return make


def vision_latency_s(text: str) -> float | None:
    """``--vision-latency-ms``: a number of milliseconds >= 0 (in seconds), or ``measured``
    (None: each frame's measured processing time).

    Raises:
        ConfigError: anything else.
    """
    if text.strip().lower() == "measured":
        return None
    try:
        ms = float(text)
    except ValueError:
        ms = math.nan
    if not (math.isfinite(ms) and 0 <= ms <= 10_000):
        raise ConfigError(f"--vision-latency-ms must be 0..10000 ms or 'measured', got {text!r}")
    return ms / 1e3


def pad_vision_factory(sim: Any, robot: Any, camera: str = "Down",
                       calibration: Any = None, *, latency_s: float | None = 0.0,
                       predict: bool = True, params: Any = None) -> Any:
    """A factory for the pilot's PadVision, with the camera's float FOV asked of the simulator
    and the camera calibration (``skeye calibrate``) when one is given; a calibration for
    another image size than the camera's is refused here, before the vision starts.
    ``latency_s`` and ``predict``: :class:`skeye.pilot.vision.PadVision`'s (vision latency,
    None = measured; fly on the offset predicted to now); ``params``: pad-hold gains and
    limits (default: derived from the loop delay)."""
    from skeye.pilot.vision import PadVision

    fov_h_rad = camera_fov_rad(sim, camera)
    lockstep = sim.mode == "lockstep"
    if calibration is not None:
        conf = sim.request("GETCONF", ("Type", "Camera"), ("Name", camera))
        width, height = conf.get_float("Width"), conf.get_float("Height")
        if (width, height) != (calibration.width_px, calibration.height_px):
            raise ConfigError(
                f"--calibration is for {calibration.width_px}x{calibration.height_px} images, "
                f"camera {camera} gives {width:g}x{height:g}: calibrate it at that resolution")

    def make(boards: Any, lock: Any) -> PadVision:
        return PadVision(boards, robot, lock, fov_h_rad=fov_h_rad, lockstep=lockstep,
                         calibration=calibration, latency_s=latency_s, predict=predict,
                         params=params)

    return make


def video_options_problem(args: argparse.Namespace) -> str:
    """What is wrong with the ``--video-*`` options ('' when nothing), checked before the
    simulator is reached."""
    if args.images is None and "://" not in args.camera:
        return ("--video-port serves the camera: it needs --images (the image server) or "
                "--camera URI")
    if not 1 <= args.video_quality <= 100:
        return f"--video-quality must be 1..100, got {args.video_quality}"
    if not 0.01 <= args.video_fps <= 1000:
        return f"--video-fps must be in [0.01, 1000] frames/s, got {args.video_fps:g}"
    if args.video_clients < 1:
        return f"--video-clients must be at least 1, got {args.video_clients}"
    if not 0 <= args.video_port <= 65535:
        return f"--video-port must be a TCP port 0..65535, got {args.video_port}"
    return ""


def camera_fov_rad(sim: Any, camera: str = "Down") -> float:
    """The camera's horizontal field of view (float, rad), asked of the simulator."""
    conf = sim.request("GETCONF", ("Type", "Camera"), ("Name", camera))
    return float(conf.get_float("FOV"))


def register(subparsers: Any) -> None:
    """Add ``skeye pilot`` to the main parser's subcommands."""
    p = subparsers.add_parser(
        "pilot",
        help="emulate the vehicle's onboard boards on a simulated robot",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--sim", default="127.0.0.1:3000", help="simulator control address (the "
                   "airframe sim://ADDRESS when --airframe is not given)")
    p.add_argument(
        "--airframe",
        default=None,
        metavar="URI",
        help="the vehicle to fly: sim://HOST:PORT (a robot of the simulator; default "
        "sim://<--sim>), asctec-ll://serial/dev/ttyS1?baud=57600 or asctec-ll://tcp/HOST:PORT "
        "(an AscTec low-level board, real or `skeye sim --ll-board`); docs/onboard.md",
    )
    p.add_argument(
        "--images",
        default=None,
        help="image server address (e.g. 127.0.0.1:5003): enables landing-pad vision",
    )
    p.add_argument(
        "--camera",
        default="Down",
        metavar="NAME|URI",
        help="the downward camera: a camera name of the spawned robot (with --images), or a "
        "URI: sim://HOST:PORT/ROBOT/CAMERA (the simulator's image server), "
        "v4l2:///dev/video0?width=800&height=600&fps=30 (a real camera), file://video.mp4 "
        "(a recorded video, at its frame rate); docs/onboard.md",
    )
    p.add_argument(
        "--calibration",
        default=None,
        metavar="CAMERA_TOML",
        help="the downward camera's calibration from `skeye calibrate` (camera matrix and lens "
        "distortion for the pad detector; default: the ideal pinhole of the camera's FOV)",
    )
    p.add_argument(
        "--vision-latency-ms",
        default="0",
        metavar="MS|measured",
        help="when a pad detection is used, in sim time after its frame's capture: 0 (default) "
        "= as soon as the detector is done; N = N ms after the capture (in lockstep the "
        "detector is busy until then, as a slower computer's would be); 'measured' = each "
        "frame's measured processing time (lockstep; in realtime the real delay applies). "
        "See docs/pilot.md, Vision latency",
    )
    p.add_argument(
        "--no-vision-prediction",
        action="store_true",
        help="fly pad hold on each detection as it arrives instead of on the pad offset "
        "predicted to now from its capture pose (for comparison; docs/pilot.md)",
    )
    p.add_argument(
        "--video-port",
        type=int,
        default=None,
        help=f"serve the camera frames with the pilot's pad detection on this TCP port "
        f"(skeye up: {DEFAULT_VIDEO_PORT}; 0 = any free; needs --images)",
    )
    p.add_argument(
        "--video-fps",
        type=float,
        default=DEFAULT_MAX_FPS,
        help=f"most frames per second sent to a video client (default {DEFAULT_MAX_FPS:g})",
    )
    p.add_argument(
        "--video-quality",
        type=int,
        default=DEFAULT_JPEG_QUALITY,
        help=f"JPEG quality of the video, 1..100 (default {DEFAULT_JPEG_QUALITY})",
    )
    p.add_argument(
        "--video-clients",
        type=int,
        default=DEFAULT_MAX_CLIENTS,
        help=f"video clients served at once (default {DEFAULT_MAX_CLIENTS})",
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument("--port", type=int, default=DEFAULT_PORT, help="TCP port (0 = any free)")
    where.add_argument("--serial", default=None, help="serve on this serial device instead")
    p.add_argument("--baud", type=int, default=57600, help="serial baud rate")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--robot", default="hummingbird", help="robot class to spawn")
    p.add_argument(
        "--robot-dir",
        default=None,
        help="folder of robot files (as skeye sim's): the class's [envelope] is read there",
    )
    p.add_argument(
        "--ceiling-m",
        type=float,
        default=None,
        help="flight envelope: highest height above home in m (default: robot file, or 120)",
    )
    p.add_argument(
        "--max-radius-m",
        type=float,
        default=None,
        help="flight envelope: farthest horizontal distance from home in m (default: robot "
        "file, or 500)",
    )
    p.add_argument("--name", default="R1", help="robot name")
    p.add_argument("--start", default="Pad1", help="start pose")
    p.add_argument("--location", default=None, help="spawn at north,east,down (m) instead")
    p.add_argument("--link-timeout", type=float, default=2.0, help="s without packets -> hold")
    p.add_argument("--land-timeout", type=float, default=20.0, help="s more -> land")
    p.add_argument(
        "--lockstep-rate",
        type=float,
        default=1.0,
        help="lockstep sim: sim seconds per wall second (0 = unpaced)",
    )
    p.add_argument(
        "--ground-clock",
        action="store_true",
        help="lockstep sim: advance only up to the sim time the ground grants (CLOCK packets)",
    )
    p.add_argument("--tick", type=float, default=0.01, help="loop period in realtime (s)")
    p.add_argument("--timeout", type=float, default=10.0, help="simulator answer deadline (s)")
    p.add_argument(
        "--sim-frozen-timeout",
        type=float,
        default=5.0,
        metavar="S",
        help="realtime: sim time standing still for S wall seconds means the simulator froze "
        "(failsafe, as if it were gone); default 5",
    )
    p.set_defaults(func=run)
