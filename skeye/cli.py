"""The ``skeye`` command line: one sub-command per process or tool."""

from __future__ import annotations

import argparse
import logging
import os
import select
import sys
import threading
import time
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from functools import partial
from typing import Any

from skeye import __version__, cliargs
from skeye.cliargs import EXTRA_OF, missing_extra
from skeye.errors import SkeyeError
from skeye.processes import on_stop_signals, wait_for_signal
from skeye.uris import url_host

ENGINE_FAILED_STATUS = 3
FAULT_ENV = "SKEYE_SIM_FAULT_AT_S"
"""Fault injection for tests (docs/reliability.md): the engine raises once sim time passes this."""


def _inject_fault(sim: Any) -> None:
    """Install the engine fault named by ``SKEYE_SIM_FAULT_AT_S``, if set."""
    text = os.environ.get(FAULT_ENV)
    if not text:
        return
    try:
        at_s = float(text)
    except ValueError:
        raise SkeyeError(f"{FAULT_ENV} must be a number of seconds, got {text!r}") from None

    def fault(s: Any) -> None:
        if s.time_s >= at_s:
            raise RuntimeError(f"injected engine fault at sim time {s.time_s:.3f} s ({FAULT_ENV})")

    sim.step_hooks.append(fault)
    print(f"skeye sim: {FAULT_ENV}={at_s:g}: the engine will fail on purpose", flush=True)


DEFAULT_IMAGE_QUALITY = 85  # skeye sim --image-format jpeg without --image-quality


def image_defaults(args: argparse.Namespace) -> tuple[Any, int | None]:
    """``--image-format``/``--image-quality`` as the image server's defaults (checked)."""
    from skeye.errors import ConfigError
    from skeye.wire.image_requests import SetFormat
    from skeye.wire.images import ImageFormat

    kind = ImageFormat(args.image_format.upper())
    quality = args.image_quality
    if quality is not None and kind is not ImageFormat.JPEG:
        raise ConfigError(f"--image-quality applies to --image-format jpeg only, not "
                          f"{args.image_format}")
    if kind is ImageFormat.JPEG and quality is None:
        quality = DEFAULT_IMAGE_QUALITY
    if args.image_port is None and (kind is not ImageFormat.RAW or quality is not None):
        raise ConfigError("--image-format and --image-quality need --image-port (the image "
                          "server is off without it)")
    try:
        SetFormat(kind, quality)  # the same rules as a client's SKEYE FORMAT
    except SkeyeError as exc:
        raise ConfigError(f"--image-quality: {exc}") from None
    return kind, quality


DEFAULT_RECORD_MAX_MB = 1024.0  # skeye sim --record without --record-max-mb
DEFAULT_RECORD_PARTS = 10  # skeye sim --record-rotate without --record-parts


def record_limits(args: argparse.Namespace) -> tuple[float, int]:
    """``--record-max-mb`` and ``--record-parts`` (defaults filled in), refused where they
    would do nothing: the ``--record-*`` options without ``--record``, ``--record-parts``
    without ``--record-rotate``."""
    from skeye.errors import ConfigError

    given = [option for option, value in (
        ("--record-max-mb", args.record_max_mb), ("--record-rotate", args.record_rotate or None),
        ("--record-parts", args.record_parts)) if value is not None]
    if args.record is None and given:
        verb = "needs" if len(given) == 1 else "need"
        raise ConfigError(f"{', '.join(given)} {verb} --record FILE (without it nothing is "
                          "recorded)")
    if args.record_parts is not None and not args.record_rotate:
        raise ConfigError("--record-parts counts --record-rotate's parts: give --record-rotate "
                          "too (without it the recording stops at --record-max-mb)")
    max_mb = DEFAULT_RECORD_MAX_MB if args.record_max_mb is None else args.record_max_mb
    parts = DEFAULT_RECORD_PARTS if args.record_parts is None else args.record_parts
    return max_mb, parts


def check_timestep(timestep_s: float) -> None:
    """``--timestep`` within the engine's range, said in the option's name.

    Raises:
        ConfigError: outside it.
    """
    from skeye.errors import ConfigError
    from skeye.sim.limits import TIMESTEP_RANGE_S

    low, high = TIMESTEP_RANGE_S
    if not low <= timestep_s <= high:
        raise ConfigError(f"--timestep must be in [{low:g}, {high:g}] s (the physics step), "
                          f"got {timestep_s:g}")


def check_sim_files(args: argparse.Namespace) -> int:
    """``skeye sim --check``: the world and the robot files (``--robot-dir``) loaded and
    checked as the simulator checks them at its start, the first problem said (status 2) or
    nothing (0); nothing started: no MuJoCo, no port. ``skeye up`` asks it before it starts
    anything (it never imports the simulator itself)."""
    from skeye.robots.config import validate_robot_dirs
    from skeye.sim.robot import check_robot_config
    from skeye.sim.world_file import load_world

    check_timestep(args.timestep)  # the robot files are checked at this physics step
    load_world(args.world)
    validate_robot_dirs(tuple(args.robot_dir),
                        partial(check_robot_config, physics_step_s=args.timestep,
                                estimator=args.estimator),
                        args.camera_profile)
    return 0


def cmd_sim(args: argparse.Namespace) -> int:
    """Run the simulator: control server (and image server when asked) until stopped."""
    if args.check:
        return check_sim_files(args)
    from skeye import native
    from skeye.processes import check_ports_free
    from skeye.robots.config import validate_robot_dirs
    from skeye.sim.engine import Simulation
    from skeye.sim.robot import check_robot_config
    from skeye.sim.runner import SimulationRunner
    from skeye.sim.server import ControlServer
    from skeye.sim.world import load_world
    from skeye.wire.wind import make_settings, parse_params

    image_format, image_quality = image_defaults(args)  # before anything starts
    record_max_mb, record_parts = record_limits(args)
    check_timestep(args.timestep)
    ports = [("the simulator's control protocol", args.host, args.port, "--port")]
    if args.image_port is not None:
        ports.append(("the simulator's image server", args.host, args.image_port,
                      "--image-port"))
    ll_boards = ll_board_specs(args)
    ports += [(f"LL board {spec.name}'s line", args.host, spec.port,
               f"--ll-board {spec.name}=tcp:PORT") for spec in ll_boards if spec.line == "tcp"]
    check_ports_free(ports)  # named, with the option that moves it, before MuJoCo loads
    world = load_world(args.world)
    # A robot file with a typo, or one INIT would refuse, stops us here.
    validate_robot_dirs(tuple(args.robot_dir),
                        partial(check_robot_config, physics_step_s=args.timestep,
                                estimator=args.estimator),
                        args.camera_profile)
    wind = make_settings(args.wind, parse_params(args.wind_params))
    sim = Simulation(
        world, seed=args.seed, timestep_s=args.timestep, wind=wind,
        robot_dirs=tuple(args.robot_dir), estimator=args.estimator,
    )
    _inject_fault(sim)
    stop = threading.Event()
    with ExitStack() as stack:
        runner = stack.enter_context(SimulationRunner(sim, mode=args.mode))
        cameras = None
        if args.image_port is not None:
            from skeye.sim.cameras import CameraSystem
            from skeye.sim.image_server import FrameBuffer, ImageServer

            buffer = FrameBuffer()
            cameras = CameraSystem(sim, buffer, synchronous=args.mode == "lockstep",
                                   profile=args.camera_profile)
            stack.callback(cameras.close)
        recorder = None
        if args.record is not None:
            from skeye.recording.records import Recorder

            meta = {
                "world": world.name,
                "mode": args.mode,
                "timestep_s": args.timestep,
                "seed": args.seed,
                "wind": args.wind,
            }
            # Entered before the server, so it closes after it and keeps the last lines.
            recorder = stack.enter_context(Recorder(
                args.record, meta, max_bytes=round(record_max_mb * 2**20),
                rotate=args.record_rotate, max_parts=record_parts))
        limits: dict[str, Any] = {
            "handshake_timeout_s": args.handshake_timeout,
            "idle_timeout_s": args.idle_timeout,
        }
        if args.max_clients_per_peer is not None:
            limits["max_clients_per_peer"] = args.max_clients_per_peer
        server = stack.enter_context(
            ControlServer(runner, host=args.host, port=args.port, **limits)
        )
        # Taken before the address is printed: a stop signal sent the moment a user (or a
        # script) reads it stops in order; it used to kill the process outright until the wait
        # below set the handlers, after the other servers' lines.
        on_stop_signals(lambda *_: stop.set())
        where = "all interfaces" if args.host in ("0.0.0.0", "::") else args.host
        print(
            f"skeye sim: world {world.name!r}, {args.mode} mode, step {args.timestep * 1000:g} ms, "
            f"seed {args.seed}, estimator {args.estimator or 'per robot file'}; "
            f"control protocol on {url_host(args.host)}:{server.port} ({where})",
            flush=True,
        )
        print(f"skeye sim: {native.status().describe()}", flush=True)
        if recorder is not None:
            recorder.attach(server, runner)
            print(f"skeye sim: recording to {args.record}", flush=True)
        if cameras is not None:
            images = stack.enter_context(
                ImageServer(cameras.buffer, host=args.host, port=args.image_port,
                            default_format=image_format, default_quality=image_quality,
                            **limits)
            )
            print(
                f"skeye sim: image server on {url_host(args.host)}:{images.port} "
                f"(MUJOCO_GL={os.environ.get('MUJOCO_GL')}; frames {image_format.value}"
                f"{f' {image_quality}' if image_quality is not None else ''} by default)",
                flush=True,
            )
            print(f"skeye sim: camera renderer: {cameras.describe_renderer()}", flush=True)
        board_failures: list[str] = []  # an LL board whose worker died: the simulator stops
        if ll_boards:
            from skeye.hil.cli import describe, start_ll_board

            def board_failed(name: str) -> Callable[[BaseException], None]:
                def failed(exc: BaseException) -> None:  # on the dying worker's thread
                    board_failures.append(f"LL board {name} failed: {type(exc).__name__}: "
                                          f"{exc}")
                    stop.set()
                return failed

            image_port = images.port if cameras is not None else None
            for spec in ll_boards:
                board = start_ll_board(stack, spec, f"127.0.0.1:{server.port}", host=args.host,
                                       on_error=board_failed(spec.name))
                print(f"skeye sim: {describe(board, image_port, args.host)}", flush=True)
        if args.host == "127.0.0.1":
            print(
                "skeye sim: bound to 127.0.0.1 only; use --host 0.0.0.0 to accept other machines",
                flush=True,
            )
        wait_for_signal(stop, runner.failed)
        if runner.error is not None:
            print(f"skeye sim: error: {runner.error}; stopping", file=sys.stderr, flush=True)
            # The clients were told (ERR {Command ENGINE}); let their writers flush it.
            deadline = time.monotonic() + 2.0
            while server.client_count and time.monotonic() < deadline:
                time.sleep(0.05)
        elif board_failures:  # its line answers no one now: a bench that looks alive is worse
            print(f"skeye sim: error: {'; '.join(board_failures)}; stopping", file=sys.stderr,
                  flush=True)
        else:
            print("skeye sim: stopping", flush=True)
    return ENGINE_FAILED_STATUS if runner.error is not None or board_failures else 0


def ll_board_specs(args: argparse.Namespace) -> list[Any]:
    """``--ll-board`` values, parsed before anything starts (ConfigError names a bad one)."""
    if not args.ll_board:
        return []
    from skeye.errors import ConfigError
    from skeye.hil.cli import parse_ll_board

    specs = [parse_ll_board(text) for text in args.ll_board]
    names = [spec.name for spec in specs]
    if len(set(names)) != len(names):
        raise ConfigError(f"--ll-board names must differ, got {', '.join(names)}")
    for spec, text in zip(specs, args.ll_board, strict=True):
        if spec.rate is not None and args.mode != "lockstep":
            raise ConfigError(f"--ll-board {text!r}: rate={spec.rate:g} is for --mode lockstep "
                              "(the board drives the lockstep clock); a realtime simulator's "
                              "clock is the wall clock")
    return specs


def _add_sim(sub: Any) -> None:
    p = sub.add_parser("sim", help="run the simulator (control protocol server)")
    p.add_argument("--world", type=cliargs.path, default="pad",
                   help="built-in world (pad, yard, indoor, checkerboard) or a .toml")
    p.add_argument("--check", action="store_true",
                   help="check --timestep, the world and the --robot-dir robot files, say "
                        "what is wrong (status 2) or nothing (0), and start nothing")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=cliargs.port, default=3000,
                   help="control protocol port (0 = any free)")
    p.add_argument("--mode", choices=("realtime", "lockstep"), default="realtime")
    p.add_argument("--seed", type=cliargs.seed, default=0,
                   help="seed of every random source (a whole number >= 0)")
    p.add_argument("--timestep", type=cliargs.positive_float, default=0.001,
                   help="physics step in seconds")
    p.add_argument(
        "--estimator",
        choices=("onboard", "truth"),
        default=None,
        help="the boards' state estimator for every robot: onboard (from the simulated sensor "
        "readings; vehicles drift as real ones) or truth (an oracle: ground truth plus small "
        "INS error processes); default: each robot file's [estimator] kind, which defaults "
        "to onboard",
    )
    p.add_argument(
        "--wind", default="none", help="wind mode: none, constant, turbulence, dryden "
        "(MIL-F-8785C low-altitude gusts), random_force (docs/physics.md, Wind)"
    )
    p.add_argument(
        "--wind-params",
        default="",
        help="wind parameters, e.g. speed_m_s=3,from_deg=90 or f_max_n=0.3",
    )
    p.add_argument(
        "--robot-dir",
        action="append",
        default=[],
        type=cliargs.file_path,
        help="folder of extra robot classes (<name>.toml); repeatable",
    )
    p.add_argument(
        "--image-port",
        type=cliargs.port,
        default=None,
        help="serve camera images on this port (5003 by convention; 0 = any free)",
    )
    p.add_argument(
        "--camera-profile",
        choices=("ideal", "webcam"),
        default=None,
        help="camera model of every robot camera, over the robot files' own (docs/camera.md): "
        "ideal = perfect pinhole; webcam = Logitech C-series-class USB webcam (distortion, "
        "noise, motion blur, rolling shutter, MJPEG, capture latency, shadows)",
    )
    p.add_argument(
        "--image-format",
        choices=("raw", "jpeg", "png"),
        default="raw",
        help="the frame format an image client gets until it asks for another with SKEYE "
        "FORMAT (USARSim's image server lets its operator choose it too; default raw)",
    )
    p.add_argument(
        "--image-quality",
        type=int,
        default=None,
        metavar="Q",
        help=f"JPEG quality 1-100 of --image-format jpeg (default {DEFAULT_IMAGE_QUALITY})",
    )
    p.add_argument(
        "--max-clients-per-peer",
        type=cliargs.positive_int,
        default=None,
        metavar="N",
        help="connections one peer address may hold on each server "
        "(default: half the slots: 64 control, 32 image)",
    )
    p.add_argument(
        "--handshake-timeout",
        type=cliargs.positive_float,
        default=10.0,
        metavar="S",
        help="close a connection that sends no command within S seconds (default 10)",
    )
    p.add_argument(
        "--idle-timeout",
        type=cliargs.positive_float,
        default=120.0,
        metavar="S",
        help="close a connection without a robot (control) or without a stream (images) that "
        "sends nothing for S seconds (default 120)",
    )
    p.add_argument(
        "--record",
        type=cliargs.file_path,
        default=None,
        metavar="FILE",
        help="record every line sent and received, and ground truth, to FILE (docs/recording.md)",
    )
    p.add_argument(
        "--record-max-mb",
        type=cliargs.positive_float,
        default=None,
        metavar="MB",
        help="the recording stops (or, with --record-rotate, goes on in FILE.2, FILE.3, ...) "
        "when it reaches MB MiB, and stops when the disk has less than 256 MiB left "
        "(default 1024)",
    )
    p.add_argument("--record-rotate", action="store_true",
                   help="at --record-max-mb, go on in a new part instead of stopping")
    p.add_argument("--record-parts", type=cliargs.positive_int, default=None, metavar="N",
                   help="the most parts --record-rotate writes before it stops (default 10)")
    p.add_argument(
        "--ll-board",
        action="append",
        default=[],
        metavar="NAME=LINE",
        help="spawn robot NAME and present it as an AscTec low-level board on LINE: pty (a "
        "pseudo-terminal; its path is printed), tcp:PORT or serial:DEVICE; options after "
        "commas: robot=CLASS, start=POSE, baud=N, serial_timeout=S, rate=R (lockstep: the board "
        "drives the clock at R sim seconds per wall second); repeatable. The pilot flies it "
        "with --airframe asctec-ll://... (docs/onboard.md)",
    )
    p.set_defaults(func=cmd_sim)


def _add_vision(sub: Any) -> None:
    from skeye.vision.cli import register

    register(sub)


def _add_calibrate(sub: Any) -> None:
    from skeye.vision.calibrate_cli import register

    register(sub)


def _add_snapshot(sub: Any) -> None:
    from skeye.recording.snapshot import register

    register(sub)


def _add_replay(sub: Any) -> None:
    from skeye.recording.replay import register

    register(sub)


def _add_plot(sub: Any) -> None:
    from skeye.recording.plotting import register

    register(sub)


def _add_pilot(sub: Any) -> None:
    from skeye.pilot.cli import register

    register(sub)


def _add_link(sub: Any) -> None:
    from skeye.link.cli import register

    register(sub)


def _add_ground(sub: Any) -> None:
    from skeye.ground.cli import register  # adds `ground` and `up`

    register(sub)


def _add_validate(sub: Any) -> None:
    from skeye.validate.cli import register

    register(sub)


def _add_logs(sub: Any) -> None:
    from skeye.sim.log_replay import register

    register(sub)


def _add_sweep(sub: Any) -> None:
    from skeye.sweep.cli import register

    register(sub)


# Each component adds its sub-commands here, by the names it adds (ground's adds two).
_REGISTRARS: dict[str, Callable[[Any], None]] = {
    "sim": _add_sim,
    "snapshot": _add_snapshot,
    "pilot": _add_pilot,
    "link": _add_link,
    "ground": _add_ground,
    "up": _add_ground,
    "pad": _add_vision,
    "vision": _add_vision,
    "calibrate": _add_calibrate,
    "validate": _add_validate,
    "sweep": _add_sweep,
    "replay": _add_replay,
    "plot": _add_plot,
    "logs": _add_logs,
}


def _command_named(argv: Sequence[str]) -> str | None:
    """The sub-command ``argv`` names, where it names one of ours after the top-level options
    (``-v``); None for ``--help``, ``--version``, no command or an unknown word."""
    for arg in argv:
        if arg in ("-v", "--verbose"):
            continue
        return arg if arg in _REGISTRARS else None
    return None


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The parser of every sub-command; or, given the ``argv`` about to be parsed and a
    command it names, of that command alone. Each component's options import its module, and
    all of them together took about 0.5 s of a start (``skeye ground`` 0.11 s on its own), paid
    by every process ``skeye up``, a sweep or a test starts; ``--help`` and a mistyped command
    still list every command."""
    parser = argparse.ArgumentParser(
        prog="skeye", description="A distributed development environment for small UAVs."
    )
    parser.add_argument("--version", action="version", version=f"skeye {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    command = None if argv is None else _command_named(argv)
    registrars = [_REGISTRARS[command]] if command else list(dict.fromkeys(_REGISTRARS.values()))
    for register in registrars:
        register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(argv).parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.WARNING,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.func(args))
    except ModuleNotFoundError as exc:
        top = (exc.name or "").split(".")[0]
        if top not in EXTRA_OF:
            raise
        print(f"skeye {args.command}: error: {missing_extra([top])}", file=sys.stderr)
        return 2
    except SkeyeError as exc:
        print(f"skeye {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError as exc:
        if not _stdout_closed():  # a socket's broken pipe: an error as any other OSError
            print(f"skeye {args.command}: error: {exc}", file=sys.stderr)
            return 2
        _silence_stdout()  # the reader went away (| head): stop quietly
        return 0
    except OSError as exc:
        print(f"skeye {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        # Ctrl-C where the command keeps no handler of its own (skeye link ... stream 60, a
        # command still importing): said in one line, 130 as a shell reports SIGINT
        print(f"skeye {args.command}: interrupted (Ctrl-C)", file=sys.stderr)
        return 130


def _stdout_closed() -> bool:
    """Whether standard output is a pipe whose reader has gone (poll says POLLERR)."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        return False  # not a file (a StringIO in tests)
    poller = select.poll()
    poller.register(fd, select.POLLOUT)
    return any(events & select.POLLERR for _, events in poller.poll(0))


def _silence_stdout() -> None:
    """After a broken pipe: point standard output's descriptor at /dev/null, so that Python's
    own flush at exit does not fail on it again (the idiom of the Python docs, "Note on
    SIGPIPE")."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    finally:
        os.close(devnull)


if __name__ == "__main__":
    sys.exit(main())
