"""``skeye sim --ll-board NAME=LINE``: robots of the simulator served as AscTec LL boards.

Each board is a client of the simulator's own control port (``skeye.control``, over loopback,
as any pilot is): it spawns the robot, wraps it in an :class:`~skeye.hil.ll_board.LLBoard`
and serves it on its line (:mod:`skeye.hil.ll_server`). The spec:

    NAME=pty                       a new pseudo-terminal (its path is printed)
    NAME=tcp:PORT                  a TCP port on the simulator's --host (0 = any free)
    NAME=serial:DEVICE             a real serial port (a USB adapter to an onboard computer)

followed by options, comma-separated: ``robot=CLASS`` (hummingbird), ``start=POSE`` (Pad1),
``baud=N`` (serial, 57600), ``serial_timeout=S`` (the board's serial timeout, 0.5 s),
``rate=R`` (lockstep: the board drives the clock at R sim seconds per wall second, for AscTec
programs, which grant no time; without it the client grants time with CLOCK, as ``skeye
pilot`` does). The start-up line names the ``skeye pilot --airframe`` URI to use.
"""

from __future__ import annotations

import math
import shlex
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass

from skeye.errors import ConfigError, SkeyeError
from skeye.hil.line import open_line
from skeye.hil.ll_board import SERIAL_TIMEOUT_S, LLSettings
from skeye.hil.ll_server import REALTIME_TICK_S, LLBoardServer
from skeye.values import MAX_BAUD, baud_rate

_NAME_CHARS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-")


@dataclass(frozen=True)
class LLBoardSpec:
    """One ``--ll-board`` value, parsed."""

    name: str
    line: str  # pty, tcp or serial
    port: int = 0
    device: str = ""
    baud: int = 57600
    robot: str = "hummingbird"
    start: str = "Pad1"
    serial_timeout_s: float = SERIAL_TIMEOUT_S
    rate: float | None = None  # lockstep: the board drives the clock at this pace


def _up_to(value: str, top: float, refusal: str) -> float:
    """``value`` as a number above 0 and at most ``top``; else ConfigError(refusal, got ...)."""
    try:
        number = float(value)
    except ValueError:
        number = math.nan
    if not (math.isfinite(number) and 0 < number <= top):
        raise ConfigError(f"{refusal}, got {value!r}")
    return number


def parse_ll_board(text: str) -> LLBoardSpec:
    """Parse ``NAME=pty|tcp:PORT|serial:DEVICE[,key=value...]``.

    Raises:
        ConfigError: naming what is wrong.
    """
    name, sep, rest = text.partition("=")
    if not sep or not name or not set(name) <= _NAME_CHARS:
        raise ConfigError(f"--ll-board {text!r}: expected NAME=pty, NAME=tcp:PORT or "
                          "NAME=serial:DEVICE (NAME: letters, digits, _ and -)")
    line, *options = rest.split(",")
    kind, _, where = line.partition(":")
    fields: dict[str, object] = {"name": name, "line": kind}
    if kind == "pty":
        if where:
            raise ConfigError(f"--ll-board {text!r}: pty takes no address (its path is made)")
    elif kind == "tcp":
        try:
            port = int(where)
        except ValueError:
            raise ConfigError(f"--ll-board {text!r}: tcp needs a port, tcp:PORT") from None
        if not 0 <= port <= 65535:
            raise ConfigError(f"--ll-board {text!r}: port {port} is not 0..65535")
        fields["port"] = port
    elif kind == "serial":
        if not where.startswith("/"):
            raise ConfigError(f"--ll-board {text!r}: serial needs a device path, "
                              "serial:/dev/ttyUSB0")
        fields["device"] = where
    else:
        raise ConfigError(f"--ll-board {text!r}: the line must be pty, tcp:PORT or "
                          f"serial:DEVICE, not {line!r}")
    given: dict[str, str] = {}
    for option in options:
        key, sep, value = option.partition("=")
        if not sep or not value:
            raise ConfigError(f"--ll-board {text!r}: option {option!r} is not key=value")
        if key in given:
            raise ConfigError(f"--ll-board {text!r}: option {key!r} is given twice "
                              f"({key}={given[key]}, {key}={value}): give it once")
        given[key] = value
        if key in ("robot", "start"):
            fields[key] = value
        elif key == "baud":
            baud = baud_rate(value)
            if kind != "serial" or baud is None:
                raise ConfigError(f"--ll-board {text!r}: baud={value} is for a serial line, "
                                  f"a whole number 1..{MAX_BAUD}")
            fields["baud"] = baud
        elif key == "rate":
            fields["rate"] = _up_to(value, 1000.0, f"--ll-board {text!r}: rate must be 0..1000 "
                                                   "sim seconds per wall second")
        elif key == "serial_timeout":
            fields["serial_timeout_s"] = _up_to(
                value, 60.0, f"--ll-board {text!r}: serial_timeout must be 0..60 s")
        else:
            raise ConfigError(f"--ll-board {text!r}: unknown option {key!r} (robot, start, "
                              "baud, serial_timeout, rate)")
    return LLBoardSpec(**fields)  # type: ignore[arg-type]


def start_ll_board(stack: ExitStack, spec: LLBoardSpec, control_address: str, *,
                   host: str = "127.0.0.1", timeout_s: float = 10.0,
                   on_error: Callable[[BaseException], None] | None = None) -> LLBoardServer:
    """Spawn ``spec``'s robot through the control port and serve it on its line; the server
    closes with ``stack``. ``on_error`` is called (on the dying thread, so it must not block)
    if one of the board's workers dies on an exception: ``skeye sim`` stops, naming it.

    Raises:
        ConfigError: naming the board: the simulator refused its robot (an unknown class or
            start pose), or its line cannot be opened.
        SkeyeError: the simulator cannot be reached.
    """
    from skeye.control.connection import connect
    from skeye.pilot.sim_airframe import SimAirframe

    sim = stack.enter_context(connect(control_address, timeout_s=timeout_s))
    try:
        robot = sim.spawn(spec.robot, start=spec.start, name=spec.name)
        airframe = SimAirframe(sim, robot)
        line = open_line(spec.line, host=host, port=spec.port, device=spec.device,
                         baud=spec.baud)
    except (SkeyeError, OSError) as exc:  # which board of several: the message says
        raise ConfigError(f"--ll-board {spec.name}: {exc}") from exc
    lockstep = sim.mode == "lockstep"
    limits = airframe.limits
    settings = LLSettings(serial_timeout_s=spec.serial_timeout_s,
                          max_speed_m_s=limits.max_speed_m_s, max_climb_m_s=limits.max_climb_m_s)
    server = LLBoardServer(
        airframe, line, lambda: sim.time_s, name=robot.name, lockstep=lockstep,
        tick_s=airframe.control_period_s if lockstep else REALTIME_TICK_S,
        time_step_s=sim.time_step_s, settings=settings,
        rate=spec.rate if lockstep else None, on_error=on_error,
    )
    stack.enter_context(server)
    server.camera = _camera(sim, spec.robot)
    return server


def _camera(sim: object, robot: str) -> tuple[str, float] | None:
    """The robot's downward camera: (name, horizontal FOV in rad, as the simulator has it)."""
    from skeye.robots.config import load_robot_config

    try:
        mounts = load_robot_config(robot).sensors
    except SkeyeError:
        return None  # a class from --robot-dir: the pilot is told no camera URI
    for mount in mounts:
        if mount.type_name.lower() == "camera":
            try:
                conf = sim.request("GETCONF", ("Type", "Camera"),  # type: ignore[attr-defined]
                                   ("Name", mount.name))
                return mount.name, float(conf.get_float("FOV"))
            except SkeyeError:
                return None
    return None


def describe(server: LLBoardServer, image_port: int | None = None,
             host: str = "127.0.0.1") -> str:
    """The start-up line of one board: where its line is, and the ``skeye pilot`` options
    that fly it (``--camera`` too when the simulator serves images)."""
    uri = server.line.client_uri()
    if server.lockstep and server.rate is None:
        uri += ("&" if "?" in uri else "?") + "lockstep=1"
    camera = ""
    if image_port is not None and server.camera is not None:
        name, fov = server.camera
        camera = " --camera " + shlex.quote(
            f"sim://{host}:{image_port}/{server.name}/{name}?fov_rad={fov!r}")
    # quoted for a shell: unquoted, a serial line's "?baud=57600&lockstep=1" ran the pilot in
    # the background without lockstep, and zsh refuses a "?" that matches no file
    return (f"{server.name} plays an AscTec LL board on {server.line.address} "
            f"(skeye pilot --airframe {shlex.quote(uri)}{camera})")
