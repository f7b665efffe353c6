"""The ``asctec-ll://`` airframe: an AscTec low-level board over its serial protocol.

How this works: :class:`AscTecLLAirframe` talks to the board through a
:class:`skeye.link.vehicle.Vehicle` (the same AscTec client ground control uses: the LL board
is to the onboard computer what the vehicle is to ground control) over a serial port or TCP.
The Airframe methods only set the pilot's intent (:class:`skeye.pilot.ll_control.StickPilot`);
one control cycle at a time the backend sends the cycle's CTRL_INPUT, then polls the
structures it flies on and updates the estimate (:class:`skeye.pilot.ll_control.LLEstimate`).

- Realtime (a real board): a worker runs the cycle at ``rate_hz`` (20 Hz) of wall time; the
  snapshot's time is the onboard computer's monotonic clock at each answer. The line budget at
  57600 baud (docs/onboard.md): every cycle CTRL_INPUT and its ack, LL_STATUS and
  IMU_CALCDATA (158 bytes); every 4th GPS_DATA_ADVANCED; every 20th RC_DATA, IMU_RAWDATA and
  CONTROLLER_OUTPUT: 3.6 kB/s of the line's 5.76 kB/s.
- Lockstep (``?lockstep=1``, the simulator's emulated board): the pilot's loop calls
  :meth:`AscTecLLAirframe.advance` every control period; the cycle's CTRL_INPUT goes first,
  then a CLOCK grant the board answers once the simulator reached it (with the sim time, which
  becomes the snapshot's time), then the poll. A run is as reproducible as on ``sim://``.

Checks and failures, each named (``lost``; the pilot then applies its failsafe, and the board,
hearing nothing more, its own serial timeout):

- the line closed or hung up: ``LL board lost: ...``;
- an answer that comes corrupted (a bad frame: the line carries nothing but answers, one frame
  per structure asked) is known lost at once (``only_answers``): the cycle goes on at the next
  good frame (the poll's other structures are used, the lost one is asked next cycle; a CLOCK
  grant is sent again), instead of waiting out ``timeout_s``;
- no answer (or only garbage, which is counted and skipped) for ``silent_after`` cycles in a
  row: ``LL board silent: ...``, which says how much unreadable data came meanwhile (a line
  that carries bytes but no frame: a wrong baud rate, or noise);
- the R/C's serial-interface switch (RC_DATA channel[4]) off while flying: ``R/C took over:
  ...`` (the safety pilot has the vehicle; commands are refused while it is off on the ground);
- a realtime cycle below 80 % of ``rate_hz`` over a second, every answer in (a slow line or
  radio link, a board answering late within ``timeout_s``): ``LL board cycle at N Hz, not
  20 Hz: its answers take M ms a cycle``, at most every 5 s, and ``LL board cycle back at
  20 Hz`` once it keeps its rate again (:attr:`AscTecLLAirframe.slow_cycle` meanwhile). The
  pilot flies on: the board holds its last sticks between cycles.

URI: ``asctec-ll://serial/dev/ttyS1?baud=57600`` or ``asctec-ll://tcp/HOST:PORT``; options
``lockstep=1``, ``rate_hz=20``, ``timeout_s=0.5`` (each answer's deadline; a CLOCK grant waits
``clock_timeout_s``, 60 s, for the simulator).
"""

from __future__ import annotations

import logging
import math
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from skeye.errors import (
    AnswerLost,
    CommandRejected,
    ConfigError,
    LinkClosed,
    LinkTimeout,
    LocalProtocolError,
    SkeyeError,
)
from skeye.geo import GeoOrigin
from skeye.link.transport import DEFAULT_BAUD, open_link, parse_uri
from skeye.link.vehicle import Vehicle
from skeye.pilot.airframe import AirframeOptions, Snapshot, VehicleLimits, vehicle_limits
from skeye.pilot.ll_control import LLEstimate, StickPilot, Sticks, Velocity, nav_state
from skeye.uris import query_of, split_uri
from skeye.values import MAX_BAUD, baud_rate
from skeye.wire.packet_units import s_to_ms
from skeye.wire.packets import PD, Clock, CtrlInput, PollMask, ResultCode, encode
from skeye.workers import Worker

log = logging.getLogger(__name__)

EVERY_CYCLE = int(PollMask.LL_STATUS | PollMask.IMU_CALCDATA)
GPS_EVERY = 4  # cycles: 5 Hz at 20 Hz, the receiver's rate
SLOW_EVERY = 20  # cycles: 1 Hz
SLOW = int(PollMask.RC_DATA | PollMask.IMU_RAWDATA | PollMask.CONTROLLER_OUTPUT)
FIRST_POLL = int(EVERY_CYCLE | PollMask.GPS_DATA_ADVANCED | SLOW)
# The first poll is asked this often (each with the answer deadline) before the board counts as
# silent: a board just powered up, or one emulated on a loaded host, may miss the first; in
# flight a missed answer is counted towards silent_after instead.
FIRST_CONTACT_TRIES = 3
SIM_TIME = re.compile(r"sim time (-?[0-9]+(?:\.[0-9]*)?) s")
REPORT_EVERY_S = 5.0  # garbage on the line is logged at most this often
RATE_HZ_MAX = 200.0  # the fastest control cycle ``rate_hz`` allows
CLOCK_TIMEOUT_S = 60.0  # how long a CLOCK grant waits for the simulator
RATE_WINDOW_S = 1.0  # the realtime cycle's rate is measured over this much wall time
RATE_SLOW = 0.8  # below this fraction of ``rate_hz`` the cycle is said to be slow


@dataclass
class _RateWindow:
    """The realtime cycles since ``start_s``: how many, the time they took, and whether any
    went unanswered (``silent`` counts those, and says its own)."""

    start_s: float
    cycles: int = 0
    busy_s: float = 0.0
    unanswered: bool = False


@dataclass(frozen=True)
class LLLinkSettings:
    """An ``asctec-ll://`` URI, parsed."""

    link_uri: str  # the byte link: serial://... or tcp://...
    lockstep: bool = False
    rate_hz: float = 20.0
    timeout_s: float = 0.5
    clock_timeout_s: float = CLOCK_TIMEOUT_S
    silent_after: int = 3  # cycles in a row without an answer


def parse_asctec_ll(uri: str) -> LLLinkSettings:
    """Parse ``asctec-ll://serial/DEVICE?baud=N`` or ``asctec-ll://tcp/HOST:PORT``.

    Raises:
        LocalProtocolError: naming what is wrong.
    """
    parts = split_uri(uri, "airframe", "asctec-ll://serial/DEVICE?baud=N or "
                      "asctec-ll://tcp/HOST:PORT")
    if parts.scheme.lower() != "asctec-ll":
        raise LocalProtocolError(f"airframe {uri!r}: expected asctec-ll://...")
    query = query_of(uri, parts, "airframe")
    known = {"baud", "lockstep", "rate_hz", "timeout_s"}
    unknown = sorted(set(query) - known)
    if unknown:
        raise LocalProtocolError(f"airframe {uri!r}: unknown option(s) {unknown} "
                                 f"(known: {', '.join(sorted(known))})")

    def number(key: str, default: float, low: float, high: float) -> float:
        text = query.get(key, [str(default)])[-1]
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and low <= value <= high):
            raise LocalProtocolError(f"airframe {uri!r}: {key}={text} is not in "
                                     f"{low:g}..{high:g}")
        return value

    kind = parts.netloc.lower()
    if kind == "serial":
        if not parts.path or parts.path == "/":
            raise LocalProtocolError(f"airframe {uri!r}: expected asctec-ll://serial/dev/ttyX")
        baud_text = query.get("baud", [str(DEFAULT_BAUD)])[-1]
        checked = baud_rate(baud_text)
        if checked is None:
            raise LocalProtocolError(f"airframe {uri!r}: baud={baud_text} is not a whole "
                                     f"number 1..{MAX_BAUD}")
        baud = checked
        link = f"serial://{parts.path}?baud={baud}"
    elif kind == "tcp":
        address = parts.path.lstrip("/")
        host, sep, port = address.rpartition(":")
        if (not sep or not host or not (port.isascii() and port.isdigit())
                or not 0 < int(port) < 65536):
            raise LocalProtocolError(f"airframe {uri!r}: expected asctec-ll://tcp/HOST:PORT")
        if "baud" in query:
            raise LocalProtocolError(f"airframe {uri!r}: baud is for a serial line")
        link = f"tcp://{address}"
        try:
            parse_uri(link)  # the host as a link takes it (an IPv6 address in brackets)
        except LocalProtocolError:
            raise LocalProtocolError(f"airframe {uri!r}: expected asctec-ll://tcp/HOST:PORT, "
                                     "an IPv6 HOST in brackets ([::1])") from None
    else:
        raise LocalProtocolError(f"airframe {uri!r}: the line must be serial/DEVICE or "
                                 f"tcp/HOST:PORT, not {parts.netloc!r}")
    lockstep_text = query.get("lockstep", ["0"])[-1].lower()
    if lockstep_text not in ("0", "1", "true", "false", "yes", "no"):
        raise LocalProtocolError(f"airframe {uri!r}: lockstep={lockstep_text} is not 0 or 1")
    return LLLinkSettings(
        link_uri=link,
        lockstep=lockstep_text in ("1", "true", "yes"),
        rate_hz=number("rate_hz", 20.0, 1.0, RATE_HZ_MAX),
        timeout_s=number("timeout_s", 0.5, 0.01, 60.0),
    )


def unreadable(vehicle: Vehicle, since: tuple[int, int] = (0, 0)) -> str:
    """What a silent board's message adds when bytes did come, only none readable (since
    ``since``, a ``Vehicle.line_errors`` reading): "" when nothing came."""
    garbage, bad = (now - then for now, then in zip(vehicle.line_errors, since, strict=True))
    if not garbage and not bad:
        return ""
    return (f"; the line carried {garbage} bytes of garbage and {bad} bad frames instead: "
            "a wrong baud rate, or a noisy line?")


class AscTecLLAirframe:
    """An AscTec LL board, flown through its serial protocol (see the module docstring)."""

    def __init__(
        self,
        vehicle: Vehicle,
        settings: LLLinkSettings,
        limits: VehicleLimits,
        *,
        uri: str = "asctec-ll://",
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.vehicle = vehicle
        self.settings = settings
        self.limits = limits
        self.uri = uri
        self.lockstep = settings.lockstep
        self.clock_is_sim = settings.lockstep
        self.control_period_s = 1.0 / settings.rate_hz
        self.estimate = LLEstimate()
        self.pilot = StickPilot(limits)
        self.cycles = 0
        self.link_failed: SkeyeError | None = None
        self._clock = clock
        self._lock = threading.RLock()  # the intent and the estimate
        self._io_lock = threading.Lock()  # one cycle at a time on the line
        self._lost: str | None = None
        self._silent = 0
        self._reported: tuple[int, int] = (0, 0)
        self._errors_at_answer: tuple[int, int] = (0, 0)  # line_errors() at the last answer
        self._reported_at = -REPORT_EVERY_S
        self._granted_s = 0.0
        self._stop = threading.Event()
        self._worker: Worker | None = None
        self.slow_cycle: float | None = None  # the realtime cycle's rate (Hz) while said slow
        self._slow_said_at = -REPORT_EVERY_S
        if self.lockstep:
            self._granted_s = self._grant(0.0)  # a grant already passed: answered with the time
        for attempt in range(1, FIRST_CONTACT_TRIES + 1):
            try:
                self._poll(FIRST_POLL, self._granted_s if self.lockstep else clock())
                if not self.estimate.ready:  # every answer came corrupted: none to fly on
                    raise LinkTimeout("its answers came corrupted: LL_STATUS and IMU_CALCDATA "
                                      "not both read")
                break
            except LinkTimeout:
                if attempt == FIRST_CONTACT_TRIES:
                    raise
                log.info("the LL board did not answer the first poll within %g s: asking "
                         "again (%d of %d)", self.settings.timeout_s, attempt + 1,
                         FIRST_CONTACT_TRIES)
        self._errors_at_answer = self.line_errors()
        if self.estimate.serial_switch is False:
            log.warning("the R/C's serial switch is off: the LL board ignores the pilot's "
                        "sticks until the safety pilot switches it on")
        if not self.lockstep:
            self._worker = Worker(self._run, "pilot-ll-link").start()

    # -- the line --------------------------------------------------------------------------
    def _grant(self, until_s: float) -> float:
        """CLOCK: the board answers once sim time reached ``until_s``; the time reached.

        A grant is idempotent, so one whose answer is lost on the line (garbage) is sent again
        every ``timeout_s``; the board answers a grant it is still working towards with the
        time so far, which shows it alive. Answers for earlier times are skipped; no answer to
        ``silent_after`` grants in a row is a silent board (LinkTimeout).
        """
        until_ms = max(0, s_to_ms(until_s))
        packet = encode(Clock(until_ms))
        deadline = time.monotonic() + self.settings.clock_timeout_s
        bad0 = self.vehicle.frame_errors
        self.vehicle.send_raw(packet)
        unanswered = 0
        while True:
            try:
                reply = self.vehicle.wait_result(int(PD.CLOCK), self.settings.timeout_s,
                                                 bad_frames_since=bad0)
            except LinkTimeout:
                unanswered += 1
                if unanswered > self.settings.silent_after or time.monotonic() > deadline:
                    raise LinkTimeout(f"the LL board did not reach sim time {until_s:.3f} s "
                                      f"(no answer to {unanswered} grants)") from None
                # Lost on the line (corrupted: at once; else at the deadline), or the
                # simulator is busy: asking again gets the time so far from a board that is
                # alive.
                bad0 = self.vehicle.frame_errors
                self.vehicle.send_raw(packet)
                continue
            unanswered = 0
            if reply.code is not ResultCode.OK:
                raise CommandRejected(reply.reason, int(reply.code))
            match = SIM_TIME.search(reply.reason)
            if match is None:
                raise CommandRejected("the LL board did not say its sim time: is it an "
                                      "emulated board (skeye sim --ll-board) in lockstep?")
            reached = float(match.group(1))
            if reached >= until_ms / 1000.0 - 0.0005:
                return reached

    def _poll(self, mask: int, time_s: float | None = None) -> None:
        """Poll ``mask`` and update the estimate with what came: a structure whose frame came
        corrupted is left out of this cycle (the next asks again), without waiting for it."""
        frames = self.vehicle.poll(mask, timeout_s=self.settings.timeout_s, only_answers=True)
        with self._lock:
            self.estimate.update(frames, self._clock() if time_s is None else time_s)

    def _cycle(self, grant_s: float | None = None) -> None:
        """Send this cycle's sticks, grant sim time (lockstep), poll; a missed answer counts
        towards ``silent_after``."""
        with self._io_lock:
            if self._lost is not None:
                return
            try:
                with self._lock:
                    sticks = self._sticks()
                try:
                    self.vehicle.command(sticks, timeout_s=self.settings.timeout_s,
                                         only_answers=True)
                except AnswerLost:
                    pass  # the board answered, corrupted: the next cycle's sticks follow
                time_s = None
                if grant_s is not None:
                    time_s = self._granted_s = self._grant(grant_s)
                mask = EVERY_CYCLE
                if self.cycles % GPS_EVERY == 0:
                    mask |= int(PollMask.GPS_DATA_ADVANCED)
                if self.cycles % SLOW_EVERY == 0:
                    mask |= SLOW
                self._poll(mask, time_s)
                self.cycles += 1
                self._silent = 0
                self._errors_at_answer = self.line_errors()
                self._report_line()
            except LinkTimeout as exc:
                self._silent += 1
                if self._silent >= self.settings.silent_after:
                    self._lose(f"LL board silent: no answer on {self.vehicle.link.name} in "
                               f"{self._silent} cycles in a row ({exc})"
                               f"{unreadable(self.vehicle, self._errors_at_answer)}")
                return
            except LinkClosed as exc:
                self.link_failed = exc
                self._lose(f"LL board lost: {exc}")
                return
            except CommandRejected as exc:
                self._lose(f"LL board refused: {exc}")
                return
            with self._lock:
                switch = self.estimate.serial_switch
                snap = self.estimate.snapshot()
            if switch is False and not snap.landed:
                self._lose("R/C took over: the serial interface switch is off (RC channel 5); "
                           "the safety pilot flies the vehicle")

    def _sticks(self) -> CtrlInput:
        return self.pilot.sticks(self.estimate.snapshot())

    def line_errors(self) -> tuple[int, int]:
        """(garbage bytes skipped, bad frames) read from the board so far."""
        return self.vehicle.line_errors

    def _report_line(self) -> None:
        """Say (at most every ``REPORT_EVERY_S``) that the line carries garbage."""
        errors = self.line_errors()
        now = time.monotonic()
        if errors != self._reported and now - self._reported_at >= REPORT_EVERY_S:
            log.warning("LL board line %s: %d bytes of garbage skipped, %d bad frames so far",
                        self.vehicle.link.name, *errors)
            self._reported, self._reported_at = errors, now

    def _lose(self, reason: str) -> None:
        if self._lost is None:
            self._lost = reason
            log.error("%s", reason)

    def _run(self) -> None:
        period = self.control_period_s
        next_s = time.monotonic()
        window = _RateWindow(next_s)
        while not self._stop.is_set():
            started = time.monotonic()
            self._cycle()
            if self._lost is not None and self.link_failed is not None:
                return  # the line is gone
            window.busy_s += time.monotonic() - started
            window.cycles += 1
            window.unanswered = window.unanswered or self._silent > 0
            if time.monotonic() - window.start_s >= RATE_WINDOW_S:
                self._check_rate(window)
                window = _RateWindow(time.monotonic())
            next_s += period
            delay = next_s - time.monotonic()
            if delay < -1.0:
                next_s = time.monotonic()
            self._stop.wait(max(0.0, delay))

    def _check_rate(self, window: _RateWindow) -> None:
        """Say (at most every ``REPORT_EVERY_S``) that the realtime cycle keeps less than
        ``RATE_SLOW`` of its rate, all its answers in (a silent board says so itself), and
        once that it is back."""
        rate_hz = window.cycles / (time.monotonic() - window.start_s)
        wanted = self.settings.rate_hz
        if rate_hz >= RATE_SLOW * wanted:
            if self.slow_cycle is not None:
                self.slow_cycle = None
                log.warning("LL board cycle back at %g Hz on %s", wanted, self.vehicle.link.name)
            return
        if window.unanswered:
            return
        now = time.monotonic()
        if self.slow_cycle is None or now - self._slow_said_at >= REPORT_EVERY_S:
            self.slow_cycle = rate_hz
            self._slow_said_at = now
            log.warning("LL board cycle at %.1f Hz, not %g Hz: its answers take %.0f ms a "
                        "cycle on %s (a slow line or radio link, a board answering late, or a "
                        "busy onboard computer); the pilot's control of the vehicle runs that "
                        "much slower", rate_hz, wanted, 1e3 * window.busy_s / window.cycles,
                        self.vehicle.link.name)

    # -- the backend -----------------------------------------------------------------------
    @property
    def lost(self) -> str | None:
        if self._lost is None and self._worker is not None and self._worker.error is not None:
            self._lost = f"LL link worker failed: {self._worker.error!r}"
        return self._lost

    def describe(self) -> str:
        mode = "lockstep" if self.lockstep else f"realtime, {self.settings.rate_hz:g} Hz"
        return f"AscTec LL board on {self.vehicle.link.name} ({mode})"

    def reset(self) -> str:
        """RESET: an LL board has nothing to respawn (a crashed vehicle is put back on its feet
        by hand; the board itself knows no crash); on the ground it stands LANDED again."""
        return f"{self.describe()}: nothing to reset on the board"

    def close(self) -> None:
        """Stop the cycle and close the line (idempotent). The board, hearing nothing more,
        applies its own serial timeout."""
        self._stop.set()
        if self._worker is not None:
            self._worker.join(2.0)
        self.vehicle.close()

    def advance(self, seconds: float) -> None:
        """Lockstep: one control cycle, granting ``seconds`` of sim time; realtime: nothing
        (the worker cycles)."""
        if self.lockstep and seconds > 0:
            self._cycle(grant_s=self._granted_s + seconds)

    # -- the Airframe ----------------------------------------------------------------------
    @property
    def busy(self) -> bool:
        with self._lock:
            return self.pilot.busy

    def snapshot(self) -> Snapshot:
        with self._lock:
            return self.estimate.snapshot()

    def _check(self) -> None:
        if self._lost is not None:
            raise SkeyeError(self._lost)
        if self.estimate.serial_switch is False:
            raise SkeyeError("serial control is switched off on the R/C (channel 5): the "
                             "safety pilot has the vehicle")

    def take_off(self, altitude_m: float) -> None:
        with self._lock:
            self._check()
            snap = self.estimate.snapshot()
            self.pilot.take_off(nav_state(snap), altitude_m, snap.armed and not snap.landed)

    def fly_to(self, north_m: float, east_m: float, altitude_m: float, speed_m_s: float) -> None:
        with self._lock:
            self._check()
            snap = self.estimate.snapshot()
            self.pilot.fly_to(nav_state(snap), (north_m, east_m, -altitude_m), speed_m_s)

    def fly_to_gps(self, latitude_deg: float, longitude_deg: float, altitude_m: float,
                   speed_m_s: float) -> None:
        with self._lock:
            snap = self.estimate.snapshot()
            fix = snap.gps
            if fix is None or not fix.fix:
                raise LinkTimeout("no GPS fix to navigate by")
            dn, de, _ = GeoOrigin(fix.latitude_deg, fix.longitude_deg, 0.0).to_ned(
                latitude_deg, longitude_deg, 0.0)
            n, e, _ = snap.pos_ned_m
            self.fly_to(n + dn, e + de, altitude_m, speed_m_s)

    def turn_by(self, yaw_rad: float) -> None:
        with self._lock:
            self._check()
            snap = self.estimate.snapshot()
            self.pilot.fly_to(nav_state(snap), snap.pos_ned_m, 1.0, snap.rpy_rad[2] + yaw_rad)

    def set_velocity(self, forward_m_s: float, right_m_s: float, up_m_s: float,
                     yaw_rate_rad_s: float, duration_s: float | None, *,
                     gps_mode: bool = False) -> None:
        with self._lock:
            self._check()
            until = None if duration_s is None else self.estimate.time_s + duration_s
            self.pilot.set(Velocity(forward_m_s, right_m_s, up_m_s, yaw_rate_rad_s, until))

    def hover(self) -> None:
        with self._lock:
            self.pilot.set(None)

    def land(self) -> None:
        with self._lock:
            self._check()
            self.pilot.land(nav_state(self.estimate.snapshot()))

    def attitude(self, roll_rad: float, pitch_rad: float, yaw_rate_rad_s: float,
                 thrust_fraction: float, height_mode: bool = False) -> None:
        with self._lock:
            self._check()
            self.pilot.set(Sticks(roll_rad, pitch_rad, yaw_rate_rad_s, thrust_fraction,
                                  height_mode))


def open_asctec_ll(uri: str, options: AirframeOptions) -> AscTecLLAirframe:
    """The ``asctec-ll://`` backend: open the line, read the board once, start cycling.

    Raises:
        LocalProtocolError: a bad URI.
        ConfigError: the robot class's limits cannot be read.
        LinkClosed / LinkTimeout: the line cannot be opened, or the board does not answer
            ("LL board silent").
    """
    settings = parse_asctec_ll(uri)
    try:
        limits = vehicle_limits(options.robot, options.robot_dirs)
    except ConfigError as exc:
        raise ConfigError(f"airframe {uri}: the stick scales come from the robot file "
                          f"(--robot, --robot-dir): {exc}") from None
    link = open_link(settings.link_uri, options.timeout_s)
    vehicle = Vehicle(link, timeout_s=settings.timeout_s, keepalive_s=None)
    try:
        return AscTecLLAirframe(vehicle, settings, limits, uri=uri)
    except LinkTimeout as exc:
        vehicle.close()
        raise LinkTimeout(f"LL board silent: {link.name} answered no poll ({exc})"
                          f"{unreadable(vehicle)}") from None
    except BaseException:
        vehicle.close()
        raise
