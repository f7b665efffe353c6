"""``skeye ground`` (the web UI server) and ``skeye up`` (simulator + pilot + ground control).

``skeye ground --vehicle tcp://127.0.0.1:7000 [--video tcp://127.0.0.1:7001] --port 8080``
serves the page on http://127.0.0.1:8080/ (``--host`` to listen elsewhere); ``--vehicle`` may be
``serial:///dev/ttyUSB0?baud=57600`` for the real vehicle. ``--video`` is the vehicle's video
port (``skeye pilot --video-port``): the page shows the frames and detections the vehicle sent.

``skeye up`` starts ``skeye sim`` (with its image server), ``skeye pilot`` and ``skeye ground``
as child processes on this machine, waits until each one listens, prints the URL, and on Ctrl-C
or SIGTERM (or when one of them fails, or when the ``make`` that started it is signalled) stops
them all in the reverse of their start order, clients before the servers they use: ground
control, then the pilot, then the simulator, each sent SIGTERM only once the one before has
exited (SIGKILL for one that has not within ``STOP_TIMEOUT_S``), so a normal stop logs no lost
camera, simulator or link. A second Ctrl-C or SIGTERM during the stop kills every child still
running at once, as a second Ctrl-C does to ``docker compose up``: three children hung at their
stop would otherwise hold it ``STOP_TIMEOUT_S`` each. A child that was killed (by a signal, or
stopped with status 0 by one it caught) is started again on the same ports, as systemd's
``Restart=on-abnormal`` does, at most ``RESTART_BURST`` times in ``RESTART_WINDOW_S``: the
pilot re-attaches to a restarted simulator, ground control reconnects to a restarted pilot. A
child that exits with an error status (the simulator's engine failed: 3; a bad option: 2; ...)
stops everything, saying why.
The pilot serves its camera on ``--video-port`` (default 7001) and ground control shows
that. Before starting anything it checks that each of its five ports is free and names the
option that moves a taken one.

The pilot flies the robot's camera with its calibration, as on a real vehicle: with
``--calibration auto`` (the default) and a robot camera whose lens distorts (the Hummingbird's
``webcam`` profile), ``skeye up`` first calibrates that camera the way a user would (the
checkerboard world photographed from 14 poses, then OpenCV's ``calibrateCamera``:
:func:`skeye.validate.calibration.calibrate_simulated_camera`) and keeps the result in
``$XDG_CACHE_HOME/skeye/calibration/`` (``~/.cache``), keyed by the camera model, so it is done
once. ``--calibration FILE`` gives the pilot that file (``skeye calibrate``'s), ``none`` none.
"""

from __future__ import annotations

import argparse
import atexit
import hashlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from skeye import cliargs
from skeye.errors import ConfigError, LocalProtocolError
from skeye.outputs import cache_folder
from skeye.peers import listen
from skeye.processes import (
    EXIT_LOST_SIMULATOR,
    check_ports_free,
    die_with_parent,
    on_stop_signals,
    sleep_until,
)
from skeye.uris import url_host

if TYPE_CHECKING:
    from skeye.robots.config import RobotConfig

CHECK_TIMEOUT_S = 120.0  # skeye sim --check of --world (a child: its imports, no MuJoCo)
HEADER_TIMEOUT_S = 10.0  # skeye.ground.limits.HEADER_TIMEOUT_S (imported lazily there)
MAX_PER_PEER = 32  # skeye.ground.limits.MAX_PER_PEER
DEFAULT_VIDEO_FPS = 8.0  # skeye ground --video-fps: frames/s asked of the vehicle's video port
LINK_RETRY_S = 1.0  # skeye ground: between attempts to reach the vehicle (VehicleBridge's)
STOP_TIMEOUT_S = 10.0  # each child, after its SIGTERM, before SIGKILL
RESTART_BURST = 5
"""Restarts of one child within ``RESTART_WINDOW_S`` before skeye up gives up (systemd's default
``StartLimitBurst`` is 5)."""
RESTART_WINDOW_S = 600.0
START_DEADLINE_S = 180.0  # per child: a loaded machine can take a minute to import MuJoCo


def run_ground(args: argparse.Namespace) -> int:
    """Serve the ground-control page until SIGINT/SIGTERM."""
    from skeye.ground.app import create_app, uvicorn_config
    from skeye.ground.bridge import LinkState, VehicleBridge
    from skeye.ground.commands import VehicleLimits
    from skeye.ground.guard import TOKEN_ENV, GroundSecurity, new_token
    from skeye.ground.limits import ConnectionLimits, GroundServer, limit_repeats
    from skeye.ground.video import VideoRelay, parse_video_uri
    from skeye.robots.config import robot_folders
    from skeye.wire.packets import VehicleInfo
    from skeye.wire.video import MAX_FPS, MIN_FPS, Subscribe

    if not (args.header_timeout > 0 and args.max_connections_per_peer >= 1):
        raise ConfigError(f"--header-timeout must be > 0 s and --max-connections-per-peer >= 1, "
                          f"got {args.header_timeout!r}, {args.max_connections_per_peer!r}")
    try:
        security = GroundSecurity(
            token=os.environ.get(TOKEN_ENV) or new_token(),
            allowed_hosts=(*(args.allow_host or ()), *host_name(args.host)),
        )
    except ValueError as exc:
        raise ConfigError(f"{exc} (from ${TOKEN_ENV} or --allow-host)") from None

    from skeye.link.transport import parse_uri

    try:
        parse_uri(args.vehicle)  # a bad URI stops us here, not in the bridge's thread
    except LocalProtocolError as exc:
        raise ConfigError(f"--vehicle: {exc}") from None
    try:
        video_at = parse_video_uri(args.video) if args.video else None
    except LocalProtocolError as exc:
        raise ConfigError(f"--video: {exc}") from None
    if video_at is not None and video_at[1] == 0:  # a port to connect to, not "any free"
        raise ConfigError(f"--video {args.video}: port 0 is no port to connect to (the "
                          "pilot's --video-port, 1..65535)")
    if video_at is None and args.video_fps != DEFAULT_VIDEO_FPS:  # it would do nothing
        raise ConfigError("--video-fps applies to the vehicle's video: it needs --video")
    try:
        Subscribe(args.video_fps)  # what the video protocol carries, checked before the link
    except LocalProtocolError:
        raise ConfigError(f"--video-fps must be within [{MIN_FPS:g}, {MAX_FPS:g}] "
                          f"frames/s, got {args.video_fps:g}") from None
    robot_dirs = robot_folders(args.robot_dir)  # a typo is named now, not ignored
    try:
        limits = VehicleLimits.for_robot(args.robot, robot_dirs)  # before the link starts
    except ConfigError as exc:
        raise ConfigError(f"--robot: {exc}") from None
    # a taken port or a host that is not this machine's, named with the option that moves it
    check_ports_free([("ground control", args.host, args.port, "--port")])
    sock = listen(args.host, args.port)
    port = sock.getsockname()[1]
    def reached(info: VehicleInfo) -> None:
        # the vehicle's own words: printable characters only (no terminal escapes), and one
        # write, so the line never interleaves with the main thread's
        said = "".join(c for c in info.description if c.isprintable()) or "a vehicle"
        kind = "simulated" if info.simulated else "a real vehicle"
        sys.stdout.write(f"skeye ground: reached {said} ({kind}) at {args.vehicle}\n")
        sys.stdout.flush()

    def link(state: LinkState, error: str) -> None:
        # one write, as reached's: the vehicle's words made printable
        error = "".join(c for c in error if c.isprintable())
        again = f"; trying again every {LINK_RETRY_S:g} s"
        if state is LinkState.CONNECTED:
            line = f"the link to the vehicle at {args.vehicle} is up again"
        elif state is LinkState.REFUSED:
            line = f"the vehicle at {args.vehicle} turned this ground station away: {error}{again}"
        else:
            line = f"no link to the vehicle: {error}{again}"
        sys.stdout.write(f"skeye ground: {line}\n")
        sys.stdout.flush()

    with VehicleBridge(args.vehicle, retry_s=LINK_RETRY_S, on_vehicle=reached,
                       on_link=link) as bridge:
        video = None
        if video_at is not None:
            video = VideoRelay(*video_at, fps=args.video_fps).start()
        try:
            app = create_app(
                bridge, video, security=security,
                limits=limits,
                body_timeout_s=args.header_timeout,
            )
            connections = ConnectionLimits(header_timeout_s=args.header_timeout,
                                           max_per_peer=args.max_connections_per_peer)
            shown = page_host(args.host)

            def started() -> None:
                # once it listens and stops in order on a signal (GroundServer); one write
                # (print writes the text and its newline apart): the bridge's thread prints the
                # vehicle it reached, and a line of its must never land inside this one
                sys.stdout.write(
                    f"skeye ground: http://{shown}:{port}/?token={security.token} (vehicle "
                    f"{args.vehicle}{', video ' + args.video if args.video else ''})\n")
                sys.stdout.flush()

            server = GroundServer(uvicorn_config(app, limits=connections), on_started=started)
            limit_repeats()  # after uvicorn set its handlers: a flood of one error is summed up
            server.run(sockets=[sock])  # returns on SIGINT / SIGTERM
        finally:
            if video is not None:
                video.close()
    print("skeye ground: stopped", flush=True)
    return 0


def host_name(host: str) -> tuple[str, ...]:
    """``--host`` as a name the server answers to, when it is one (not an IP address): the
    page's address is printed with it, and was refused (``Host ... is not a name of this
    server``) without ``--allow-host`` of the same name."""
    import ipaddress

    try:
        ipaddress.ip_address(host.strip("[]"))
    except ValueError:
        return (host,)
    return ()


def check_world(world: str, robot_dirs: Sequence[Path]) -> None:
    """``--world`` checked by the simulator's own ``skeye sim --check`` in a child: named
    before anything starts (the simulator found it once started, after the camera's
    calibration), where this process never imports the simulator (docs/architecture.md).

    Raises:
        ConfigError: the simulator's words for what is wrong.
    """
    argv = [sys.executable, "-m", "skeye.cli", "sim", "--check", "--world", world,
            *(f"--robot-dir={folder}" for folder in robot_dirs)]
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=CHECK_TIMEOUT_S,
                              stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        raise ConfigError(f"--world {world}: the simulator's check took over "
                          f"{CHECK_TIMEOUT_S:g} s") from None
    if done.returncode != 0:
        said = [line for line in done.stderr.splitlines() if line.strip()]
        reason = said[-1].removeprefix("skeye sim: error: ") if said else \
            f"status {done.returncode}"
        raise ConfigError(reason)


def _add_ground(sub: Any) -> None:
    p = sub.add_parser(
        "ground",
        help="serve the ground-control web page for a vehicle",
        description="Serve the ground-control web page (telemetry, camera, map, commands).",
    )
    p.add_argument(
        "--vehicle",
        default="tcp://127.0.0.1:7000",
        help="vehicle link: tcp://host:port (skeye pilot) or serial:///dev/ttyUSB0?baud=57600",
    )
    p.add_argument(
        "--video",
        default=None,
        help="the vehicle's video port (skeye pilot --video-port), e.g. tcp://127.0.0.1:7001: "
        "the camera view shows its frames and its own pad detection",
    )
    p.add_argument(
        "--robot",
        default="hummingbird",
        help="the vehicle's robot class: the speed limits commands are checked against",
    )
    p.add_argument("--robot-dir", action="append", default=[], metavar="DIR", type=cliargs.path,
                   help="a folder of robot files where --robot is looked up (as skeye sim's)")
    p.add_argument("--video-fps", type=cliargs.positive_float, default=DEFAULT_VIDEO_FPS,
                   help="the most camera frames per second asked of the vehicle's --video "
                   f"(default {DEFAULT_VIDEO_FPS:g})")
    p.add_argument("--port", type=cliargs.port, default=8080, help="HTTP port (0 = any free)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--header-timeout", type=float, default=HEADER_TIMEOUT_S, metavar="S",
                   help="close a connection whose request head is not complete within S "
                   "seconds of connecting, or whose POST body is not complete within S "
                   f"seconds of its head (408; default {HEADER_TIMEOUT_S:g})")
    p.add_argument("--max-connections-per-peer", type=int, default=MAX_PER_PEER, metavar="N",
                   help="connections one local user (however many loopback addresses it "
                   f"binds) or remote address may hold (default {MAX_PER_PEER})")
    _add_allow_host(p)
    p.set_defaults(func=run_ground)


def _add_allow_host(p: Any) -> None:
    p.add_argument(
        "--allow-host",
        action="append",
        metavar="NAME",
        help="also answer to this host name in the Host header (IP addresses and localhost "
        "always are); repeat for several, e.g. for remote use under a DNS name",
    )


# --- skeye up --------------------------------------------------------------------------------


def _child_argv(*args: str) -> list[str]:
    """A skeye sub-command in a child interpreter (the same venv as this one)."""
    return [sys.executable, "-m", "skeye.cli", *args]


def page_host(host: str) -> str:
    """The host of the page's URL that ``skeye ground`` and ``skeye up`` print for a server
    bound to ``host``: 127.0.0.1 for a wildcard, an IPv6 address in brackets."""
    return url_host("127.0.0.1" if host in ("0.0.0.0", "::") else host)


def reach_host(host: str) -> str:
    """Where a client on this machine reaches a server bound to ``host``: the loopback for a
    wildcard (``0.0.0.0``, ``::``), else ``host`` itself (a server bound to one address of this
    machine, ``::1`` or a LAN address, is not on 127.0.0.1)."""
    if host in ("", "0.0.0.0"):
        return "127.0.0.1"
    if host == "::":
        return "::1"
    return host


class StartStopped(ConfigError):
    """Ctrl-C or SIGTERM while ``skeye up`` was starting: asked for, not a failure."""


class StartFailed(ConfigError):
    """A child exited while ``skeye up`` waited for it to listen (``what``: which one)."""

    def __init__(self, what: str, message: str) -> None:
        super().__init__(message)
        self.what = what


def _wait_listening(port: int, child: subprocess.Popen[bytes], what: str, deadline_s: float,
                    stop: threading.Event | None = None, host: str = "127.0.0.1") -> None:
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        # the stop first: a stop signal sent to every process (systemd's control group,
        # kill -- -PGID) may have ended the child too
        if stop is not None and stop.is_set():
            raise StartStopped(f"stopped while {what} was starting")
        if child.poll() is not None:
            raise StartFailed(what, f"{what} exited ({_exit_status(what, child.returncode)}) "
                              "while starting")
        try:
            with socket.create_connection((host, port), timeout=0.5):
                return
        except OSError:
            time.sleep(0.2)
    raise ConfigError(f"{what} did not listen on port {port} within {deadline_s:g} s")


def _stop_all(children: Sequence[tuple[str, subprocess.Popen[Any]]]) -> None:
    """Stop the children in the reverse of their start order, each a client of the ones
    started before it (ground control of the pilot, the pilot of the simulator and its image
    server): SIGTERM to one, wait up to ``STOP_TIMEOUT_S`` for it to exit (SIGKILL after), and
    only then the next, so that no client sees a server go away at a normal stop and logs it as
    a loss (the pilot's "camera lost", "vehicle lost"), as systemd stops units in the reverse
    of their ``After=`` order."""
    from skeye.processes import stop_processes

    for _, child in reversed(children):
        stop_processes([child], STOP_TIMEOUT_S)


_EXIT_MEANING = {
    ("simulator", 3): "its simulation engine failed",
    ("pilot", EXIT_LOST_SIMULATOR): "it lost the simulator",
}
SIM_SETTLE_S = 30.0
"""How long to wait for the simulator's own exit status once the pilot says it lost the
simulator: the simulator is then usually exiting, and its status names the root cause."""
OTHER_DEATH_SETTLE_S = 5.0  # the same wait after any other child's death


def _exit_meaning(what: str, status: int | None) -> str:
    return _EXIT_MEANING.get((what, status if status is not None else 0), "")


def _report_dead(children: Sequence[tuple[str, subprocess.Popen[bytes]]],
                 stop: threading.Event | None = None, named: str = "") -> bool:
    """Say which children have exited, and how (but ``named``, said already); True if any has.

    When another child died first, the simulator gets a moment to exit too: a pilot that lost
    its simulator (or failed while starting) is usually looking at one on its way out, and the
    simulator's own status names the root cause. ``stop`` set (Ctrl-C, SIGTERM) ends that wait:
    a stuck simulator never exits by itself, and the user asked to stop."""
    simulator = children[0][1] if children and children[0][0] == "simulator" else None
    others = [(w, c) for w, c in children if w != "simulator" and c.poll() is not None]
    if simulator is not None and others:
        lost = any(w == "pilot" and c.returncode == EXIT_LOST_SIMULATOR for w, c in others)
        _wait_exit(simulator, SIM_SETTLE_S if lost else OTHER_DEATH_SETTLE_S,
                   stop or threading.Event())
    dead = [(w, c) for w, c in children if c.poll() is not None]
    for what, child in dead:
        if what != named:
            print(f"skeye up: {what} exited ({_exit_status(what, child.returncode)}); "
                  "stopping", flush=True)
    return bool(dead)


def _exit_status(what: str, status: int | None) -> str:
    """A child's exit as said: ``3: its simulation engine failed``, ``SIGKILL``."""
    meaning = _exit_meaning(what, status)
    code = status or 0
    said = str(code) if code >= 0 else _signal_name(code)
    return f"{said}{': ' + meaning if meaning else ''}"


def _wait_exit(child: subprocess.Popen[Any], timeout_s: float, stop: threading.Event) -> None:
    """Wait up to ``timeout_s`` for ``child`` to exit, or until ``stop`` is set."""
    end = time.monotonic() + timeout_s
    while child.poll() is None:
        left = end - time.monotonic()
        if left <= 0.0 or sleep_until(stop, min(left, 0.05)):
            return


def restartable(status: int | None) -> bool:
    """Whether a child that ended with ``status`` is started again (see the module comment):
    killed by a signal (negative status), or stopped by one it caught (0)."""
    return status is not None and status <= 0


def _signal_name(status: int) -> str:
    if status >= 0:
        return f"status {status}"
    try:
        return signal.Signals(-status).name
    except ValueError:
        return f"signal {-status}"


def pilot_calibration(choice: str, robot: str, robot_dirs: tuple[Path, ...] = ()) -> Path | None:
    """The calibration file ``skeye up`` gives the pilot: ``choice`` is ``auto``, ``none`` or a
    file (see the module's docstring); ``robot`` is looked up as the simulator does, in the
    built-ins, then in ``robot_dirs`` (``--robot-dir``).

    Raises:
        ConfigError: a file that does not exist, an unknown robot, a calibration that failed.
    """
    from skeye.robots.config import CAMERA_TYPE, load_robot_config, mount_camera_model

    if choice == "none":
        return None
    if choice != "auto":
        from skeye.vision.calibration import load_calibration

        path = Path(choice)
        if path.is_dir():
            raise ConfigError(f"--calibration {choice} is a folder, not a calibration file "
                              "(give its .toml file, or auto or none)")
        if not path.is_file():
            raise ConfigError(f"--calibration {choice}: no such file (or give auto or none)")
        try:
            load_calibration(path)  # a bad file is refused here, before anything starts
        except Exception as exc:  # its message names the file already
            raise ConfigError(f"--calibration: {exc}") from None
        return path
    config = load_robot_config(robot, robot_dirs, allow_paths=False)
    mount = next((m for m in config.sensors if m.type_name.lower() == CAMERA_TYPE), None)
    if mount is None:
        return None  # a robot without a camera: nothing to calibrate
    model = mount_camera_model(config, mount)  # its first camera, as camera_model() takes
    if not model.distorted:
        return None  # the ideal pinhole: the pilot's field of view from GETCONF is exact
    from skeye import __version__
    from skeye.validate.calibration import (
        BOARD,
        PROCEDURE_VERSION,
        board_poses,
        calibrate_simulated_camera,
    )

    # The key: the camera model, the procedure (board, poses, how the views are taken) and
    # the simulator's version.
    ident = repr((model, BOARD, board_poses(model.width, model.height, model.fx_px),
                  PROCEDURE_VERSION, __version__))
    key = hashlib.sha256(ident.encode()).hexdigest()[:12]
    try:
        workdir = cache_folder("calibration") / f"{Path(robot).stem}-{model.profile}-{key}"
    except OSError as exc:
        raise ConfigError(f"--calibration auto keeps the calibration in a cache folder: {exc}; "
                          "set XDG_CACHE_HOME, or give --calibration FILE or none") from None
    path = workdir / "camera.toml"
    if path.is_file():
        print(f"skeye up: the pilot uses the camera calibration {path}", flush=True)
        return path
    print(f"skeye up: calibrating the {robot}'s {model.profile} camera on the checkerboard "
          f"world (once; kept in {workdir})", flush=True)
    partial = workdir.with_name(f"{workdir.name}.{os.getpid()}.partial")
    start = time.monotonic()

    def progress(step: str) -> None:
        print(f"skeye up: calibrating [{time.monotonic() - start:5.1f} s]: {step}", flush=True)

    try:
        calibrate_simulated_camera(partial, model.profile, robot=robot, progress=progress,
                                   robot_dirs=robot_dirs)
        try:
            os.replace(partial, workdir)  # whole or not at all
        except OSError:
            if not path.is_file():  # not another skeye up's calibration, done meanwhile
                raise
    except Exception as exc:
        raise ConfigError(f"calibrating the {robot}'s camera failed: {exc} (give "
                          "--calibration FILE or none)") from exc
    finally:
        if partial.exists():
            shutil.rmtree(partial, ignore_errors=True)
    return path


UP_NEEDS = ("mujoco", "fastapi", "uvicorn")
"""What ``skeye up``'s children import that lives in an extra (``cliargs.EXTRA_OF``)."""


def check_up_extras() -> None:
    """Refuse ``skeye up`` before it starts or calibrates anything when the simulator's or
    ground control's extra is missing (the onboard install), naming every extra it lacks.

    Raises:
        ConfigError: a module of ``UP_NEEDS`` is not installed.
    """
    from importlib.util import find_spec

    modules = [module for module in UP_NEEDS if find_spec(module) is None]
    if not modules:
        return
    extras = list(dict.fromkeys(cliargs.EXTRA_OF[module] for module in modules))
    named = ", ".join(modules[:-1]) + " and " + modules[-1] if len(modules) > 1 else modules[0]
    raise ConfigError(
        f"{named} {'is' if len(modules) == 1 else 'are'} not installed: this "
        f"command runs the simulator and ground control, so it needs skeye's "
        f"{' and '.join(extras)} extra{'s' if len(extras) > 1 else ''} (pip install "
        f"'skeye[sim,ground]'; the base install is the onboard pilot's, docs/onboard.md)")


def run_up(args: argparse.Namespace) -> int:
    """Start simulator, pilot and ground control; stop them all on a signal. Without the sim
    or ground extra it refuses at once (``check_up_extras``)."""
    from skeye.ground.guard import TOKEN_ENV, GroundSecurity, new_token

    check_up_extras()
    env = dict(os.environ)
    env.setdefault("MUJOCO_GL", "egl")
    token = env.get(TOKEN_ENV) or new_token()
    env[TOKEN_ENV] = token  # to the ground child by environment: argv is visible to all users
    stop = threading.Event()
    children: list[tuple[str, subprocess.Popen[bytes]]] = []
    killed: list[str] = []  # the children a second stop signal killed

    def handler(signum: int, frame: Any) -> None:
        if not stop.is_set():
            stop.set()  # the main thread stops the children, one after the other
            return
        # A second Ctrl-C or SIGTERM, or one while the children are being stopped: kill what
        # still runs now, not STOP_TIMEOUT_S a child later.
        for what, child in reversed(children):
            # poll() says None while the main thread waits on the child: a third signal
            # kills it again, but names it once
            if child.poll() is None:
                child.kill()
                if what not in killed:
                    killed.append(what)

    on_stop_signals(handler)
    commands: dict[str, tuple[list[str], tuple[int, ...]]] = {}  # what -> argv, its ports
    restarts: dict[str, list[float]] = {}  # what -> when it was restarted

    # Every exit path stops the children: the finally below, atexit if something escapes it,
    # and the kernel (PR_SET_PDEATHSIG) if this process is killed outright.
    atexit.register(_stop_all, children)

    def start(what: str, argv: list[str], *ports: int) -> None:
        # Its own process group: a terminal's Ctrl-C (SIGINT to the foreground group) reaches
        # skeye up alone, which stops the children in order; it used to reach all three at
        # once, and ground control logged the pilot gone at a normal stop.
        child = subprocess.Popen(argv, env=env, stdin=subprocess.DEVNULL,
                                 preexec_fn=die_with_parent(), process_group=0)
        commands[what] = (argv, ports)
        for i, (name, _) in enumerate(children):
            if name == what:
                children[i] = (what, child)
                break
        else:
            children.append((what, child))
        for port in ports:
            # ground control listens on --host; the others on 127.0.0.1
            host = reach_host(args.host) if port == args.ground_port else "127.0.0.1"
            _wait_listening(port, child, what, START_DEADLINE_S, stop, host)

    def restart_dead() -> bool:
        """Start again every child that was killed (True), unless one failed or restarted too
        often (False: stop everything)."""
        dead = [(w, c) for w, c in children if c.poll() is not None]
        if not dead:
            return True
        now = time.monotonic()
        for what, child in dead:
            recent = [t for t in restarts.get(what, []) if now - t < RESTART_WINDOW_S]
            if stop.is_set() or not restartable(child.returncode):
                return False
            if len(recent) >= RESTART_BURST:
                print(f"skeye up: {what} exited ({_signal_name(child.returncode or 0)}) after "
                      f"{len(recent)} restarts in {RESTART_WINDOW_S:g} s: not starting it "
                      "again", flush=True)
                return False
            restarts[what] = [*recent, now]
            print(f"skeye up: {what} exited ({_signal_name(child.returncode or 0)}); starting "
                  f"it again (restart {len(recent) + 1} of {RESTART_BURST} in "
                  f"{RESTART_WINDOW_S:g} s)", flush=True)
            argv, ports = commands[what]
            start(what, argv, *ports)
            print(f"skeye up: {what} is back", flush=True)
        return True

    from skeye.processes import ParentWatch, check_ports_free
    from skeye.robots.config import (
        BUILTIN_ROBOTS,
        CAMERA_TYPE,
        load_robot_config,
        robot_folders,
    )

    parent = ParentWatch()
    status = 0
    try:
        # the world, the robot-dirs and the robot, named before anything starts (they were
        # found wrong by the simulator or the pilot, once started)
        folders = robot_folders(tuple(args.robot_dir or ()))
        robot = load_robot_config(args.robot, folders, allow_paths=False)
        check_pilot_can_fly(args.robot, robot)
        # the camera the pilot watches: the robot's first (None: it carries none: no images,
        # no video, and the page says so)
        camera = next((m.name for m in robot.sensors if m.type_name.lower() == CAMERA_TYPE),
                      None)
        check_world(args.world, folders)
        if args.rtp_video and camera is None:
            raise ConfigError(f"--rtp-video sends the camera, and the robot {args.robot} "
                              "carries none")
        if args.calibration not in ("auto", "none") and camera is None:
            raise ConfigError(f"--calibration {args.calibration} is the camera's, and the "
                              f"robot {args.robot} carries none (give auto or none)")
        check_up_rtp_video(args.rtp_video)
        try:  # what ground control, the last child, would refuse
            GroundSecurity(token=token, allowed_hosts=tuple(args.allow_host or ()))
        except ValueError as exc:
            raise ConfigError(f"{exc} (from ${TOKEN_ENV} or --allow-host)") from None
        mavlink = up_mavlink_links(args)  # a bad URI or a taken port: nothing starts
        check_ports_free([
            ("the simulator", "127.0.0.1", args.sim_port, "--sim-port"),
            ("the image server", "127.0.0.1", args.image_port, "--image-port"),
            ("the pilot", "127.0.0.1", args.pilot_port, "--pilot-port"),
            *([("the pilot's video", "127.0.0.1", args.video_port, "--video-port")]
              if camera is not None else []),
            ("ground control", args.host, args.ground_port, "--ground-port"),
            *mavlink_listeners(mavlink),
        ])
        calibration = pilot_calibration(args.calibration, args.robot, folders)
        if stop.is_set():  # Ctrl-C while calibrating: start nothing
            raise StartStopped("stopped while calibrating the camera")
        robot_dirs = [f"--robot-dir={d}" for d in args.robot_dir or ()]
        # the pilot takes one --robot-dir: the folder that holds the robot's file (a built-in
        # needs none)
        builtin = args.robot.lower().removeprefix("usarbot.") in BUILTIN_ROBOTS
        pilot_dir = [] if builtin else [f"--robot-dir={Path(robot.source).parent}"]
        start(
            "simulator",
            _child_argv(
                "sim", "--world", args.world, "--port", str(args.sim_port),
                "--image-port", str(args.image_port), "--seed", str(args.seed), *robot_dirs,
            ),
            args.image_port, args.sim_port,
        )
        start(
            "pilot",
            _child_argv(
                "pilot", "--sim", f"127.0.0.1:{args.sim_port}", "--port", str(args.pilot_port),
                *([] if camera is None else [
                    "--images", f"127.0.0.1:{args.image_port}", f"--camera={camera}",
                    "--video-port", str(args.video_port)]),
                "--robot", args.robot, *pilot_dir,
                *(["--calibration", str(calibration)] if calibration is not None else []),
                *[f"--mavlink={uri}" for uri in mavlink],
                *([f"--rtp-video={args.rtp_video}"] if args.rtp_video else []),
            ),
            args.pilot_port,
        )
        start(
            "ground control",
            _child_argv(
                "ground", "--vehicle", f"tcp://127.0.0.1:{args.pilot_port}",
                *([] if camera is None else ["--video", f"tcp://127.0.0.1:{args.video_port}"]),
                "--port", str(args.ground_port),
                "--host", args.host, "--robot", args.robot, *robot_dirs,
                *[f"--allow-host={h}" for h in args.allow_host or ()],
            ),
            args.ground_port,
        )
        shown = page_host(args.host)  # the URL skeye ground prints
        print(
            f"skeye up: open http://{shown}:{args.ground_port}/?token={token}  "
            f"(simulator {args.sim_port}, "
            f"images {args.image_port}, pilot {args.pilot_port}, "
            f"{'no camera' if camera is None else f'video {args.video_port}'}"
            f"{'; MAVLink ' + ', '.join(mavlink) if mavlink else ''}); "
            "Ctrl-C stops everything",
            flush=True,
        )
        while not sleep_until(stop, 0.5):  # not stop.wait: see sleep_until
            going = parent.stopping()  # `make run` got Ctrl-C or a signal (see ParentWatch)
            if going is not None:
                print(f"skeye up: {going}; stopping", flush=True)
                break
            if not restart_dead() and _report_dead(children, stop):
                status = 1
                break
    except ConfigError as exc:
        if stop.is_set():
            # Ctrl-C or SIGTERM while starting: a stop asked for, status 0 as once started
            # (it was 1, as for a child that failed). A terminal's Ctrl-C also reaches the
            # calibration's simulator (a signal to every process, a child too), whose failure
            # it caused: not said as one.
            said = exc if isinstance(exc, StartStopped) else "stopped while starting"
            print(f"skeye up: {said}", flush=True)
        else:
            print(f"skeye up: {exc}", file=sys.stderr, flush=True)
            # The root cause may be another child: a pilot that cannot reach its simulator is
            # usually looking at one that is exiting. _report_dead gives it time to say so.
            _report_dead(children, stop, exc.what if isinstance(exc, StartFailed) else "")
            status = 1
    finally:
        if stop.is_set() and any(c.poll() is None for _, c in children):
            print("skeye up: stopping (Ctrl-C or SIGTERM again kills what is still running at "
                  "once)", flush=True)
        stop.set()  # from here on (a failed child's stop too) a stop signal kills at once
        _stop_all(children)
        atexit.unregister(_stop_all)
    if killed:
        print(f"skeye up: killed {', '.join(killed)} at a second stop signal", flush=True)
    print("skeye up: stopped", flush=True)
    return status


def check_pilot_can_fly(name: str, robot: RobotConfig) -> None:
    """Refuse a robot the pilot cannot fly: one without a sensor type the pilot reads
    (``skeye.pilot.sim_airframe.SENSORS_READ``; the AirRobot carries no Gyro, Accelerometer,
    Barometer or Battery). The pilot found it once the simulator ran.

    Raises:
        ConfigError: naming the types the robot lacks.
    """
    from skeye.pilot.sim_airframe import SENSORS_READ

    mounted = {m.type_name.lower() for m in robot.sensors}
    missing = [t for t in SENSORS_READ if t.lower() not in mounted]
    if missing:
        raise ConfigError(
            f"--robot {name}: the pilot cannot fly it: it carries no {', '.join(missing)} "
            f"sensor (the pilot reads {', '.join(SENSORS_READ)}; the hummingbird mounts all)")


def check_up_rtp_video(uri: str | None) -> None:
    """``--rtp-video`` checked as the pilot checks it (the URI, a route there, PyAV), before
    anything starts: the pilot found it wrong once the simulator ran.

    Raises:
        ConfigError: naming the option and what is wrong.
    """
    if uri is None:
        return
    from skeye.pilot.rtp_video import check_rtp_destination

    try:
        check_rtp_destination(uri)
    except ConfigError as exc:
        raise ConfigError(f"--rtp-video: {exc}") from None
    try:
        import av  # noqa: F401  (the `mavlink` extra)
    except ImportError:
        raise ConfigError("--rtp-video needs PyAV: pip install 'skeye[mavlink]'") from None


DEFAULT_MAVLINK = ("udpout://127.0.0.1:14550", "udpout://127.0.0.1:14540")
"""``skeye up``'s MAVLink links, as PX4 SITL's: to QGroundControl (14550) and to a MAVSDK or
pymavlink script (14540), each listening there."""


def up_mavlink_links(args: argparse.Namespace) -> list[str]:
    """The pilot's ``--mavlink`` links (``--mavlink`` given: those; ``--no-mavlink``: none),
    checked before anything starts.

    Raises:
        ConfigError: a bad URI or a listening port already taken.
    """
    from skeye.mavlink.transport import check_free

    if args.no_mavlink:
        return []
    try:
        import pymavlink  # noqa: F401  (the `mavlink` extra)
    except ImportError:
        if args.mavlink:
            raise ConfigError("--mavlink needs pymavlink: pip install 'skeye[mavlink]'") from None
        print("skeye up: MAVLink off (pymavlink is not installed: pip install "
              "'skeye[mavlink]')", flush=True)
        return []
    links = list(args.mavlink or DEFAULT_MAVLINK)
    for uri in links:
        check_free(uri)
    return links


def mavlink_listeners(links: list[str]) -> list[tuple[str, str, int, str]]:
    """The pilot's ``tcp://`` MAVLink links, which listen on this machine, as
    :func:`skeye.processes.check_ports_free` takes them: one on a port of the other children's
    (all TCP) would fail in the pilot after the simulator had started."""
    from skeye.mavlink.transport import listening_links

    return [(f"the MAVLink link {uri}", host, port, "--mavlink")
            for scheme, host, port, uri in listening_links(links) if scheme == "tcp"]


def _add_up(sub: Any) -> None:
    p = sub.add_parser(
        "up",
        help="start simulator, pilot and ground control on this machine",
        description="Start skeye sim, skeye pilot and skeye ground; Ctrl-C stops them all.",
    )
    p.add_argument("--world", type=cliargs.path, default="pad",
                   help="world for the simulator (default pad)")
    p.add_argument("--robot", default="hummingbird", help="robot class the pilot flies")
    p.add_argument("--seed", type=cliargs.seed, default=0,
                   help="simulator seed (a whole number >= 0)")
    # Fixed ports 1..65535: skeye up hands each one to the next child, so none may be 0.
    p.add_argument("--sim-port", type=cliargs.fixed_port, default=3000)
    p.add_argument("--image-port", type=cliargs.fixed_port, default=5003)
    p.add_argument("--pilot-port", type=cliargs.fixed_port, default=7000)
    p.add_argument("--video-port", type=cliargs.fixed_port, default=7001,
                   help="the pilot's video port (camera frames with its pad detection)")
    p.add_argument("--ground-port", type=cliargs.fixed_port, default=8080)
    mav = p.add_mutually_exclusive_group()
    mav.add_argument("--mavlink", action="append", default=None, metavar="URI",
                     help="the pilot's MAVLink links (repeatable; default: "
                     + " and ".join(DEFAULT_MAVLINK) + ", as PX4 SITL sends to QGroundControl "
                     "and MAVSDK; docs/protocols/mavlink.md)")
    mav.add_argument("--no-mavlink", action="store_true", help="serve no MAVLink link")
    p.add_argument("--rtp-video", default=None, metavar="udp://HOST:PORT",
                   help="the pilot also sends its camera as H.264 RTP there (QGroundControl: "
                   "udp://127.0.0.1:5600)")
    p.add_argument("--host", default="127.0.0.1", help="address the web page binds")
    p.add_argument("--robot-dir", action="append", default=[], metavar="DIR", type=cliargs.path,
                   help="a folder of robot files for the simulator (and the pilot's envelope), "
                   "as skeye sim --robot-dir; repeatable")
    p.add_argument("--calibration", type=cliargs.path, default="auto", metavar="auto|none|FILE",
                   help="the pilot's camera calibration: auto (default) calibrates a "
                        "distorting simulated camera once and keeps it; a skeye calibrate file; "
                        "none")
    _add_allow_host(p)
    p.set_defaults(func=run_up)


def register(subparsers: Any) -> None:
    """Add ``skeye ground`` and ``skeye up`` to the main parser's sub-commands."""
    _add_ground(subparsers)
    _add_up(subparsers)
