"""``skeye pilot``: the onboard computer's stand-in, serving the vehicle packet protocol.

It connects to a simulator (``--sim``), spawns a robot and serves one ground-control client over
TCP (``--port``, default 7000, bound to 127.0.0.1 unless ``--host``) or a serial line
(``--serial /dev/ttyUSB0 --baud 57600``). When the simulator goes away the pilot keeps serving
(the vehicle is lost: failsafe), tries every second to connect again at the same address, and
when the simulator is back spawns its robot there again and says so. When the simulator runs
in lockstep the pilot drives its clock: ``--lockstep-rate`` sim seconds per wall second (1 =
real time, 0 = as fast as the CPU allows).

The flight envelope (``skeye.pilot.envelope``: ceiling above home, radius around home) comes
from the robot class's file (``[envelope]``; a class outside the built-ins is looked up in
``--robot-dir``), else the pilot's defaults (120 m, 500 m); ``--ceiling-m`` and
``--max-radius-m`` override either. The start-up line says which envelope is in force.

With ``--images`` the pilot runs the landing-pad detector on its camera; ``--video-port PORT``
(``skeye up`` gives 7001) also serves those camera frames, each with the pilot's own detection,
to ground control (docs/protocols/video.md; ``skeye ground --video tcp://HOST:PORT``), bound to
``--host`` like the packet port. An onboard ``skeye pilot`` with a real camera serves the same
port the same way.

With ``--policy module:callable`` (and ``--images``) a policy, e.g. one learned in skeye's
Gymnasium environments, flies the vehicle in place of the pad-hold law while PAD_MODE is HOLD or
LAND, on the same observation the environments give it (:mod:`skeye.pilot.policy`,
docs/gym.md).
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import re
import socket
import sys
import threading
from collections.abc import Callable
from contextlib import ExitStack, nullcontext
from dataclasses import replace
from typing import Any

from skeye import cliargs
from skeye.errors import (
    CommandRejected,
    ConfigError,
    LinkClosed,
    LinkTimeout,
    LocalProtocolError,
    SkeyeError,
)
from skeye.pilot.airframe import (
    AirframeOptions,
    airframe_scheme,
    open_airframe,
)
from skeye.pilot.boards import BoardSettings
from skeye.pilot.camera import CameraError, check_camera_uri, needs_fov_option
from skeye.pilot.envelope import FlightEnvelope
from skeye.pilot.server import DEFAULT_PORT, PilotServer
from skeye.pilot.video_server import (
    DEFAULT_MAX_CLIENTS,
    DEFAULT_MAX_FPS,
    DEFAULT_VIDEO_PORT,
    VideoServer,
)
from skeye.processes import EXIT_LOST_SIMULATOR, on_stop_signals, sleep_until
from skeye.wire.video import DEFAULT_JPEG_QUALITY

log = logging.getLogger(__name__)


def flight_envelope(args: argparse.Namespace) -> tuple[FlightEnvelope, str]:
    """The envelope in force and where it came from (robot file, defaults, options).

    Raises:
        ConfigError: a bad robot file or value, or a class missing from ``--robot-dir``.
    """
    from skeye.robots.config import BUILTIN_ROBOTS, load_robot_config, robot_folders

    dirs = robot_folders((args.robot_dir,)) if args.robot_dir else ()
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


def sim_airframe_uri(sim: str) -> str:
    """``--sim`` (``host:port``, ``tcp://host:port`` or ``host``, as the simulator connection
    takes it) as the ``sim://`` airframe URI; ConfigError names ``--sim`` (not ``--airframe``,
    which was not given)."""
    from skeye.control.connection import parse_address

    try:
        host, port = parse_address(sim)
    except LocalProtocolError as exc:
        raise ConfigError(f"--sim: {exc}") from None
    return f"sim://[{host}]:{port}" if ":" in host else f"sim://{host}:{port}"


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
    if args.images is not None:  # named here, not later as the simulator's address
        from skeye.control.connection import DEFAULT_IMAGE_PORT, parse_address

        try:
            parse_address(args.images, DEFAULT_IMAGE_PORT, "image server address")
        except LocalProtocolError as exc:
            raise ConfigError(f"--images: {exc}") from None
    return AirframeOptions(
        robot=args.robot, name=args.name, start=args.start, location_ned_m=location,
        images=args.images, timeout_s=args.timeout, frozen_timeout_s=args.sim_frozen_timeout,
        robot_dirs=(args.robot_dir,) if args.robot_dir else (),
        sync_clock=args.lockstep_sync,
    )


LOCKSTEP_RATE_DEFAULT = 1.0
"""``--lockstep-rate``: sim seconds per wall second in lockstep."""


def run(args: argparse.Namespace) -> int:
    """Run the pilot until SIGINT/SIGTERM; returns the exit code (0; 1 for an error; 2 for a
    bad option; :data:`EXIT_LOST_SIMULATOR` when the vehicle (simulator, LL board or flight
    controller) could not be reached, or its link failed)."""
    from skeye.processes import check_ports_free

    try:
        airframe_uri = args.airframe or sim_airframe_uri(args.sim)
        envelope, envelope_source = flight_envelope(args)
        airframe_scheme(airframe_uri)
        options = airframe_options(args)
    except (ConfigError, LocalProtocolError) as exc:
        return _error(str(exc))
    if args.video_port is not None:
        problem = video_options_problem(args)
        if problem:
            return _error(problem)
    camera_uri = args.camera if "://" in args.camera else None
    if camera_uri is not None:
        try:
            check_camera_uri(camera_uri)  # the whole URI, before the airframe opens
        except (LocalProtocolError, CameraError) as exc:  # CameraError: a file no video
            return _error(f"--camera: {exc}")
        problem = other_robots_camera_problem(airframe_uri, camera_uri, args.name)
        if problem:
            return _error(problem)
    elif args.images is None and args.camera != DEFAULT_CAMERA:
        return _error(camera_name_problem(args.camera))
    elif args.images is not None and airframe_scheme(airframe_uri) in REAL_VEHICLES:
        # said before the vehicle (a real board, a flight controller) is opened
        return _error(images_problem(airframe_uri))
    if args.lockstep_sync and airframe_scheme(airframe_uri) in REAL_VEHICLES:
        return _error(f"--lockstep-sync keeps a lockstep simulator's clock with the other "
                      f"pilots of its robots (sim://); {airframe_uri} steps no simulator")
    has_camera = args.images is not None or camera_uri is not None
    calibration = None
    if args.calibration is not None:
        from skeye.vision.calibration import load_calibration

        if not has_camera:
            return _error("--calibration is for the pad vision: it needs --images or "
                          "--camera URI")
        try:
            calibration = load_calibration(args.calibration)
        except ConfigError as exc:
            return _error(f"--calibration: {exc}")
    elif camera_uri is not None and needs_fov_option(camera_uri):  # before the vehicle opens
        return _error(fov_unknown_problem(camera_uri))
    try:
        latency_s = vision_latency_s(args.vision_latency_ms)
        check_policy_options(args)
    except ConfigError as exc:
        return _error(str(exc))
    if not (math.isfinite(args.frame_jitter_ms) and 0.0 <= args.frame_jitter_ms <= 1000.0):
        return _error(f"--frame-jitter-ms must be 0..1000 ms, got {args.frame_jitter_ms}")
    problem = unused_option_problem(args)  # a bad value is named as such first
    if problem:
        return _error(problem)
    if args.rtp_video is not None:
        from skeye.pilot.rtp_video import MAX_RTP_FPS, MIN_RTP_FPS, check_rtp_destination

        if not MIN_RTP_FPS <= args.rtp_fps <= MAX_RTP_FPS:  # before the robot is spawned
            return _error(f"--rtp-fps must be {MIN_RTP_FPS:g}..{MAX_RTP_FPS:g} frames/s, got "
                          f"{args.rtp_fps:g}")
        try:
            check_rtp_destination(args.rtp_video)  # resolves, and a route exists
            import av  # noqa: F401  (the `mavlink` extra)
        except ImportError:
            return _error("--rtp-video needs PyAV: pip install 'skeye[mavlink]'")
        except ConfigError as exc:
            return _error(f"--rtp-video: {exc}")
        if not has_camera:
            return _error("--rtp-video sends the camera: it needs --images or --camera URI")
    if args.mavlink:  # needs pymavlink (the `mavlink` extra): say so before the robot is spawned
        import skeye.pilot.mavlink_server  # noqa: F401
    if not 1 <= args.mavlink_sysid <= 255:
        return _error(f"--mavlink-sysid must be a MAVLink system id 1..255, got "
                      f"{args.mavlink_sysid}")
    try:
        clash = shared_port_problem(args)
    except ConfigError as exc:
        return _error(f"--mavlink: {exc}")
    if clash:
        return _error(clash)
    try:
        for uri in args.mavlink or ():
            from skeye.mavlink.transport import check_free

            check_free(uri)  # a bad URI or a taken port stops us before the robot is spawned
    except ConfigError as exc:
        return _error(f"--mavlink: {exc}")
    airframe: Any = None
    try:
        ports = [] if args.serial else [("the pilot", args.host, args.port, "--port")]
        if args.video_port is not None:
            ports.append(("the pilot's video", args.host, args.video_port, "--video-port"))
        if ports:  # before the vehicle is opened: a taken port leaves nothing behind
            check_ports_free(ports)
        problem = serial_problem(args.serial)
        if problem:
            return _error(problem)
        try:
            airframe = open_airframe(airframe_uri, options)
        except (ConfigError, LocalProtocolError) as exc:  # a URI its backend refused
            # the vehicle's URI, not the option: it may come from --sim, and the backend's
            # message names the option at fault (--start, --name); once, where the backend's
            # message names the URI already (each URI parser's "airframe 'URI': ...")
            said = str(exc)
            return _error(said if airframe_uri in said else f"{airframe_uri}: {said}")
        with ExitStack() as stack:
            stack.callback(airframe.close)
            limits = airframe.limits
            settings = BoardSettings(
                link_timeout_s=args.link_timeout,
                land_timeout_s=args.land_timeout,
                max_speed_m_s=limits.max_speed_m_s,
                default_speed_m_s=min(1.0, limits.max_speed_m_s),
                max_climb_m_s=limits.max_climb_m_s,
                max_yaw_rate_rad_s=limits.max_yaw_rate_rad_s,
                envelope=envelope,
            )
            vision = None
            camera_name, fov_h_rad = args.camera, None
            if camera_uri is not None:
                try:
                    source = open_camera_for(camera_uri, airframe, args.name, calibration,
                                             args.timeout)
                except CameraError as exc:  # a file that is no video, or the wrong size
                    return _error(f"--camera: {exc}")
                stack.callback(source.close)
                fov_h_rad = source.fov_h_rad
                if calibration is None and fov_h_rad is None:
                    return _error(fov_unknown_problem(camera_uri))
                if source.lost:  # the pilot runs on: a warning, as skeye calibrate's
                    _warn(f"{source.lost}; the pad modes hold still until it gives frames")
                camera_name = camera_uri
                vision = camera_vision_factory(source, fov_h_rad, calibration,
                                               lockstep=airframe.lockstep, latency_s=latency_s,
                                               predict=not args.no_vision_prediction)
            elif args.images is not None:
                sim, robot = getattr(airframe, "connection", None), getattr(airframe, "robot", None)
                if sim is None or robot is None:
                    return _error(images_problem(airframe_uri))
                try:
                    fov_h_rad = camera_fov_rad(sim, args.camera)
                except CommandRejected as exc:  # no such camera on the robot
                    return _error(f"--camera {args.camera}: {exc}")
                camera_name = f"{args.name}/{args.camera}"
                if args.policy is not None:
                    vision = policy_vision_factory(sim, robot, args, calibration, latency_s)
                else:
                    vision = pad_vision_factory(sim, robot, args.camera, calibration,
                                                latency_s=latency_s,
                                                predict=not args.no_vision_prediction,
                                                frame_time=args.frame_time,
                                                frame_jitter_s=args.frame_jitter_ms / 1e3,
                                                pad_source=args.pad_source)
            lockstep = airframe.lockstep
            tick_s = airframe.control_period_s if lockstep else args.tick
            if not lockstep:
                idle = lockstep_options_given(args)
                if idle:
                    _warn(f"{' and '.join(idle)}: the vehicle runs in real time "
                          f"({airframe.describe()}), with no lockstep clock to pace, keep "
                          f"together or grant: {'they do' if len(idle) > 1 else 'it does'} "
                          "nothing")
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
            forward = getattr(airframe, "landing_target", None)
            if forward is not None:  # a flight controller takes the detections (LANDING_TARGET)
                server.boards.pad.add_listener(forward)
            stop = threading.Event()
            on_stop_signals(lambda *_: stop.set())
            mavlink = open_mavlink(server, args, pad_vision=vision is not None)
            rtp = open_rtp_video(server, video, args)
            airframe_check = getattr(airframe, "check", None)
            try:
                stack.enter_context(server)  # closed before the video and the airframe
            except LinkClosed as exc:
                if args.serial is None:
                    raise
                # busy, a directory, not a terminal: a bad option, not a lost simulator
                return _error(f"--serial: {exc}")
            with mavlink or nullcontext(), rtp or nullcontext():
                print(
                    f"skeye pilot: {describe_airframe(airframe.describe(), lockstep, args)}; "
                    f"ground control on {server.address}; flight envelope: "
                    f"{envelope.describe()} ({envelope_source})"
                    f"{'; video on ' + video.address if video is not None else ''}"
                    f"{'; MAVLink on ' + ', '.join(mavlink.addresses) if mavlink else ''}"
                    f"{'; H.264 RTP video to ' + rtp.address if rtp else ''}",
                    flush=True,
                )
                while not sleep_until(stop, 0.2):  # not stop.wait: see sleep_until
                    if server.loop_error is not None:
                        raise server.loop_error
                    if airframe_check is not None:
                        airframe_check()  # its link thread died: WorkerFailed names the cause
                    if mavlink is not None:
                        mavlink.check()
                    if rtp is not None:
                        rtp.check()
                    if video is not None:
                        video.check()
            print("skeye pilot: stopping", flush=True)
        unsaid = getattr(airframe, "close_problem", None)  # each wait at stop is bounded
        if unsaid:
            _warn(f"stopped without the simulator: {unsaid}")
    except SkeyeError as exc:
        _error(str(exc))
        if airframe is None and isinstance(exc, (LinkClosed, LinkTimeout)):
            return EXIT_LOST_SIMULATOR  # the vehicle (or simulator) cannot be reached
        if getattr(airframe, "link_failed", None) is not None or isinstance(exc, LinkClosed):
            return EXIT_LOST_SIMULATOR
        return 1
    return 0


_ANY_HOST = ("", "0.0.0.0", "::")


def bound_address(host: str) -> str:
    """The address a listener on ``host`` binds: the IPv4 address the name resolves to, as
    each link's bind resolves it (``localhost`` is ``127.0.0.1``; ``0`` is ``0.0.0.0``, any
    address, as ``""`` and ``::`` are), or ``host`` as written where it does not resolve (its
    link's bind says so)."""
    if host in _ANY_HOST:
        return "0.0.0.0"
    try:
        return socket.gethostbyname(host)
    except (OSError, UnicodeError):
        return host


def shared_port_problem(args: argparse.Namespace) -> str | None:
    """One port given to two of the pilot's listening links (``--port``, ``--video-port``, a
    ``--mavlink`` ``tcp://`` or ``udp://``), on one protocol and overlapping addresses (the
    addresses the hosts resolve to: ``localhost`` and ``127.0.0.1`` are one; any address
    overlaps every one): said before anything is opened, as each link's own check passes while
    the other is unbound.

    Raises:
        ConfigError: a ``--mavlink`` URI that is not one.
    """
    from skeye.mavlink.transport import listening_links

    links: list[tuple[str, str, int, str]] = []
    if not args.serial:
        links.append(("tcp", args.host, args.port, "the pilot (--port)"))
    if args.video_port is not None:
        links.append(("tcp", args.host, args.video_port, "the pilot's video (--video-port)"))
    for scheme, host, port, uri in listening_links(args.mavlink or ()):
        links.append((scheme, host, port, f"the MAVLink link {uri} (--mavlink)"))
    bound = {host: bound_address(host) for _, host, _, _ in links}
    for i, (scheme, host, port, what) in enumerate(links):
        for other_scheme, other_host, other_port, other in links[:i]:
            address, other_address = bound[host], bound[other_host]
            if (port and port == other_port and scheme == other_scheme
                    and (address == other_address or "0.0.0.0" in (address, other_address))):
                return (f"{scheme.upper()} port {port} is given to both {other} and {what}; "
                        "give each its own port")
    return None


def fov_unknown_problem(camera_uri: str) -> str:
    """The refusal of a ``--camera`` URI whose field of view nothing gives."""
    return (f"--camera {camera_uri}: its field of view is not known: add fov_deg= to the URI, "
            "or give --calibration camera.toml (skeye calibrate)")


def _error(message: str) -> int:
    """Say ``message`` on stderr as the pilot's error, the way every sub-command does
    (``skeye pilot: error: ...``); returns 2, a bad option's exit code."""
    print(f"skeye pilot: error: {message}", file=sys.stderr, flush=True)
    return 2


def _warn(message: str) -> None:
    """Say ``message`` on stderr as a warning: the pilot runs on (``skeye pilot: warning:``,
    as ``skeye calibrate`` warns)."""
    print(f"skeye pilot: warning: {message}", file=sys.stderr, flush=True)


def serial_problem(device: str | None) -> str:
    """What is wrong with ``--serial DEVICE`` ('' when nothing or no ``--serial``): a device
    that is not there or cannot be opened for reading and writing is a bad option, found
    before the vehicle is opened."""
    if device is None:
        return ""
    if not os.path.exists(device):
        return f"--serial {device}: no such device"
    if not os.access(device, os.R_OK | os.W_OK):
        return f"--serial {device}: no permission to read and write it"
    return ""


def lockstep_options_given(args: argparse.Namespace) -> list[str]:
    """The lockstep simulator's options given (``--lockstep-rate`` other than its default,
    ``--lockstep-sync``, ``--ground-clock``): said when the vehicle turns out to run in real
    time, where they do nothing (a real vehicle's ``--lockstep-sync`` is refused before)."""
    given = [("--lockstep-rate", args.lockstep_rate != LOCKSTEP_RATE_DEFAULT),
             ("--lockstep-sync", args.lockstep_sync), ("--ground-clock", args.ground_clock)]
    return [option for option, on in given if on]


def describe_airframe(described: str, lockstep: bool, args: argparse.Namespace) -> str:
    """The start-up line's airframe: its own description with the clock mode said once (a
    simulated robot says ``(realtime)`` or ``(lockstep)`` itself; the pace is added to it)."""
    if lockstep:
        pace = f"lockstep x{args.lockstep_rate:g}"
        if "(lockstep)" in described:
            return described.replace("(lockstep)", f"({pace})")
        return f"{described} ({pace})" if "lockstep" not in described else described
    return described if "realtime" in described else f"{described} (realtime)"


def open_mavlink(server: PilotServer, args: argparse.Namespace, pad_vision: bool = False) -> Any:
    """The MAVLink endpoint on ``--mavlink`` links (None without): a second client of the
    pilot's boards, beside the AscTec link (docs/protocols/mavlink.md)."""
    if not args.mavlink:
        return None
    from skeye.pilot.mavlink_server import MavlinkServer
    from skeye.pilot.mavlink_vehicle import Settings

    return MavlinkServer(server.boards, server.lock, list(args.mavlink),
                         settings=Settings(pad_vision=pad_vision),
                         system_id=args.mavlink_sysid)


def open_rtp_video(server: PilotServer, video: Any, args: argparse.Namespace) -> Any:
    """``--rtp-video udp://HOST:PORT``: the vision's frames with their detections as H.264
    over RTP (QGroundControl's UDP 5600), beside the video port (None without)."""
    if not args.rtp_video:
        return None
    from skeye.pilot.rtp_video import RtpVideo

    rtp = RtpVideo(args.rtp_video, max_fps=args.rtp_fps)
    sinks = [rtp.publish] + ([video.publish] if video is not None else [])

    def publish(frame: Any) -> None:  # neither sink waits (both swap a newest-frame slot)
        for sink in sinks:
            sink(frame)

    if server.vision is None:
        raise ConfigError("--rtp-video sends the camera: it needs --images or --camera URI")
    server.vision.attach_video(publish)
    return rtp


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
                       predict: bool = True, params: Any = None,
                       vision_class: Any = None, frame_time: str = "arrival",
                       frame_jitter_s: float = 0.0, pad_source: str = "vision") -> Any:
    """A factory for the pilot's PadVision, with the camera's float FOV asked of the simulator
    and the camera calibration (``skeye calibrate``) when one is given; a calibration for
    another image size than the camera's is refused here, before the vision starts.
    ``latency_s`` and ``predict``: :class:`skeye.pilot.vision.PadVision`'s (vision latency,
    None = measured; fly on the offset predicted to now); ``params``: pad-hold gains and
    limits (default: derived from the loop delay); ``vision_class``: a PadVision subclass
    (``--policy``: :class:`skeye.pilot.policy.DetectOnlyVision`); ``frame_time`` and
    ``frame_jitter_s``: what a frame's time is (its arrival at the pilot, or its capture),
    and the host's jitter."""
    from skeye.pilot.vision import PadVision

    cls = vision_class or PadVision

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
        return cls(boards, robot, lock, fov_h_rad=fov_h_rad, lockstep=lockstep,
                   calibration=calibration, latency_s=latency_s, predict=predict,
                   params=params, frame_time=frame_time, frame_jitter_s=frame_jitter_s,
                   pad_source=pad_source)

    return make


# option, what it tunes, the option(s) that turn that on, and whether they are given
_TUNES: tuple[tuple[str, str, str, Callable[[argparse.Namespace], bool]], ...] = (
    ("--baud", "the --serial line", "--serial", lambda a: a.serial is not None),
    *((option, "the video port", "--video-port", lambda a: a.video_port is not None)
      for option in ("--video-fps", "--video-quality", "--video-clients")),
    ("--rtp-fps", "the RTP video", "--rtp-video", lambda a: a.rtp_video is not None),
    *((option, "the policy", "--policy", lambda a: a.policy is not None)
      for option in ("--policy-observation", "--policy-rate", "--policy-image-size")),
    *((option, "the simulator's camera frames", "--images", lambda a: a.images is not None)
      for option in ("--frame-time", "--pad-source", "--frame-jitter-ms")),
    *((option, "the pad vision", "--images or --camera URI",
       lambda a: a.images is not None or "://" in a.camera)
      for option in ("--vision-latency-ms", "--no-vision-prediction")),
)


DEFAULT_CAMERA = "Down"  # --camera: the spawned robot's downward camera


REAL_VEHICLES = ("asctec-ll", "mavlink")
"""Airframe schemes of a real vehicle: no robot spawned, so no camera for ``--images``."""


def images_problem(airframe_uri: str) -> str:
    """Why ``--images`` is refused on an airframe without a spawned robot."""
    return (f"--images reads the camera of a robot the pilot spawned (sim://); {airframe_uri} "
            "has none: give --camera URI")


def other_robots_camera_problem(airframe_uri: str, camera_uri: str, name: str) -> str:
    """Why a ``sim://`` camera of another robot is refused on a ``sim://`` airframe ('' when
    it is not one): the pilot spawns and flies robot ``name`` (``--name``), and a vehicle's
    camera is on the vehicle, so another robot's camera would fly it on what that robot sees.
    On ``asctec-ll://`` the pilot spawns no robot: the camera names the robot the board flies
    (``skeye sim --ll-board``), which the pilot cannot check."""
    if airframe_scheme(airframe_uri) != "sim" or not camera_uri.lower().startswith("sim://"):
        return ""
    from skeye.pilot.camera_sim import parse_sim_camera

    _, _, camera_name, _ = parse_sim_camera(camera_uri, name)
    owner = camera_name.partition("/")[0]
    if owner == name:
        return ""
    return (f"--camera {camera_uri} is robot {owner}'s camera; this pilot flies {name} "
            f"(--name): a vehicle's camera is on the vehicle: give sim://HOST:PORT/{name}/CAMERA, "
            "or sim://HOST:PORT/CAMERA")


def camera_name_problem(camera: str) -> str:
    """Why ``--camera NAME`` (no URI) without ``--images`` is refused: a name is a camera of
    the robot the pilot spawns, and only ``--images`` reads it; without it the pilot flew with
    no camera and said nothing. The message names the URIs likely meant (a device path is the
    ``v4l2://`` one with its scheme forgotten)."""
    device = f"v4l2://{camera}" if camera.startswith("/dev/") else "v4l2:///dev/video0"
    return (f"--camera {camera}: a name is a camera of the robot the pilot spawns, read with "
            f"--images; a camera of this computer or a video is a URI: {device}, "
            "file://video.mp4, or sim://HOST:PORT/ROBOT/CAMERA (docs/onboard.md)")


def unused_option_problem(args: argparse.Namespace) -> str:
    """What is wrong ('' when nothing) with an option given a value other than its default
    where it would do nothing: one that tunes something not turned on (``--baud`` without
    ``--serial``, ``--video-quality`` without ``--video-port``, ...)."""
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    defaults = parser.parse_args(["pilot"])
    for option, what, needs, given in _TUNES:
        dest = option.removeprefix("--").replace("-", "_")  # argparse's own dest
        if getattr(args, dest) != getattr(defaults, dest) and not given(args):
            return f"{option} applies to {what}: it needs {needs}"
    return ""


def check_policy_options(args: argparse.Namespace) -> None:
    """The ``--policy*`` options, checked before the simulator is reached (ConfigError)."""
    if args.policy is None:
        return
    from skeye.pilot.policy import OBSERVATIONS, load_policy

    if args.images is None:
        raise ConfigError("--policy flies on the pad vision: it needs --images")
    if args.policy_observation not in OBSERVATIONS:
        raise ConfigError(f"--policy-observation must be one of {list(OBSERVATIONS)}")
    if not (math.isfinite(args.policy_rate) and 0.5 <= args.policy_rate <= 1000):
        raise ConfigError(f"--policy-rate must be 0.5..1000 Hz, got {args.policy_rate:g}")
    args.policy_image_size = image_size(args.policy_image_size)
    args.policy = load_policy(args.policy)  # a policy that does not load stops us here


def image_size(text: Any) -> tuple[int, int]:
    """``--policy-image-size WxH`` (8..2048 each) as (width, height); ConfigError if not."""
    if isinstance(text, tuple):
        return text
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        w = h = 0
    if not (8 <= w <= 2048 and 8 <= h <= 2048):
        raise ConfigError(f"--policy-image-size must be WIDTHxHEIGHT, 8..2048 each, got {text!r}")
    return (w, h)


def policy_vision_factory(sim: Any, robot: Any, args: argparse.Namespace, calibration: Any,
                          latency_s: float | None) -> Any:
    """``--policy``: the pilot's vision detecting only, with the policy flying in the pad
    modes (:class:`skeye.pilot.policy.PolicyPilot`, docs/gym.md "The pilot adapter")."""
    from skeye.pilot.policy import ActionLimits, DetectOnlyVision, policy_factory

    cfg = robot.motion_config
    make_vision = pad_vision_factory(sim, robot, args.camera, calibration, latency_s=latency_s,
                                     vision_class=DetectOnlyVision)
    return policy_factory(
        make_vision, args.policy, observation=args.policy_observation,
        limits=ActionLimits(cfg.max_speed_m_s, cfg.max_climb_m_s, cfg.max_yaw_rate_rad_s),
        period_s=1.0 / args.policy_rate, image_size=args.policy_image_size,
    )


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
    return ""


def camera_fov_rad(sim: Any, camera: str = "Down") -> float:
    """The camera's horizontal field of view (float, rad), asked of the simulator."""
    conf = sim.request("GETCONF", ("Type", "Camera"), ("Name", camera))
    return float(conf.get_float("FOV"))


def register(subparsers: Any) -> None:
    """Add ``skeye pilot`` to the main parser's subcommands."""
    p = subparsers.add_parser(
        "pilot",
        help="the vehicle's onboard program: fly a simulated robot, an AscTec LL board or a "
             "MAVLink flight controller",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    # ``--location -3,0,0`` (south of the origin) is a value, as ``-3`` alone is to argparse:
    # its test for "a negative number, not an option" is widened to a comma-separated vector
    p._negative_number_matcher = re.compile(  # argparse has no public hook for this
        r"^-\d+$|^-\d*\.\d+$|^-\.?\d[^,\s]*(,[^,\s]*)+$")
    p.add_argument("--sim", default="127.0.0.1:3000", help="simulator control address (the "
                   "airframe sim://ADDRESS when --airframe is not given)")
    p.add_argument(
        "--airframe",
        default=None,
        metavar="URI",
        help="the vehicle to fly: sim://HOST:PORT (a robot of the simulator; default "
        "sim://<--sim>), asctec-ll://serial/dev/ttyS1?baud=57600 or asctec-ll://tcp/HOST:PORT "
        "(an AscTec low-level board, real or `skeye sim --ll-board`; docs/onboard.md), "
        "mavlink://serial/dev/ttyACM0?baud=921600, mavlink://udp/127.0.0.1:14540 (the "
        "controller sends there), mavlink://udpout/HOST:PORT or mavlink://tcp/HOST:PORT (a "
        "PX4-style flight controller in offboard control; docs/protocols/mavlink.md)",
    )
    p.add_argument(
        "--images",
        default=None,
        help="image server address (e.g. 127.0.0.1:5003): enables landing-pad vision",
    )
    p.add_argument(
        "--camera",
        default=DEFAULT_CAMERA,
        metavar="NAME|URI",
        help="the downward camera: a camera name of the spawned robot (with --images), or a "
        "URI: sim://HOST:PORT/ROBOT/CAMERA (the simulator's image server), "
        "v4l2:///dev/video0?width=800&height=600&fps=30 (a real camera), file://video.mp4 "
        "(a recorded video, at its frame rate); docs/onboard.md",
    )
    p.add_argument(
        "--calibration",
        type=cliargs.path,
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
        "--frame-time",
        choices=("arrival", "capture"),
        default="arrival",
        help="a camera frame's time to the pilot: arrival (default), when it reached the "
        "pilot, as a host timestamps a USB webcam's frames (the capture latency unknown); "
        "capture, the simulator's exact capture time (the comparison case). See docs/pilot.md, "
        "Frame times",
    )
    p.add_argument(
        "--pad-source",
        choices=("vision", "truth"),
        default="vision",
        help="where pad observations come from: vision (default), the detector on the camera "
        "frames; truth, the simulator's ground truth at each frame's capture in place of the "
        "detection (a comparison mode: a perfect detector, same timing)",
    )
    p.add_argument(
        "--frame-jitter-ms",
        type=float,
        default=0.0,
        metavar="MS",
        help="the host's timestamp jitter on each frame's arrival: uniform in 0..MS ms, seeded "
        "(default 0; the simulated webcam's own delivery jitter is the camera model's)",
    )
    p.add_argument(
        "--no-vision-prediction",
        action="store_true",
        help="fly pad hold on each detection as it arrives instead of on the pad offset "
        "predicted to now from its capture pose (for comparison; docs/pilot.md)",
    )
    p.add_argument(
        "--video-port",
        type=cliargs.port,
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
    p.add_argument(
        "--policy",
        default=None,
        metavar="MODULE:CALLABLE",
        help="fly a policy (observation -> action, e.g. one learned in skeye.gym) in place of "
        "the pad-hold law while PAD_MODE is HOLD or LAND; needs --images (docs/gym.md)",
    )
    p.add_argument(
        "--policy-observation",
        default="pad",
        help="what the policy observes: pad (state + pad detection, PadLanding-v0's default) "
        "or image (state + grey camera image)",
    )
    p.add_argument("--policy-rate", type=float, default=20.0,
                   help="policy calls per sim second (the environments' control_rate_hz; 20)")
    p.add_argument("--policy-image-size", default="80x60", metavar="WxH",
                   help="the image observation's size (the environments' image_size; 80x60)")
    p.add_argument(
        "--mavlink",
        action="append",
        default=None,
        metavar="URI",
        help="also serve the vehicle as a MAVLink 2 autopilot on this link (repeatable): "
        "udpout://127.0.0.1:14550 sends to QGroundControl, udpout://127.0.0.1:14540 to a "
        "MAVSDK script, udp://127.0.0.1:14560 listens, tcp://127.0.0.1:5760 serves TCP, "
        "serial:///dev/ttyUSB0?baud=57600 a radio (docs/protocols/mavlink.md)",
    )
    p.add_argument(
        "--mavlink-sysid",
        type=int,
        default=1,
        metavar="N",
        help="the vehicle's MAVLink system id, 1..255 (default 1): give each vehicle of a "
        "fleet its own, as PX4's MAV_SYS_ID or ArduPilot's SYSID_THISMAV, so that one ground "
        "station tells them apart",
    )
    p.add_argument(
        "--rtp-video",
        default=None,
        metavar="udp://HOST:PORT",
        help="also send the camera with the pad detection drawn on it as H.264 over RTP "
        "(QGroundControl's UDP video on udp://127.0.0.1:5600; needs --images and PyAV)",
    )
    p.add_argument("--rtp-fps", type=cliargs.positive_float, default=10.0,
                   help="most frames per second of the RTP video, 0.1..60 (default 10)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--port", type=cliargs.port, default=DEFAULT_PORT,
                       help="TCP port (0 = any free)")
    where.add_argument("--serial", default=None, help="serve on this serial device instead")
    p.add_argument("--baud", type=cliargs.baud, default=57600,
                   help="serial baud rate (1..4000000)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--robot", default="hummingbird", help="robot class to spawn")
    p.add_argument(
        "--robot-dir",
        type=cliargs.path,
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
    p.add_argument("--location", default=None, metavar="N,E,D",
                   help="spawn at north,east,down (m) instead, e.g. -3,0,0 (3 m south)")
    p.add_argument("--link-timeout", type=cliargs.positive_float, default=2.0,
                   help="s without packets -> hold")
    p.add_argument("--land-timeout", type=cliargs.positive_float, default=20.0,
                   help="s more -> land")
    p.add_argument(
        "--lockstep-rate",
        type=cliargs.non_negative_float,
        default=LOCKSTEP_RATE_DEFAULT,
        help="lockstep sim: sim seconds per wall second (0 = unpaced)",
    )
    p.add_argument(
        "--lockstep-sync",
        action="store_true",
        help="lockstep sim: keep the clock together with the other pilots that give it, one "
        "per robot (STEP {Sync true}; without it several pilots' steps add up); a pilot that "
        "stops stepping holds the others (docs/pilot.md, Several vehicles)",
    )
    p.add_argument(
        "--ground-clock",
        action="store_true",
        help="lockstep sim: advance only up to the sim time the ground grants (CLOCK packets)",
    )
    p.add_argument("--tick", type=cliargs.positive_float, default=0.01,
                   help="loop period in realtime (s)")
    p.add_argument("--timeout", type=cliargs.positive_float, default=10.0,
                   help="simulator answer deadline (s)")
    p.add_argument(
        "--sim-frozen-timeout",
        type=cliargs.positive_float,
        default=5.0,
        metavar="S",
        help="realtime: sim time standing still for S wall seconds means the simulator froze "
        "(failsafe, as if it were gone); default 5",
    )
    p.set_defaults(func=run)
