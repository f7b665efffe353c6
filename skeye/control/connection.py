"""The connection to a simulator: its link, its two threads, and request/answer matching.

How this works (user's view: docs/control.md):

- The byte link comes from :func:`skeye.link.transport.open_link` (``tcp://host:port``).
- A **message-handler** thread alone reads the link. It feeds the bytes to the shared sans-IO
  codec (:class:`skeye.wire.sim_lines.LineDecoder`) and dispatches each message: ``SEN`` to its
  sensor object, ``STA`` to the robot's status, answers (``RES``, ``ERR``, ``CONF``, ``GEO``,
  ``NFO {StartPoses}``) to the oldest pending request they answer. An ``ERR`` nobody waits for
  (a refused ``DRIVE``, a physics stop) goes to the robot, whose motion then fails with it.
- A **command-handler** thread alone writes the link, draining one bounded multi-producer
  queue of whole lines, so bytes of two commands never interleave. A full queue blocks the
  producer up to its timeout, then raises :class:`~skeye.errors.LinkTimeout`.
- Every wait has a deadline. When the link dies (EOF, a socket error, a protocol violation) the
  reader records the error and wakes every waiter (pending requests, sensor waits, motion waits)
  with it, so a caller gets a clear :class:`LinkClosed` instead of hanging.

Invariants: a request is registered before its line is queued (its answer cannot be missed);
answers to one connection come in request order (the server handles a connection's commands
one at a time), so "the oldest pending request this message answers" is the right match.
:meth:`Connection.close` is idempotent and joins every thread it started.
"""

from __future__ import annotations

import ipaddress
import logging
import numbers
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from skeye.control.image_client import ImageClient
from skeye.errors import (
    CommandRejected,
    InvalidArgument,
    LinkClosed,
    LinkTimeout,
    LocalProtocolError,
    PeerClosed,
    RemoteProtocolError,
    SkeyeError,
)
from skeye.link.transport import Link, open_link, tcp_uri
from skeye.values import is_finite_number
from skeye.wire.sim import decode, encode, fields_of, res_time_s
from skeye.wire.sim_lines import LineDecoder, LineError, Message, format_message
from skeye.wire.sim_messages import GetConf, GetStartPoses, Init, Ping, Set, Step
from skeye.workers import Worker

from .clock import MAX_RUN_FOR_S, Clock, LockstepClock, RealtimeClock, period_steps
from .motion import MotionConfig
from .robots import Robot, robot_class

log = logging.getLogger(__name__)

DEFAULT_PORT = 3000
DEFAULT_IMAGE_PORT = 5003
SYNC_STEP_TIMEOUT_S = 3600.0
"""How long a ``STEP {Sync true}`` waits for its answer: the other members' steps come first (the
simulator's own limit for a STEP to be taken up, skeye.sim.session.STEP_TIMEOUT_S)."""
LOCKSTEP_IMAGE_TIMEOUT_S = 70.0
"""In lockstep, how long an image request may wait for its answer (at least): the frame may
wait for its render, which the simulator gives up on after 60 s (skeye.sim.render.
RENDER_TIMEOUT_S) and then answers with an error. The connection's own ``timeout_s`` (10 s by
default) is too short for a loaded machine's first render (a renderer's first frame took 5.3 s
at load 13.5 on 2 cores, 2026-11-28): the request failed, the pilot's vision saw "pad not seen"
for that frame, and the lockstep flight went on differently; the simulator is paused meanwhile,
so waiting changes nothing but the wall time."""
_STOP = b""
_RECV_WAIT_S = 1.0  # the reader's longest wait in one recv (a closed link wakes it at once)


@dataclass(frozen=True)
class Pose:
    """A start pose: NED position (m) and roll, pitch, yaw (rad)."""

    position_ned_m: tuple[float, float, float]
    rpy_rad: tuple[float, float, float]


def parse_address(address: str, default_port: int = DEFAULT_PORT,
                  what: str = "simulator address") -> tuple[str, int]:
    """``host:port``, ``tcp://host:port`` or ``host`` -> (host, port).

    ``what`` names the address in the error (``"image server address"`` for ``images=``).

    Raises:
        LocalProtocolError: an empty host, a port that is not a number in 1..65535, or a
            scheme other than tcp.
    """
    if not isinstance(address, str):
        raise LocalProtocolError(f"{what} must be a string 'host:port', got {address!r}")
    text = address.strip()
    if "://" in text:
        scheme, text = text.split("://", 1)
        if scheme.lower() != "tcp":
            raise LocalProtocolError(f"{what} {address!r}: only tcp:// is supported")
    text = text.rstrip("/")
    if text.startswith("["):  # [::1]:3000
        host, _, rest = text[1:].partition("]")
        port_text = rest.lstrip(":") or str(default_port)
    elif text.count(":") == 1:
        host, port_text = text.split(":")
    else:
        host, port_text = text, str(default_port)
    if not host:
        raise LocalProtocolError(f"{what} {address!r} has no host")
    if ":" in host:  # bare or bracketed: only an IPv6 address has colons
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            raise LocalProtocolError(
                f"{what} {address!r}: {host!r} is no IPv6 address; give host:port, or an "
                "IPv6 address in brackets, [::1]:5003") from None
    if not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise LocalProtocolError(f"{what} {address!r}: bad port {port_text!r} (1..65535)")
    return host, int(port_text)


def _check_timeout(timeout_s: Any) -> float:
    """``timeout_s`` as a float, or LocalProtocolError: a wait must be finite and > 0."""
    if not (is_finite_number(timeout_s) and timeout_s > 0):
        raise LocalProtocolError(f"timeout_s must be a finite number > 0, got {timeout_s!r}")
    return float(timeout_s)


class _Pending:
    """One request waiting for its answer."""

    def __init__(self, command: str, answer_types: frozenset[str], ident: str | None) -> None:
        self.command = command
        self.answer_types = answer_types
        self.ident = ident
        self.event = threading.Event()
        self.answer: Message | None = None
        self.error: SkeyeError | None = None

    def matches(self, msg: Message) -> bool:
        if msg.type in ("RES", "ERR"):
            if (msg.get("Command") or "").upper() != self.command:
                return False
            if msg.type == "RES" and "RES" not in self.answer_types:
                return False
            return self.ident is None or msg.get("Id") == self.ident or msg.type == "ERR"
        if msg.type not in self.answer_types:
            return False
        if msg.type == "NFO":
            return msg.has("StartPoses")
        return True


_ANSWERS: dict[str, frozenset[str]] = {
    "GETSTARTPOSES": frozenset({"NFO"}),
    "GETCONF": frozenset({"CONF"}),
    "GETGEO": frozenset({"GEO"}),
}


class Connection:
    """One connection to the simulator's control port; a context manager.

    Use :func:`connect` to make one. As in USARSim, a connection drives at most one robot.

    Args:
        address: ``host:port`` of the control server.
        images: ``host:port`` of the image server, for :meth:`CameraSensor.image`.
        timeout_s: deadline for connecting, for each answer and each wait of the link.
        queue_size: lines the command queue holds before producers block.
        motion: motion-control defaults for robots spawned on this connection.
    """

    def __init__(
        self,
        address: str = f"127.0.0.1:{DEFAULT_PORT}",
        *,
        images: str | None = None,
        timeout_s: float = 10.0,
        queue_size: int = 256,
        motion: MotionConfig | None = None,
        sync_clock: bool = False,
    ) -> None:
        _check_timeout(timeout_s)
        if queue_size < 1:
            raise LocalProtocolError(f"queue_size must be >= 1, got {queue_size}")
        self.host, self.port = parse_address(address)
        self.images_address = (
            None if images is None
            else parse_address(images, DEFAULT_IMAGE_PORT, "image server address")
        )
        self.timeout_s = timeout_s
        self.motion_config = motion or MotionConfig()
        self.sync_clock = sync_clock
        """Lockstep: step in the simulator's clock barrier (``STEP {Sync true}``), in step
        with the other clients that do (one per robot, as ``skeye pilot --lockstep-sync``);
        needs a robot, and each such connection stepped from a thread of its own: a STEP
        waits for every other member's (up to ``SYNC_STEP_TIMEOUT_S``)."""
        self.mode = ""
        self.time_step_s = 0.0
        self.level = ""
        self.time_s = 0.0
        self.silent_s = 0.0
        """How long the reader has waited, without a byte from the simulator, since the last
        bytes arrived: counted only while it waits in ``recv``, each wait at most its length
        (1 s), so a pause of this process (a busy machine) outside ``recv`` is never taken for a
        silent simulator, and one inside it counts at most 1 s."""
        self.unmatched_errors: list[Message] = []
        self.close_unanswered: str | None = None
        """Set by :meth:`close` when the simulator did not close its end in time."""
        self.robot: Robot | None = None
        self._error: SkeyeError | None = None
        self._closed = False
        self._lock = threading.Lock()
        self._pending: list[_Pending] = []
        self._ping_ids = 0
        self._outbox: queue.Queue[bytes] = queue.Queue(queue_size)
        self._nfo = threading.Event()
        self._close_hooks: list[Callable[[SkeyeError], None]] = []
        try:  # no send deadline: a full command queue is what times out (see ``send``)
            self._link: Link = open_link(tcp_uri(self.host, self.port), timeout_s,
                                         send_timeout_s=None)
        except LinkTimeout as exc:
            raise LinkTimeout(f"simulator {self.peer}: no connection in {timeout_s:g} s") from exc
        except LinkClosed as exc:
            raise LinkClosed(f"cannot connect to the simulator at {self.peer}: {exc}") from exc
        self._reader = Worker(self._read_loop, "skeye-control-read", on_error=self._worker_failed)
        self._writer = Worker(self._write_loop, "skeye-control-write",
                              on_error=self._worker_failed)
        self._reader.start()
        self._writer.start()
        self.clock: Clock
        try:
            if not self._nfo.wait(timeout_s):
                raise LinkTimeout(f"simulator {self.peer}: no NFO greeting in {timeout_s:g} s")
            self.check()
            try:  # the sim time now: a late joiner does not read 0 until a reading comes
                self.ping()
            except LinkTimeout:
                raise LinkTimeout(f"simulator {self.peer}: no answer in {timeout_s:g} s to the "
                                  "PING connect() sends to learn the sim time") from None
            steps = period_steps(self.motion_config.control_rate_hz, self.time_step_s)
            if self.mode == "lockstep":
                self.clock = LockstepClock(self._tick, self._get_error, self._step,
                                           self.time_step_s, steps)
            else:
                self.clock = RealtimeClock(self._tick, self._get_error,
                                           steps * self.time_step_s)
        except BaseException:
            self.close()
            raise

    # -- context manager ----------------------------------------------------------------
    def __enter__(self) -> Connection:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<Connection {self.peer} {self.mode} t={self.time_s:.3f}s>"

    @property
    def peer(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def error(self) -> SkeyeError | None:
        """Why the link is down, or None while it is up."""
        return self._error

    def _get_error(self) -> SkeyeError | None:
        return self._error

    def check(self) -> None:
        """Raise the link's error if it is down (LinkClosed, RemoteProtocolError...)."""
        if self._error is not None:
            raise self._error

    # -- writing ------------------------------------------------------------------------
    def send(self, type_word: str, *fields: tuple[str, object], timeout_s: float | None = None
             ) -> None:
        """Queue one command line for the command-handler thread (no answer expected).

        Raises:
            LocalProtocolError: the command cannot be formatted.
            LinkTimeout: the queue stayed full for ``timeout_s``.
            LinkClosed: the link is down.
        """
        self._put(format_message(type_word, *fields), timeout_s)

    def send_message(self, message: Any, timeout_s: float | None = None) -> None:
        """:meth:`send` of a typed message (:mod:`skeye.wire.sim_messages`, e.g. ``Drive``)."""
        self._put(encode(message), timeout_s)

    def request_message(self, message: Any, timeout_s: float | None = None) -> Any:
        """:meth:`request` of a typed message; returns the typed answer (:mod:`skeye.wire.sim`).

        Raises:
            RemoteProtocolError: the answer breaks the protocol; else as :meth:`request`.
        """
        return decode(self.request(type(message).WORD, *fields_of(message), timeout_s=timeout_s))

    def _put(self, line: bytes, timeout_s: float | None) -> None:
        self.check()
        wait_s = self.timeout_s if timeout_s is None else _check_timeout(timeout_s)
        try:
            self._outbox.put(line, timeout=wait_s)
        except queue.Full:
            raise LinkTimeout(
                f"simulator {self.peer}: command queue full for {wait_s:g} s "
                "(the simulator is not reading)"
            ) from None
        self.check()

    def request(
        self, type_word: str, *fields: tuple[str, object], timeout_s: float | None = None
    ) -> Message:
        """Send a command and wait for its answer (``RES``, ``CONF``, ``GEO`` or ``NFO``).

        Raises:
            CommandRejected: the simulator answered ``ERR``; ``reason`` says why.
            LocalProtocolError: ``timeout_s`` is not a finite number > 0.
            LinkTimeout: no answer within ``timeout_s`` (default: the connection's).
            LinkClosed: the link died while waiting.
        """
        wait_s = self.timeout_s if timeout_s is None else _check_timeout(timeout_s)
        command = type_word.upper()
        ident = None
        if command == "PING":
            # The simulator reads a key's first block (as USARSim's GetArgVal), so match that.
            ident = next((str(v) for k, v in fields if str(k).lower() == "id"), None)
        pending = _Pending(command, _ANSWERS.get(command, frozenset({"RES"})), ident)
        line = format_message(type_word, *fields)
        with self._lock:
            self.check()
            self._pending.append(pending)
        try:
            self._put(line, wait_s)
            if not pending.event.wait(wait_s):
                raise LinkTimeout(f"simulator {self.peer}: no answer to {command} in {wait_s:g} s")
        finally:
            with self._lock:
                if pending in self._pending:
                    self._pending.remove(pending)
        if pending.error is not None:
            raise pending.error
        assert pending.answer is not None
        if pending.answer.type == "ERR":
            reason = pending.answer.get("Reason") or "no reason given"
            raise CommandRejected(f"{command}: {reason}")
        return pending.answer

    def _write_loop(self) -> None:
        try:
            while True:
                line = self._outbox.get()
                if line is _STOP or not line:
                    return
                chunks = [line]
                try:  # batch what is already queued: fewer syscalls, same byte order
                    while len(chunks) < 64:
                        more = self._outbox.get_nowait()
                        if not more:
                            self._link.send(b"".join(chunks))
                            return
                        chunks.append(more)
                except queue.Empty:
                    pass
                self._link.send(b"".join(chunks))
        except SkeyeError as exc:  # LinkClosed, LinkTimeout
            self._fail(LinkClosed(f"simulator {self.peer}: sending failed: {exc}"))

    def _worker_failed(self, exc: BaseException) -> None:
        """A link thread died of a bug: every waiter hears of it (the worker logged it)."""
        self._fail(SkeyeError(f"a connection thread failed: {exc!r}"))

    # -- reading ------------------------------------------------------------------------
    def _read_loop(self) -> None:
        decoder = LineDecoder()
        error: SkeyeError
        try:
            while True:
                waited_from = time.monotonic()
                try:
                    data = self._link.recv(_RECV_WAIT_S)
                except PeerClosed:
                    error = LinkClosed(
                        f"the simulator at {self.peer} closed the connection "
                        f"(last sim time {self.time_s:.3f} s)"
                    )
                    break
                except LinkClosed as exc:
                    error = LinkClosed(f"simulator {self.peer}: connection lost: {exc}")
                    break
                if not data:  # one wait counts at most its own length: a pause of this
                    # process inside recv (a simulator in the same process pauses too) is not
                    # all silence
                    self.silent_s += min(time.monotonic() - waited_from, _RECV_WAIT_S)
                    continue
                self.silent_s = 0.0
                for event in decoder.feed(data):
                    if isinstance(event, LineError):
                        log.warning("simulator %s sent a bad line: %s: %r", self.peer,
                                    event.reason, event.line)
                        if event.fatal:
                            raise RemoteProtocolError(f"simulator {self.peer}: {event.reason}")
                        continue
                    self._dispatch(event)
        except SkeyeError as exc:
            error = exc
        except Exception as exc:  # a bug must not leave waiters hanging
            log.exception("message handler failed")
            error = SkeyeError(f"the message handler failed: {exc!r}")
        if self._closed:
            error = LinkClosed(f"the connection to {self.peer} was closed")
        self._fail(error)

    def _note_time(self, msg: Message) -> None:
        text = msg.get("Time")
        if text is not None:
            try:
                t = float(text)
            except ValueError:
                return
            if t > self.time_s:
                self.time_s = t

    def _dispatch(self, msg: Message) -> None:
        kind = msg.type
        if kind == "SEN":
            self._note_time(msg)
            robot = self.robot
            if robot is not None:
                robot.on_sensor(msg)
            return
        if kind == "STA":
            self._note_time(msg)
            if self.robot is not None:
                self.robot.on_status(msg)
            return
        if kind == "NFO" and msg.has("Mode") and not self._nfo.is_set():
            nfo = decode(msg)
            self.mode = (nfo.mode or "realtime").lower()
            self.time_step_s = 0.001 if nfo.time_step_s is None else nfo.time_step_s
            self.level = nfo.level or ""
            self._nfo.set()
            return
        if kind == "RES":
            self._note_time(msg)
        with self._lock:
            match = next((p for p in self._pending if p.matches(msg)), None)
            if match is not None:
                self._pending.remove(match)
        if match is not None:
            match.answer = msg
            match.event.set()
            return
        if kind == "ERR" and msg.get("Command") == "ENGINE":  # the simulator is stopping
            self._fail(LinkClosed(f"simulator {self.peer}: its engine failed: "
                                  f"{msg.get('Reason') or 'no reason given'}"))
            return
        if kind == "ERR":
            self.unmatched_errors.append(msg)
            del self.unmatched_errors[:-100]
            log.warning("simulator %s: %s refused: %s", self.peer, msg.get("Command"),
                        msg.get("Reason"))
            if self.robot is not None:
                self.robot.on_error(msg)

    def _fail(self, error: SkeyeError) -> None:
        """The link is down: record why and wake every waiter with it."""
        with self._lock:
            if self._error is None:
                self._error = error
            error = self._error
            pending, self._pending = self._pending, []
            hooks = list(self._close_hooks)
        for p in pending:
            p.error = error
            p.event.set()
        self._nfo.set()
        robot = self.robot
        if robot is not None:
            robot.link_down(error)
        for hook in hooks:
            try:
                hook(error)
            except Exception:
                log.exception("close hook failed")
        try:  # let the writer finish; if the queue is full it exits on its send error
            self._outbox.put_nowait(_STOP)
        except queue.Full:
            pass
        self._link.close()  # wakes the reader; the writer's next send fails

    # -- world commands -------------------------------------------------------------------
    def start_poses(self) -> dict[str, Pose]:
        """The world's start poses: name -> :class:`Pose`."""
        answer = self.request_message(GetStartPoses())
        return {name: Pose(location, rotation) for name, location, rotation in answer.poses}

    def ping(self) -> float:
        """Round trip to the simulator; returns its sim time."""
        with self._lock:
            self._ping_ids += 1
            ident = f"p{self._ping_ids}"
        return res_time_s(self.request_message(Ping(ident)))

    def set_wind(self, mode: str, params: str = "") -> None:
        """``SET {Type Wind}``: none, constant, turbulence or random_force (see the sim docs)."""
        self.request_message(Set("Wind", mode=mode, params=params or None))

    def _step(self, count: int) -> float:
        timeout_s = max(self.timeout_s, count * self.time_step_s * 20)
        if self.sync_clock:  # the other members' steps come first, however long they take
            timeout_s = max(timeout_s, SYNC_STEP_TIMEOUT_S)
        answer = self.request_message(Step(count, sync=True if self.sync_clock else None),
                                      timeout_s=timeout_s)
        t = res_time_s(answer)
        self.time_s = max(self.time_s, t)
        return t

    def step(self, count: int = 1) -> float:
        """Lockstep: advance ``count`` physics steps (motion control keeps running); sim time.

        Raises:
            InvalidArgument: ``count`` is not a whole number from 1 to a day of sim time.
        """
        if self.mode != "lockstep":
            raise LocalProtocolError("step() needs a simulator in lockstep mode")
        most = round(MAX_RUN_FOR_S / self.time_step_s)  # run_for's bound, in steps
        if (isinstance(count, bool) or not isinstance(count, numbers.Integral)
                or not 1 <= count <= most):
            raise InvalidArgument(f"step count must be an integer 1..{most} (a day of sim "
                                  f"time), got {count!r}")
        assert isinstance(self.clock, LockstepClock)
        self.clock.advance_steps(count)
        return self.time_s

    def run_for(self, seconds: float) -> float:
        """Let ``seconds`` of sim time pass (lockstep: step; realtime: wait); the sim time.

        Raises:
            InvalidArgument: ``seconds`` is not a finite number 0..``MAX_RUN_FOR_S`` (a day).
        """
        if not (is_finite_number(seconds) and 0 <= seconds <= MAX_RUN_FOR_S):
            raise InvalidArgument(f"run_for: seconds must be a finite number 0..{MAX_RUN_FOR_S:g} "
                                  f"(a day of sim time at most; make several calls for more), "
                                  f"got {seconds!r}")
        self.clock.advance(seconds)
        return self.time_s

    def _tick(self) -> None:
        robot = self.robot
        if robot is not None:
            robot.control_tick()

    # -- robots ---------------------------------------------------------------------------
    def spawn(
        self,
        robot: type[Robot] | str = "hummingbird",
        *,
        start: str | None = None,
        location_ned_m: tuple[float, float, float] | None = None,
        rotation_rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0),
        name: str = "R1",
        feedback: str = "ins",
        motion: MotionConfig | None = None,
        wait: bool = True,
    ) -> Robot:
        """Spawn a robot at a start pose or a NED location; returns it once it streams
        (``wait``; else once the simulator has answered, which in lockstep is before its first
        step: the caller steps, as to catch the frame of its spawn state).

        Args:
            robot: a robot class (:class:`~skeye.control.robots.Hummingbird`) or class name.
            start: a start pose name (see :meth:`start_poses`).
            location_ned_m: or a NED position (m); ``rotation_rpy_rad`` its attitude.
            name: the robot's name in the simulator.
            feedback: default navigation feedback, ``"ins"`` or ``"ground_truth"``.
            motion: motion-control settings (default: the connection's).

        Raises:
            LocalProtocolError: this connection already has a robot, or bad arguments.
            CommandRejected: the simulator refused (unknown class or start pose...).
        """
        if self.robot is not None:
            raise LocalProtocolError(
                f"this connection already drives {self.robot.name} (one robot per connection)"
            )
        if (start is None) == (location_ned_m is None):
            raise LocalProtocolError("spawn needs exactly one of start= or location_ned_m=")
        cls: type[Robot] = robot_class(robot) if isinstance(robot, str) else robot
        if start is not None:
            init = Init(cls.class_name, name, start=start)
            home: tuple[float, float, float] | None = None
        else:
            assert location_ned_m is not None
            home = tuple(float(v) for v in location_ned_m)  # type: ignore[assignment]
            rr, rp, ry = (float(v) for v in rotation_rpy_rad)
            init = Init(cls.class_name, name, location_ned_m=home, rotation_rpy_rad=(rr, rp, ry))
        if start is not None:
            poses = self.start_poses()
            pose = next((p for n, p in poses.items() if n.lower() == start.lower()), None)
            if pose is None:
                raise LocalProtocolError(
                    f"no start pose {start!r}; the world has: {', '.join(poses) or 'none'}"
                )
            home = pose.position_ned_m
        assert home is not None
        new = cls(self, name, home, feedback=feedback, motion=motion or self.motion_config)
        self.robot = new
        try:
            answer = self.request_message(init)
            new.name = answer.name or name
            new.configure(self.request_message(GetConf("Robot")))
            if wait:
                new.await_first_readings()
        except BaseException:
            self.robot = None
            raise
        return new

    # -- images ---------------------------------------------------------------------------
    def image_client(self) -> ImageClient:
        """A new client of the simulator's image server (``images=`` given to connect); its
        answer deadline is ``timeout_s``, and in lockstep at least
        :data:`LOCKSTEP_IMAGE_TIMEOUT_S`."""
        if self.images_address is None:
            raise LocalProtocolError("connect with images='host:port' to fetch camera frames")
        host, port = self.images_address
        timeout_s = self.timeout_s
        if self.mode == "lockstep":  # a frame may wait for its render: the simulator's limit
            timeout_s = max(timeout_s, LOCKSTEP_IMAGE_TIMEOUT_S)
        return ImageClient(host, port, timeout_s=timeout_s)

    # -- shutdown -------------------------------------------------------------------------
    def close(self, timeout_s: float = 2.0) -> None:
        """Stop every thread and close the socket; idempotent. The simulator removes the robot:
        with one, this end is closed first and the simulator's end awaited, which it closes
        once the robot's removal is queued on its engine, so that a robot spawned after
        ``close()``, queued later, finds its place free (one a connection, as the camera
        calibration photographs its views). Every wait here shares one deadline,
        ``timeout_s`` in all: a simulator that does not answer (stopped with SIGSTOP, frozen)
        costs at most that, and :attr:`close_unanswered` then says so."""
        if self._closed:
            return
        self._closed = True
        deadline = time.monotonic() + timeout_s

        def left() -> float:
            return max(0.0, deadline - time.monotonic())

        clock = getattr(self, "clock", None)
        if clock is not None:
            clock.close(left())
        if self.robot is not None and self._error is None:
            if not self._await_the_simulators_end(left()):
                self.close_unanswered = (
                    f"the simulator at {self.peer} did not close its end within "
                    f"{timeout_s:g} s (stopped or frozen?): it removes robot "
                    f"{self.robot.name} when it reads again")
        self._fail(LinkClosed(f"the connection to {self.peer} was closed"))
        for t in (self._writer, self._reader):
            t.join(left())  # returns at once for the calling thread's own worker
        self._link.close()
        if self.robot is not None:
            self.robot.close()

    def _await_the_simulators_end(self, timeout_s: float) -> bool:
        """The queued commands sent, this end closed, and the simulator's end read (the reader
        stops there), within ``timeout_s``; on a full queue or a stuck send it gives up, and
        ``close()`` closes the socket as it would have. True when the simulator's end came."""
        if timeout_s <= 0.0:
            return False
        deadline = time.monotonic() + timeout_s
        try:
            self._outbox.put_nowait(_STOP)  # the writer sends what is queued, then stops
        except queue.Full:
            return False
        if not self._writer.join(timeout_s):
            return False
        self._link.finish_sending()
        return self._reader.join(max(0.0, deadline - time.monotonic()))

    def add_close_hook(self, fn: Callable[[SkeyeError], None]) -> None:
        """Call ``fn(error)`` once when the link goes down."""
        with self._lock:
            self._close_hooks.append(fn)


def connect(
    address: str = f"127.0.0.1:{DEFAULT_PORT}",
    *,
    images: str | None = None,
    timeout_s: float = 10.0,
    **kwargs: Any,
) -> Connection:
    """Connect to a simulator's control port (``host:port``); use it as a context manager.

    Example::

        with skeye.connect("127.0.0.1:3000") as sim:
            copter = sim.spawn("hummingbird", start="Pad1")
            copter.take_off(1.0)
            copter.land()
    """
    return Connection(address, images=images, timeout_s=timeout_s, **kwargs)
