"""Ground-side client of a vehicle (real, or ``skeye pilot``): typed commands and telemetry.

How this works: a ``Vehicle`` owns one ``Link``. A reader thread alone calls ``link.recv``,
feeds the bytes to a sans-IO ``VehicleStreamParser`` and files each message: telemetry frames
into ``latest`` (and the callbacks), acks and RESULTs into per-descriptor counters that waiting
commands watch. Commands are sent under one lock, so only one command is in flight at a time and
two threads never interleave frames; each waits (with a timeout) for its answer: a RESULT for
skeye commands, an ack for AscTec ones, one frame per requested structure for a poll. A RESULT
with a non-zero code raises ``CommandRejected(reason, code)``. If the vehicle turns us away on
connect (RESULT code 5: another ground station is connected), every later command raises that.

Units: the typed methods take SI in named arguments (``up_m_s`` positive up, like
``skeye.control``); the conversion to the wire's FRD/NED integer scalings is in
``skeye.wire.packet_units``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import defaultdict, deque
from collections.abc import Callable, Iterable
from types import TracebackType

from skeye.errors import (
    AnswerLost,
    CommandRejected,
    LinkTimeout,
    LocalProtocolError,
    VehicleLost,
)
from skeye.link.transport import Link, LinkClosed, open_link
from skeye.wire.packet_defs import LAYOUTS
from skeye.wire.packet_units import (
    GotoGpsSi,
    MoveBySi,
    PadModeSi,
    ctrl_input_from_si,
    goto_gps_from_si,
    move_by_from_si,
    pad_mode_from_si,
    s_to_ms,
    take_off_from_si,
    velocity_from_si,
    wire_value,
)
from skeye.wire.packets import (
    PD,
    Ack,
    Clock,
    ComeHome,
    EndFlight,
    FrameError,
    GotoGps,
    Health,
    HealthStatus,
    Hold,
    Land,
    Launch,
    Message,
    MoveBy,
    MoveFrame,
    NavState,
    NavStatus,
    PadAction,
    PadMode,
    Poll,
    PollMask,
    Reset,
    Result,
    ResultCode,
    SkeyeMask,
    Stream,
    VehicleStreamParser,
    Velocity,
    Waypoint,
    WaypointGoto,
    encode,
)
from skeye.workers import Worker

log = logging.getLogger(__name__)

DEFAULT_TIMEOUT_S = 2.0
TelemetryCallback = Callable[[Message], None]

NO_COMMAND_PD = 0x00  # RESULT.command_pd of an answer to no command (a refused connection)
BAD_FRAME_LOG_EVERY_S = 5.0  # a bad frame is logged as a warning at most this often


def velocity_command(forward_m_s: float = 0.0, right_m_s: float = 0.0, up_m_s: float = 0.0,
                     yaw_rate_rad_s: float = 0.0, duration_s: float = 0.0) -> Velocity:
    """VELOCITY (see :meth:`Vehicle.set_velocity`), built and checked without a link."""
    return velocity_from_si((forward_m_s, right_m_s, -up_m_s), yaw_rate_rad_s, duration_s)


def move_by_command(forward_m: float = 0.0, right_m: float = 0.0, up_m: float = 0.0,
                    yaw_rad: float = 0.0, frame: str = "body", speed_m_s: float = 1.0) -> MoveBy:
    """MOVE_BY (see :meth:`Vehicle.move_by`), built and checked without a link."""
    frames = {"body": MoveFrame.BODY_FRD, "world": MoveFrame.WORLD_NED}
    if frame not in frames:
        raise LocalProtocolError(f"move_by frame {frame!r}: expected 'body' or 'world'")
    return move_by_from_si(MoveBySi((forward_m, right_m, -up_m), yaw_rad, frames[frame],
                                    speed_m_s))


def goto_gps_command(latitude_deg: float, longitude_deg: float, height_m: float,
                     speed_m_s: float = 1.0) -> GotoGps:
    """GOTO_GPS (see :meth:`Vehicle.goto_gps`), built and checked without a link."""
    return goto_gps_from_si(GotoGpsSi(latitude_deg, longitude_deg, height_m, speed_m_s))


def pad_mode_command(mode: PadAction | str | int, deadband_m: float = 0.1,
                     max_speed_m_s: float = 0.5) -> PadMode:
    """PAD_MODE (see :meth:`Vehicle.pad_mode`), built and checked without a link."""
    return pad_mode_from_si(PadModeSi(_pad_action(mode), deadband_m, max_speed_m_s))


def _pad_action(mode: PadAction | str | int) -> PadAction:
    if isinstance(mode, str):
        try:
            return PadAction[mode.upper()]
        except KeyError:
            raise LocalProtocolError(f"pad mode {mode!r}: expected off, hold or land") from None
    try:
        return PadAction(mode)
    except ValueError:
        raise LocalProtocolError(
            f"pad mode {mode!r}: expected 0 (off), 1 (hold), 2 (land)"
        ) from None


DEFAULT_KEEPALIVE_S = 0.5


class Vehicle:
    """A vehicle at the other end of a link; a context manager that closes the link."""

    def __init__(
        self,
        link: Link,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        keepalive_s: float | None = DEFAULT_KEEPALIVE_S,
    ) -> None:
        self.link = link
        self.timeout_s = timeout_s
        # A ground station that goes quiet looks like a lost radio link to the vehicle (which
        # then holds, and lands after its timeout): poll LL_STATUS when nothing else was sent
        # for keepalive_s, like a GCS heartbeat. None turns it off (tests of the failsafe).
        self.keepalive_s = keepalive_s
        self._last_sent_s = time.monotonic()
        self.parser = VehicleStreamParser()
        self.latest: dict[PD, Message] = {}
        self.frame_errors = 0
        self.frames_received = 0  # frames read whole: acks, results and structures
        self._frame_errors_logged = 0  # frame_errors at the last warning about them
        self._frame_error_logged_s = -math.inf  # when that warning was (monotonic)
        self.turned_away: Result | None = None  # the RESULT code 5 that refused this client
        self._cond = threading.Condition()
        self._counts: dict[PD, int] = defaultdict(int)
        # Every NAV_STATUS with its count, so wait_state sees a state that lasted a single frame
        # even when several frames arrived while the waiting thread was not scheduled.
        self._nav_history: deque[tuple[int, NavStatus]] = deque(maxlen=4096)
        self._acks: dict[PD, int] = defaultdict(int)
        self._results: dict[int, list[Result]] = defaultdict(list)
        self._callbacks: list[TelemetryCallback] = []
        self._command_lock = threading.Lock()
        self._reader_error: BaseException | None = None
        self._stop = threading.Event()
        self._reader = Worker(self._read_loop, "vehicle-reader").start()

    @classmethod
    def open(
        cls,
        uri: str,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        keepalive_s: float | None = DEFAULT_KEEPALIVE_S,
    ) -> Vehicle:
        """Open ``tcp://host:port`` or ``serial:///dev/ttyX?baud=57600`` and wrap it."""
        return cls(open_link(uri), timeout_s=timeout_s, keepalive_s=keepalive_s)

    def _send(self, data: bytes) -> None:
        self._last_sent_s = time.monotonic()
        self.link.send(data)

    # -- lifecycle -----------------------------------------------------------------------
    def close(self, timeout_s: float = 2.0) -> None:
        """Stop the reader and close the link (idempotent)."""
        self._stop.set()
        self.link.close()
        self._reader.join(timeout_s)

    def __enter__(self) -> Vehicle:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def line_errors(self) -> tuple[int, int]:
        """(garbage bytes skipped, bad frames) read on this link so far."""
        return self.parser.garbage_bytes, self.frame_errors

    @property
    def unheard(self) -> str | None:
        """What came on a link that never carried one whole frame (the far end speaks
        another protocol: a simulator's or a web port), or None once a frame came."""
        if self.frames_received:
            return None
        said = "nothing a vehicle sends came on this link"
        garbage, bad = self.line_errors
        return f"{said} ({garbage} unreadable bytes, {bad} bad frames)" if garbage or bad \
            else said

    @property
    def connected(self) -> bool:
        """False once the link closed (by us, the vehicle, or an error)."""
        return not self.link.closed and self._reader.is_alive()

    # -- receiving -----------------------------------------------------------------------
    def _read_loop(self) -> None:
        try:
            while not self._stop.is_set():
                data = self.link.recv(0.2)
                if data:
                    for event in self.parser.feed(data):
                        self._dispatch(event)
                keepalive = self.keepalive_s
                if keepalive is not None and time.monotonic() - self._last_sent_s >= keepalive:
                    self._send(encode(Poll(int(PollMask.LL_STATUS))))
        except LinkClosed:
            pass
        except BaseException as exc:  # reaches waiting callers through _wait
            log.exception("vehicle reader failed")
            self._reader_error = exc
        finally:
            with self._cond:
                self._cond.notify_all()

    def _dispatch(self, event: Message | FrameError) -> None:
        if isinstance(event, FrameError):
            with self._cond:  # a waiter on a line of answers learns its answer is lost
                self.frame_errors += 1
                self._cond.notify_all()
            now = time.monotonic()
            if now - self._frame_error_logged_s >= BAD_FRAME_LOG_EVERY_S:  # a noisy line
                # would otherwise log a warning per frame
                log.warning("bad frame from the vehicle: %s (%d bad frames since the last "
                            "such warning)", event.reason,
                            self.frame_errors - self._frame_errors_logged)
                self._frame_error_logged_s, self._frame_errors_logged = now, self.frame_errors
            return
        self.frames_received += 1
        with self._cond:
            if isinstance(event, Ack):
                self._acks[event.pd] += 1
            elif isinstance(event, Result):
                if event.code is ResultCode.BUSY and event.command_pd == NO_COMMAND_PD:
                    self.turned_away = event
                self._results[event.command_pd].append(event)
            else:
                pd = LAYOUTS[type(event)].pd
                assert pd is not None  # every vehicle frame has a descriptor
                self.latest[pd] = event
                self._counts[pd] += 1
                if isinstance(event, NavStatus):
                    self._nav_history.append((self._counts[pd], event))
            self._cond.notify_all()
        if not isinstance(event, Ack):
            for cb in list(self._callbacks):
                try:
                    cb(event)
                except Exception:
                    log.exception("telemetry callback %r failed", cb)

    def add_callback(self, fn: TelemetryCallback) -> None:
        """Call ``fn(message)`` from the reader thread for every frame (not acks)."""
        self._callbacks.append(fn)

    def remove_callback(self, fn: TelemetryCallback) -> None:
        """Stop calling ``fn``.

        Raises:
            LocalProtocolError: ``fn`` was not added.
        """
        try:
            self._callbacks.remove(fn)
        except ValueError:
            raise LocalProtocolError(f"{fn!r} is not a telemetry callback here") from None

    def _wait(self, ready: Callable[[], bool], what: str, timeout_s: float | None) -> None:
        """Wait under ``self._cond`` until ``ready()``; raise on timeout or a dead link."""
        deadline = time.monotonic() + (self.timeout_s if timeout_s is None else timeout_s)
        while not ready():
            if self._reader_error is not None:
                raise LinkClosed(f"vehicle reader failed: {self._reader_error!r}")
            if not self._reader.is_alive() or self.link.closed:
                if self.turned_away is not None:
                    raise CommandRejected(self.turned_away.reason, int(self.turned_away.code))
                raise LinkClosed(f"{self.link.name}: link closed while waiting for {what}")
            left = deadline - time.monotonic()
            if left <= 0:
                raise LinkTimeout(
                    f"{self.link.name}: no {what} within {timeout_s or self.timeout_s} s"
                )
            self._cond.wait(min(left, 0.2))

    def wait_for(self, pd: PD, timeout_s: float | None = None) -> Message:
        """Wait for the next frame with descriptor ``pd`` (telemetry or streamed) and return it."""
        with self._cond:
            start = self._counts[pd]
            self._wait(lambda: self._counts[pd] > start, f"frame PD 0x{pd:02x}", timeout_s)
            return self.latest[pd]

    def wait_state(self, *states: NavState, timeout_s: float = 30.0) -> NavStatus:
        """Wait until a NAV_STATUS received after this call reports one of ``states`` (needs
        NAV_STATUS streaming). Every frame counts, not only the newest: a state seen in one
        frame is found even if later frames arrived before this thread ran."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            seen = self._counts[PD.NAV_STATUS]
        last: NavStatus | None = None
        names = ", ".join(s.name for s in states)
        while True:
            after = seen

            def arrived(after: int = after) -> bool:
                return self._counts[PD.NAV_STATUS] > after

            with self._cond:
                try:
                    self._wait(arrived, "NAV_STATUS", max(0.01, deadline - time.monotonic()))
                except LinkTimeout:
                    raise LinkTimeout(
                        f"vehicle not {names} within {timeout_s} s (last: {last})"
                    ) from None
                fresh = [m for n, m in self._nav_history if n > after]
                seen = self._counts[PD.NAV_STATUS]
            for msg in fresh:
                last = msg
                if msg.state in states:
                    return msg
            if time.monotonic() >= deadline:
                raise LinkTimeout(f"vehicle not {names} within {timeout_s} s (last: {last})")

    def nav_status(self) -> NavStatus | None:
        """The latest NAV_STATUS received (streamed), or None."""
        msg = self.latest.get(PD.NAV_STATUS)
        return msg if isinstance(msg, NavStatus) else None

    # -- sending -------------------------------------------------------------------------
    def _check_turned_away(self) -> None:
        if self.turned_away is not None:
            raise CommandRejected(self.turned_away.reason, int(self.turned_away.code))

    def send_raw(self, data: bytes) -> None:
        """Send bytes as they are (tests, and tools checking a vehicle's error handling)."""
        with self._command_lock:
            self._send(data)

    def command(self, msg: Message, timeout_s: float | None = None, *,
                only_answers: bool = False) -> Result | Ack:
        """Send a skeye or AscTec command and wait for its RESULT or ack.

        ``only_answers``: the line carries nothing but answers to this client's requests (an
        AscTec LL board's; a vehicle streaming telemetry is not such a line), so a bad frame
        arriving while the answer is due is that answer, corrupted: ``AnswerLost`` at once,
        not ``LinkTimeout`` at the deadline.

        Raises:
            CommandRejected: the vehicle answered a RESULT with a non-zero code.
            AnswerLost: with ``only_answers``, a bad frame came in the answer's place (whether
                the vehicle took the command is not known).
            LinkTimeout: no answer within the timeout.
        """
        layout = LAYOUTS.get(type(msg))
        if layout is None or layout.pd is None or isinstance(msg, Poll):
            raise LocalProtocolError(f"{type(msg).__name__} is not a command with an answer")
        pd = layout.pd
        self._check_turned_away()
        with self._command_lock, self._cond:
            acks0 = self._acks[pd]
            results0 = len(self._results[pd])
            bad0 = self.frame_errors
            self._send(encode(msg))
            self._wait(
                lambda: (self._acks[pd] > acks0 or len(self._results[pd]) > results0
                         or (only_answers and self.frame_errors > bad0)),
                f"answer to {type(msg).__name__}",
                timeout_s,
            )
            if self._acks[pd] == acks0 and len(self._results[pd]) == results0:
                raise AnswerLost(f"{self.link.name}: the answer to {type(msg).__name__} came "
                                 "corrupted (a bad frame in its place)")
            if len(self._results[pd]) > results0:
                result = self._results[pd][results0]
                del self._results[pd][: results0 + 1]
                if result.code is not ResultCode.OK:
                    raise CommandRejected(result.reason, int(result.code))
                return result
            return Ack(pd)

    def poll(
        self, mask: int = int(PollMask.LL_STATUS), timeout_s: float | None = None, *,
        only_answers: bool = False,
    ) -> dict[PD, Message]:
        """Poll structures (``PollMask`` bits) and return one fresh frame of each.

        ``only_answers`` (a line of answers alone, as for ``command``): the vehicle sends one
        frame per structure, so once the frames that came and the bad frames since the request
        make up the whole answer, the wait ends (at the next good frame after a bad one, or at
        the bad frame when it was the last due) and the structures that came are returned, the
        corrupted ones left out. A frame whose start was corrupted is garbage, not a bad frame:
        its answer still waits out the timeout."""
        request = Poll(mask)
        wanted = request.requested()
        if not wanted:
            raise LocalProtocolError(f"poll mask 0x{mask:04x} requests no known structure")
        self._check_turned_away()
        with self._command_lock, self._cond:
            start = {pd: self._counts[pd] for pd in wanted}
            bad0 = self.frame_errors

            def came() -> list[PD]:
                return [pd for pd in wanted if self._counts[pd] > start[pd]]

            def accounted() -> bool:
                lost = self.frame_errors - bad0 if only_answers else 0
                return len(came()) + lost >= len(wanted)

            self._send(encode(request))
            self._wait(accounted, f"poll answer (mask 0x{mask:04x})", timeout_s)
            return {pd: self.latest[pd] for pd in came()}

    # -- typed skeye commands --------------------------------------------------------------
    def take_off(self, height_m: float) -> Result | Ack:
        """Start motors and climb to ``height_m`` above the take-off point."""
        return self.command(take_off_from_si(height_m))

    def land(self) -> Result | Ack:
        """Descend and stop the motors."""
        return self.command(Land())

    def hold(self) -> Result | Ack:
        """Stop and hover here."""
        return self.command(Hold())

    def reset(self) -> Result | Ack:
        """Bring the vehicle back at home, still (the way out of CRASHED; a simulated vehicle
        respawns at its start pose)."""
        return self.command(Reset())

    @property
    def health(self) -> Health | None:
        """The latest HEALTH the vehicle sent (None before the first)."""
        msg = self.latest.get(PD.HEALTH)
        return msg if isinstance(msg, Health) else None

    def set_velocity(
        self,
        forward_m_s: float = 0.0,
        right_m_s: float = 0.0,
        up_m_s: float = 0.0,
        yaw_rate_rad_s: float = 0.0,
        duration_s: float = 0.0,
    ) -> Result | Ack:
        """Fly at body-frame velocities for ``duration_s`` (0 = until replaced)."""
        return self.command(
            velocity_command(forward_m_s, right_m_s, up_m_s, yaw_rate_rad_s, duration_s))

    def move_by(
        self,
        forward_m: float = 0.0,
        right_m: float = 0.0,
        up_m: float = 0.0,
        yaw_rad: float = 0.0,
        frame: str = "body",
        speed_m_s: float = 1.0,
    ) -> Result | Ack:
        """Move relative to the current position; ``frame="world"`` reads forward as north
        and right as east."""
        return self.command(move_by_command(forward_m, right_m, up_m, yaw_rad, frame,
                                            speed_m_s))

    def goto_gps(
        self, latitude_deg: float, longitude_deg: float, height_m: float, speed_m_s: float = 1.0
    ) -> Result | Ack:
        """Fly to GPS coordinates at ``height_m`` above home."""
        return self.command(goto_gps_command(latitude_deg, longitude_deg, height_m, speed_m_s))

    def pad_mode(
        self, mode: PadAction | str | int, deadband_m: float = 0.1, max_speed_m_s: float = 0.5
    ) -> Result | Ack:
        """Set landing-pad mode: off, hold over the pad, or land on it."""
        return self.command(pad_mode_command(mode, deadband_m, max_speed_m_s))

    def run_until(self, time_s: float, timeout_s: float | None = None) -> NavStatus:
        """Grant the vehicle sim time up to ``time_s`` (CLOCK; a pilot run with
        ``--ground-clock``) and wait for a NAV_STATUS at that time (needs NAV_STATUS streaming).

        Returns the NAV_STATUS taken at ``time_s`` (the pilot holds the clock there), so a
        script that decides on it acts at an exact sim time.

        Raises:
            VehicleLost: the pilot's HEALTH says LOST (its simulator died or froze): sim time
                stands still until it is back, so the wait ends at once, with the pilot's
                reason, instead of at the timeout.
            LinkTimeout: sim time did not reach ``time_s`` within the timeout.
        """
        until_ms = s_to_ms(time_s)
        limit_s = self.timeout_s if timeout_s is None else timeout_s
        with self._cond:
            navs, healths = self._counts[PD.NAV_STATUS], self._counts[PD.HEALTH]
        self.command(Clock(until_ms))
        deadline = time.monotonic() + limit_s
        while True:
            health = self.health
            if health is not None and health.status is HealthStatus.LOST:
                raise VehicleLost(f"sim time cannot reach {time_s} s: the vehicle is lost "
                                  f"({health.reason or 'no reason given'})")
            with self._cond:
                msg = self.latest.get(PD.NAV_STATUS)
                if (self._counts[PD.NAV_STATUS] > navs and isinstance(msg, NavStatus)
                        and msg.time >= until_ms):
                    return msg
                navs, healths = self._counts[PD.NAV_STATUS], self._counts[PD.HEALTH]

                def news(navs: int = navs, healths: int = healths) -> bool:
                    return (self._counts[PD.NAV_STATUS] > navs
                            or self._counts[PD.HEALTH] > healths)

                try:
                    self._wait(news, "NAV_STATUS", max(0.01, deadline - time.monotonic()))
                except LinkTimeout:
                    raise LinkTimeout(f"sim time did not reach {time_s} s within {limit_s} s "
                                      f"(last: {msg})") from None

    def stream(
        self, poll_mask: int = 0, skeye_mask: int = int(SkeyeMask.NAV_STATUS), period_s: float = 0.1
    ) -> Result | Ack:
        """Have the vehicle push the masked telemetry every ``period_s`` (0 stops it; a period
        that rounds to 0 ms but is not 0 raises LocalProtocolError, where it was sent as
        "stop")."""
        return self.command(Stream(poll_mask, skeye_mask, wire_value(Stream, "period", period_s)))

    # -- AscTec commands -----------------------------------------------------------------
    def ctrl_input(
        self,
        roll_rad: float,
        pitch_rad: float,
        yaw_rate_rad_s: float,
        thrust_fraction: float,
        ctrl: int = 0x0F,
    ) -> Result | Ack:
        """Direct stick input (CTRL_INPUT); answered by an ack."""
        return self.command(
            ctrl_input_from_si(roll_rad, pitch_rad, yaw_rate_rad_s, thrust_fraction, ctrl)
        )

    def upload_waypoint(self, waypoint: Waypoint) -> Result | Ack:
        """Upload the single waypoint (``>*>ws``)."""
        return self.command(waypoint)

    def waypoint_goto(self) -> Result | Ack:
        """Fly to the uploaded waypoint (``>*>wg``)."""
        return self.command(WaypointGoto())

    def launch(self) -> Result | Ack:
        """AscTec launch (``>*>wl``): take off and set home."""
        return self.command(Launch())

    def end_flight(self) -> Result | Ack:
        """AscTec end flight (``>*>we``): land where you are."""
        return self.command(EndFlight())

    def come_home(self) -> Result | Ack:
        """AscTec come home (``>*>wh``)."""
        return self.command(ComeHome())

    def results(self, command_pd: int) -> Iterable[Result]:
        """RESULTs for ``command_pd`` not consumed by a command (e.g. garbage answered)."""
        with self._cond:
            return list(self._results[command_pd])

    def wait_result(self, command_pd: int, timeout_s: float | None = None, *,
                    bad_frames_since: int | None = None) -> Result:
        """Wait for an unsolicited RESULT for ``command_pd`` (e.g. after ``send_raw``).

        ``bad_frames_since``: ``frame_errors`` when the request went out, on a line of answers
        alone (see ``command``): a bad frame since then is the RESULT, corrupted, and raises
        ``AnswerLost`` at once."""
        with self._cond:
            self._wait(
                lambda: bool(self._results[command_pd]) or (
                    bad_frames_since is not None and self.frame_errors > bad_frames_since),
                f"RESULT for 0x{command_pd:02x}", timeout_s,
            )
            if not self._results[command_pd]:
                raise AnswerLost(f"{self.link.name}: the RESULT for 0x{command_pd:02x} came "
                                 "corrupted (a bad frame in its place)")
            return self._results[command_pd].pop(0)
