"""``skeye link URI COMMAND [args]``: send one command to a vehicle and print what comes back.

For scripts and for checking a real vehicle: every command prints the vehicle's answer (the
RESULT or ack) and exits 0 when it was accepted, 3 when the vehicle refused it (the RESULT's
code is printed), 2 on a bad argument or URI and 1 when the link failed or timed out. The
command's packet (and a poll or stream mask) is built before the link is opened, so a value it
cannot carry is said as typed: the argument or option, in its unit, with the range the
packet carries (``skeye link: error: --yaw-rate-deg-s 5000 deg/s is outside
-1877.47..1877.41 deg/s, what a VELOCITY packet carries``; exit 2), vehicle or none; so is
a value not 0 that rounds to 0 where the packet reads 0 as a word of its own (STREAM's
period 0: stop; a speed's: the default 1 m/s); so is
a mask that requests nothing (``skeye link: error: mask 0 requests no structure; known:
...``), which would bring nothing back.
Telemetry prints one line per frame: the structure's name, then ``field=value`` in wire units.
Output closed early (``skeye link ... stream 60 | head``) ends the command quietly, status 0;
Ctrl-C ends it with ``skeye link: interrupted (Ctrl-C)`` and status 130.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import fields
from enum import IntEnum
from typing import Any, TextIO

from skeye import cliargs
from skeye.errors import CommandRejected, LinkClosed, LinkTimeout, LocalProtocolError, SkeyeError
from skeye.link.transport import open_link, parse_uri
from skeye.link.vehicle import (
    Vehicle,
    goto_gps_command,
    move_by_command,
    pad_mode_command,
    velocity_command,
)
from skeye.wire.packet_units import (
    ZERO_MEANS,
    RoundsToZero,
    si_range,
    take_off_from_si,
    wire_value,
)
from skeye.wire.packets import (
    LAYOUTS,
    Ack,
    GotoGps,
    Hold,
    Land,
    LlStatus,
    Message,
    MoveBy,
    PadMode,
    Poll,
    PollMask,
    Reset,
    Result,
    SkeyeMask,
    Stream,
    TakeOff,
    Velocity,
)

EXIT_OK, EXIT_LINK, EXIT_USAGE, EXIT_REJECTED = 0, 1, 2, 3


def format_message(msg: Message) -> str:
    """One line: the message's class name and its fields in wire units."""
    parts = []
    for f in fields(msg):
        value = getattr(msg, f.name)
        if isinstance(value, IntEnum):
            value = value.name
        parts.append(f"{f.name}={value}")
    return f"{type(msg).__name__} {' '.join(parts)}".rstrip()


def _mask(text: str, names: type[PollMask] | type[SkeyeMask], label: str,
          cls: type[Message], name: str) -> int:
    """A mask from a number (``0x0205``) or names joined by ``,`` (``ll_status,gps_data``),
    checked against ``cls``'s wire field ``name`` (its range, and the bits it carries: STREAM
    carries only known ones, POLL keeps unknown ones) and said as typed, under ``label``.

    Raises:
        LocalProtocolError: an unknown bit name, or a mask the packet cannot carry.
    """
    valid = ", ".join(m.name.lower() for m in names if m.name)
    try:
        total = int(text, 0)
    except ValueError:
        total = 0
        for word in text.split(","):
            word = word.strip().upper()
            if word == "ALL":
                total |= int(sum(names))
                continue
            try:
                total |= int(names[word])
            except KeyError:
                raise LocalProtocolError(
                    f"unknown mask bit {word.lower()!r}; known: {valid}, all"
                ) from None
    field = next(f for f in LAYOUTS[cls].fields if f.name == name)
    lo, hi = field.limits
    if not lo <= total <= hi:
        raise LocalProtocolError(f"{label} {text} is outside {lo}..0x{hi:x}, what a "
                                 f"{_packet_name(cls)} packet carries")
    if field.bits is not None and total & ~field.bits:
        raise LocalProtocolError(f"{label} {text} sets bits (0x{total & ~field.bits:04x}) that "
                                 f"name no structure a {_packet_name(cls)} packet carries; "
                                 f"known: {valid}, all")
    return total


def command_masks(args: argparse.Namespace) -> tuple[int, ...]:
    """The masks of a ``poll`` (one) or ``stream`` (poll and skeye) command, empty for the
    others, built before the link is opened as the command packets are: a mask the packet
    cannot carry, or one that requests nothing, is said as typed (exit 2) without a vehicle.

    Raises:
        LocalProtocolError: an unknown bit name, a mask the packet cannot carry, or nothing
            requested.
    """
    if args.link_command == "poll":
        mask = _mask(args.mask, PollMask, "mask", Poll, "mask")
        if not Poll(mask).requested():  # the vehicle would answer nothing: a timeout
            known = ", ".join(m.name.lower() for m in PollMask if m.name)
            raise LocalProtocolError(f"mask {args.mask} requests no structure; known: {known}, "
                                     "all")
        return (mask,)
    if args.link_command == "stream":
        masks = (_mask(args.poll_mask, PollMask, "--poll-mask", Stream, "poll_mask"),
                 _mask(args.skeye_mask, SkeyeMask, "--skeye-mask", Stream, "skeye_mask"))
        if not any(masks):  # only known bits are carried: none set, nothing would come
            raise LocalProtocolError(f"--poll-mask {args.poll_mask} and --skeye-mask "
                                     f"{args.skeye_mask} request nothing to stream")
        return masks
    return ()


def _answer(answer: Result | Ack, out: TextIO) -> None:
    print(format_message(answer), file=out)


def _same(value: float) -> float:
    return value


def _negated(value: float) -> float:  # up on the command line, down (FRD, NED) on the wire
    return -value


# The values each command puts in its packet, as the user types them: the argument or option,
# its attribute, its unit, the packet and its wire field, and the user's unit -> the field's SI
# unit (its own inverse: a sign, or degrees <-> radians paired below).
_ValueSpec = tuple[str, str, str, type[Message], str, Callable[[float], float]]
_M, _M_S = "m", "m/s"
_VALUES: dict[str, tuple[_ValueSpec, ...]] = {
    "take-off": (("height", "height", _M, TakeOff, "height", _same),),
    "velocity": (("forward", "forward", _M_S, Velocity, "vx", _same),
                 ("right", "right", _M_S, Velocity, "vy", _same),
                 ("up", "up", _M_S, Velocity, "vz", _negated),
                 ("--yaw-rate-deg-s", "yaw_rate_deg_s", "deg/s", Velocity, "yaw_rate",
                  math.radians),
                 ("--duration", "duration", "s", Velocity, "duration", _same)),
    "move-by": (("forward", "forward", _M, MoveBy, "dx", _same),
                ("right", "right", _M, MoveBy, "dy", _same),
                ("up", "up", _M, MoveBy, "dz", _negated),
                ("--yaw-deg", "yaw_deg", "deg", MoveBy, "dyaw", math.radians),
                ("--speed", "speed", _M_S, MoveBy, "speed", _same)),
    "goto-gps": (("latitude", "latitude", "deg", GotoGps, "latitude", _same),
                 ("longitude", "longitude", "deg", GotoGps, "longitude", _same),
                 ("height", "height", _M, GotoGps, "height", _same),
                 ("--speed", "speed", _M_S, GotoGps, "speed", _same)),
    "pad-mode": (("--deadband", "deadband", _M, PadMode, "deadband", _same),
                 ("--max-speed", "max_speed", _M_S, PadMode, "max_speed", _same)),
    "stream": (("--period", "period", "s", Stream, "period", _same),),
}
_INVERSE: dict[Callable[[float], float], Callable[[float], float]] = {
    _same: _same, _negated: _negated, math.radians: math.degrees}


def _packet_name(cls: type[Message]) -> str:
    """The packet's name as the protocol's page writes it (``MoveBy`` -> ``MOVE_BY``)."""
    return re.sub(r"(?<!^)(?=[A-Z])", "_", cls.__name__).upper()


def _one_count_si(cls: type[Message], name: str) -> float:
    """One count of ``cls``'s scaled wire field ``name``, in SI."""
    scale = next(f for f in LAYOUTS[cls].fields if f.name == name).scale
    assert scale is not None  # every field of _VALUES is scaled
    return float(scale.to_si(1))


def check_values(args: argparse.Namespace) -> None:
    """Refuse a command's value that its packet cannot carry, named as the user typed it (the
    argument or option, its value and unit, the range in that unit): not the packet's own
    field names, and ``up`` not as the down velocity the packet carries.

    Raises:
        LocalProtocolError: a value not finite or outside what the packet carries.
    """
    for label, dest, unit, cls, name, to_si in _VALUES.get(args.link_command, ()):
        value = getattr(args, dest)
        if not math.isfinite(value):
            raise LocalProtocolError(f"{label} must be a finite number ({unit}), got {value}")
        try:
            wire_value(cls, name, to_si(value))
        except RoundsToZero:
            # --period 0.0004 was sent as 0 ms, "stop": 0 frames, exit 0; --speed 0.0004 as
            # 0 mm/s, flown at 1 m/s
            step = abs(_INVERSE[to_si](_one_count_si(cls, name)))
            raise LocalProtocolError(
                f"{label} {value:g} {unit} is 0 in the {_packet_name(cls)} packet, which "
                f"carries it in steps of {step:g} {unit}, and 0 there means "
                f"{ZERO_MEANS[(cls, name)]}: give at least {step:g} {unit}") from None
        except LocalProtocolError:
            a, b = sorted(_INVERSE[to_si](v) for v in si_range(cls, name))
            raise LocalProtocolError(
                f"{label} {value:g} {unit} is outside {a:g}..{b:g} {unit}, what a "
                f"{_packet_name(cls)} packet carries") from None


def command_message(args: argparse.Namespace) -> Message | None:
    """The command packet of a ``skeye link`` command (None for poll and stream), built before
    the link is opened, so that a value the packet cannot carry is said (in SI, exit 2) without
    a vehicle.

    Raises:
        LocalProtocolError: a value the packet cannot carry.
    """
    check_values(args)
    cmd = args.link_command
    if cmd == "take-off":
        return take_off_from_si(args.height)
    if cmd in ("land", "hold", "reset"):
        return {"land": Land, "hold": Hold, "reset": Reset}[cmd]()
    if cmd == "velocity":
        return velocity_command(args.forward, args.right, args.up,
                                math.radians(args.yaw_rate_deg_s), args.duration)
    if cmd == "move-by":
        return move_by_command(args.forward, args.right, args.up, math.radians(args.yaw_deg),
                               args.frame, args.speed)
    if cmd == "goto-gps":
        return goto_gps_command(args.latitude, args.longitude, args.height, args.speed)
    if cmd == "pad-mode":
        return pad_mode_command(args.mode, args.deadband, args.max_speed)
    return None


def run(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """Execute the parsed ``skeye link`` command; returns the exit code."""
    opened: list[Vehicle] = []  # the vehicle, once its link is open (for what a failure says)
    try:
        masks = command_masks(args)  # a bad mask is named before the link is opened
        msg = command_message(args)
        # --timeout bounds the connection too: it was 5 s whatever was given (--timeout 1
        # waited 5 s for a host that does not answer; --timeout 30 gave up at 5 s)
        with Vehicle(open_link(args.uri, args.timeout), timeout_s=args.timeout) as vehicle:
            opened.append(vehicle)
            return _run(vehicle, args, msg, masks, out)
    except CommandRejected as exc:
        print(f"skeye link: rejected: {exc.reason} (code {exc.code})", file=sys.stderr)
        return EXIT_REJECTED
    except LocalProtocolError as exc:
        print(f"skeye link: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (LinkClosed, LinkTimeout) as exc:
        unheard = opened[0].unheard if opened else None
        hint = f"; {unheard}: {_unheard_hint(args.uri, opened[0])}" if unheard else ""
        print(f"skeye link: link error: {exc}{hint}", file=sys.stderr)
        return EXIT_LINK
    except SkeyeError as exc:
        print(f"skeye link: error: {exc}", file=sys.stderr)
        return EXIT_LINK


def _unheard_hint(uri: str, vehicle: Vehicle) -> str:
    """What to check when no whole frame came on ``uri``: a TCP port may be another program's
    (a simulator's, ground control's); a serial line may have no pilot on it, or run at
    another baud rate, whose bytes read as garbage. (A serial line was asked whether it was
    "a skeye pilot's link (skeye pilot --port)", the TCP port, and a baud rate unlike the
    pilot's went unnamed.)"""
    scheme, where, number = parse_uri(uri)  # it opened: the URI parses
    if scheme == "tcp":
        return (f"is {uri} a skeye pilot's link (skeye pilot --port)? A simulator's or ground "
                "control's port speaks another protocol")
    garbage, bad = vehicle.line_errors
    said = (f"is a skeye pilot on the other end of {where} at {number} baud (skeye pilot "
            f"--serial DEVICE --baud {number})? ")
    if garbage or bad:
        return said + ("Unreadable bytes are what a line read at another baud rate than its "
                       "sender's gives: try the pilot's --baud")
    return said + "Nothing at all came: check the cable and that the pilot runs"


def _run(vehicle: Vehicle, args: argparse.Namespace, msg: Message | None,
         masks: tuple[int, ...], out: TextIO) -> int:
    cmd = args.link_command
    if cmd == "poll":
        for polled in vehicle.poll(masks[0]).values():
            print(format_message(polled), file=out)
        return EXIT_OK
    if cmd == "stream":
        return _stream(vehicle, args, masks[0], masks[1], out)
    if msg is None:  # argparse only lets known commands through
        raise LocalProtocolError(f"unknown command {cmd!r}")
    _answer(vehicle.command(msg), out)
    return EXIT_OK


def _stream(vehicle: Vehicle, args: argparse.Namespace, poll_mask: int, skeye_mask: int,
            out: TextIO) -> int:
    lock = threading.Lock()
    count = [0]
    closed = threading.Event()  # the output was closed (a broken pipe): stop streaming

    # The link's keepalive polls LL_STATUS every 0.5 s the command sends nothing: its answers
    # are no frames of this stream unless --poll-mask asked for LL_STATUS (they were printed
    # and counted among the stream's, two a second, with --poll-mask none)
    keepalive_only = not poll_mask & PollMask.LL_STATUS

    # Frames that come before the STREAM's answer is printed wait for it: the link's thread
    # printed the first ones while the main thread was about to print the answer, so the
    # answer came after them about one run in two.
    early: list[Message] = []
    answered = threading.Event()

    def emit(msg: Message) -> None:  # with lock held
        try:
            print(format_message(msg), file=out, flush=True)
        except BrokenPipeError:
            closed.set()  # said once, in the main thread; not raised in the link's thread

    def show(msg: Message) -> None:
        if isinstance(msg, Result) or closed.is_set():
            return
        if keepalive_only and isinstance(msg, LlStatus):
            return
        with lock:
            count[0] += 1
            if answered.is_set():
                emit(msg)
            else:
                early.append(msg)

    vehicle.add_callback(show)
    answer = vehicle.stream(poll_mask, skeye_mask, args.period)
    with lock:
        _answer(answer, out)
        for msg in early:
            emit(msg)
        answered.set()
    start = time.monotonic()
    deadline = start + args.seconds
    while time.monotonic() < deadline and vehicle.connected and not closed.is_set():
        time.sleep(min(0.05, max(0.0, deadline - time.monotonic())))
    vehicle.remove_callback(show)
    if vehicle.link.closed and not closed.is_set():  # said as such, not "link is closed"
        raise LinkClosed(f"{vehicle.link.name}: the vehicle closed the link after "
                         f"{time.monotonic() - start:.1f} of {args.seconds:g} s, {count[0]} "
                         "frames")
    vehicle.stream(0, 0, 0.0)
    if closed.is_set():  # skeye's main() ends the command quietly
        raise BrokenPipeError("the output was closed")
    print(f"# {count[0]} frames in {args.seconds:g} s", file=out)
    return EXIT_OK


def register(subparsers: Any) -> None:
    """Add ``skeye link URI COMMAND [args]`` to the main parser's subcommands."""
    p = subparsers.add_parser(
        "link",
        help="send one command to a vehicle (pilot or real) and print the answer",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("uri", help="tcp://host:port or serial:///dev/ttyUSB0?baud=57600")
    p.add_argument("--timeout", type=cliargs.positive_float, default=5.0,
                   help="seconds to wait for the connection and for the answer")
    sub = p.add_subparsers(dest="link_command", required=True, metavar="COMMAND")
    c = sub.add_parser("take-off", help="start motors and climb")
    c.add_argument("height", type=float, help="metres above the take-off point")
    sub.add_parser("land", help="descend and stop motors")
    sub.add_parser("hold", help="stop and hover here")
    sub.add_parser("reset", help="bring a crashed vehicle back at home (respawn in the simulator)")
    c = sub.add_parser("velocity", help="fly at body-frame velocities")
    c.add_argument("forward", type=float, help="m/s")
    c.add_argument("right", type=float, help="m/s")
    c.add_argument("up", type=float, help="m/s")
    c.add_argument("--yaw-rate-deg-s", type=float, default=0.0)
    c.add_argument("--duration", type=float, default=0.0, help="seconds (0 = until replaced)")
    c = sub.add_parser("move-by", help="move relative to the current position")
    c.add_argument("forward", type=float, help="m (north with --frame world)")
    c.add_argument("right", type=float, help="m (east with --frame world)")
    c.add_argument("up", type=float, help="m")
    c.add_argument("--yaw-deg", type=float, default=0.0)
    c.add_argument("--frame", choices=("body", "world"), default="body")
    c.add_argument("--speed", type=float, default=1.0, help="m/s")
    c = sub.add_parser("goto-gps", help="fly to GPS coordinates")
    c.add_argument("latitude", type=float, help="degrees")
    c.add_argument("longitude", type=float, help="degrees")
    c.add_argument("height", type=float, help="metres above home")
    c.add_argument("--speed", type=float, default=1.0, help="m/s")
    c = sub.add_parser("pad-mode", help="landing-pad mode")
    c.add_argument("mode", choices=("off", "hold", "land"))
    c.add_argument("--deadband", type=float, default=0.1, help="m")
    c.add_argument("--max-speed", type=float, default=0.5, help="m/s")
    c = sub.add_parser("poll", help="poll structures once and print them")
    c.add_argument(
        "mask",
        nargs="?",
        default="ll_status",
        help="0x... or names: ll_status,imu_calcdata,... all",
    )
    c = sub.add_parser("stream", help="stream telemetry for N seconds and print it")
    c.add_argument("seconds", type=cliargs.positive_float, help="how long to stream (s, > 0)")
    c.add_argument("--period", type=cliargs.positive_float, default=0.1,
                   help="seconds between pushes")
    c.add_argument("--poll-mask", default="0", help="structures (0x... or names)")
    c.add_argument("--skeye-mask", default="nav_status", help="nav_status,pad,truth (or 0x...)")
    p.set_defaults(func=run)
