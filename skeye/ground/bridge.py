"""Ground control's link to the vehicle: connect, keep alive, reconnect, measure the link.

How this works: ``VehicleBridge`` owns at most one ``skeye.link.Vehicle`` at a time. One
worker thread alone opens, supervises and closes it; the web app only reads snapshots
(``snapshot``, ``quality``, ``history``) and sends commands (``execute``), which the
``Vehicle``'s own command lock serialises with the worker's keep-alive polls.

- Connecting: open the URI, ask the vehicle to STREAM status, IMU, GPS, NAV_STATUS and PAD at
  ``stream_period_s``. A vehicle that turns us away (RESULT code 5: another ground station is
  connected) puts the link in REFUSED; the worker retries every ``retry_s`` in every case.
- Keeping alive: the pilot holds position when no packet arrives from ground control for its
  link timeout (2 s), so the worker polls CURRENT_WAY every ``keepalive_s``; the poll's round
  trip is the link's latency figure.
- Losing the link: the peer closing it, a failed keep-alive, or no packet for ``stale_s``
  closes the vehicle and goes back to connecting; the page sees the state change and the
  telemetry age grow, and the next pilot (a restart) is picked up by the same loop.

The link state is a transition table (``LINK_TRANSITIONS``); an illegal transition raises.
Link quality (packets, rate over the last ``RATE_WINDOW_S``, frame errors, age of the last
packet, round trip, commands and refusals) is counted here; ``PacketRate`` is pure, with the
time passed in.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass
from enum import Enum
from types import TracebackType
from typing import Any

from skeye.errors import (
    CommandRejected,
    InvalidArgument,
    LinkClosed,
    LinkTimeout,
    LocalProtocolError,
    SkeyeError,
)
from skeye.ground.commands import GroundCommand, run_command
from skeye.ground.telemetry import nav_json, pad_json, telemetry_json
from skeye.link.vehicle import Vehicle
from skeye.wire.packet_defs import LAYOUTS
from skeye.wire.packet_units import imu_calcdata_to_si
from skeye.wire.packets import (
    PD,
    Ack,
    ImuCalcData,
    Message,
    NavStatus,
    PadReport,
    PollMask,
    Result,
    ResultCode,
    SkeyeMask,
    VehicleInfo,
)
from skeye.workers import Worker

log = logging.getLogger(__name__)

RATE_WINDOW_S = 2.0
# GPS_DATA_ADVANCED: the receiver's fix and the vehicle's fused position estimate ("here").
STREAM_POLL_MASK = int(PollMask.LL_STATUS | PollMask.IMU_CALCDATA | PollMask.GPS_DATA_ADVANCED)
# TRUTH: a simulated vehicle's truth, shown beside the estimate (a real vehicle sends none)
STREAM_SKEYE_MASK = int(SkeyeMask.NAV_STATUS | SkeyeMask.PAD | SkeyeMask.TRUTH)
KEEPALIVE_MASK = int(PollMask.CURRENT_WAY)  # not streamed, so its answer times the round trip
HISTORY_POINTS = 3000  # NAV_STATUS samples kept for a page that opens late (5 min at 10 Hz)


class LinkState(Enum):
    """Where the link to the vehicle stands."""

    DISCONNECTED = "disconnected"
    CONNECTING = "connecting"
    CONNECTED = "connected"
    REFUSED = "refused"  # the vehicle serves another ground station
    CLOSED = "closed"  # the bridge was closed; final


class LinkEvent(Enum):
    CONNECT = "connect"
    UP = "up"
    TURNED_AWAY = "turned away"
    FAILED = "failed"
    LOST = "lost"
    CLOSE = "close"


LINK_TRANSITIONS: dict[tuple[LinkState, LinkEvent], LinkState] = {
    (LinkState.DISCONNECTED, LinkEvent.CONNECT): LinkState.CONNECTING,
    (LinkState.REFUSED, LinkEvent.CONNECT): LinkState.CONNECTING,
    (LinkState.CONNECTING, LinkEvent.UP): LinkState.CONNECTED,
    (LinkState.CONNECTING, LinkEvent.TURNED_AWAY): LinkState.REFUSED,
    (LinkState.CONNECTING, LinkEvent.FAILED): LinkState.DISCONNECTED,
    (LinkState.CONNECTED, LinkEvent.LOST): LinkState.DISCONNECTED,
    **{(s, LinkEvent.CLOSE): LinkState.CLOSED for s in LinkState},
}


def next_link_state(state: LinkState, event: LinkEvent) -> LinkState:
    """The state after ``event``; raises LocalProtocolError for an illegal transition."""
    try:
        return LINK_TRANSITIONS[(state, event)]
    except KeyError:
        raise LocalProtocolError(
            f"link state {state.value}: event {event.value!r} is not allowed"
        ) from None


class PacketRate:
    """Packets per second over a sliding window; time is an argument (sans clock)."""

    def __init__(self, window_s: float = RATE_WINDOW_S) -> None:
        if not window_s > 0:
            raise InvalidArgument(f"window_s must be > 0, got {window_s}")
        self.window_s = window_s
        self._times: deque[float] = deque()

    def add(self, now_s: float) -> None:
        self._times.append(now_s)
        self._trim(now_s)

    def rate_hz(self, now_s: float) -> float:
        self._trim(now_s)
        return len(self._times) / self.window_s

    def _trim(self, now_s: float) -> None:
        while self._times and self._times[0] < now_s - self.window_s:
            self._times.popleft()


@dataclass(frozen=True)
class LinkQuality:
    """What the page shows about the link."""

    uri: str
    state: str
    packets: int
    packet_rate_hz: float
    frame_errors: int
    garbage_bytes: int
    last_packet_age_s: float | None
    round_trip_ms: float | None
    connects: int
    commands: int
    rejected: int
    last_error: str


@dataclass(frozen=True)
class CommandOutcome:
    """The answer to one command, as the page shows it."""

    command: str
    ok: bool
    code: int  # RESULT code; 0 = accepted
    code_name: str
    reason: str

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


class VehicleUnavailable(SkeyeError):
    """No vehicle is connected, so a command could not be sent."""


class VehicleBridge:
    """Keeps one vehicle link alive and shares its telemetry (a context manager).

    Args:
        uri: ``tcp://host:port`` or ``serial:///dev/ttyX?baud=57600``.
        stream_period_s: telemetry push period asked of the vehicle.
        keepalive_s: keep-alive poll period (below the vehicle's 2 s link timeout).
        retry_s: wait between connection attempts.
        stale_s: no packet for this long counts as a lost link.
        command_timeout_s: how long a command waits for its RESULT.
        open_vehicle: how to open a URI (tests inject in-memory links).
        clock: monotonic seconds.
        on_vehicle: called (on the reader thread) with each vehicle's VEHICLE message when it
            first arrives after a connect, or when it changes: which vehicle was reached.
        on_link: called (on the worker thread) with the link's state and its error when the
            link fails, is turned away or is lost with an error not said since it was last up,
            and when it is up again after that: news for a terminal, each failure once, not
            at every retry.
    """

    def __init__(
        self,
        uri: str,
        *,
        stream_period_s: float = 0.1,
        keepalive_s: float = 0.5,
        retry_s: float = 1.0,
        stale_s: float = 3.0,
        command_timeout_s: float = 3.0,
        open_vehicle: Callable[[str, float], Vehicle] = Vehicle.open,
        clock: Callable[[], float] = time.monotonic,
        on_vehicle: Callable[[VehicleInfo], None] | None = None,
        on_link: Callable[[LinkState, str], None] | None = None,
    ) -> None:
        if not 0 < keepalive_s < stale_s:
            raise InvalidArgument(f"need 0 < keepalive_s < stale_s, got {keepalive_s}, {stale_s}")
        self.uri = uri
        self.stream_period_s = stream_period_s
        self.keepalive_s = keepalive_s
        self.retry_s = retry_s
        self.stale_s = stale_s
        self.command_timeout_s = command_timeout_s
        self._open_vehicle = open_vehicle
        self._clock = clock
        self._lock = threading.Lock()
        self._state = LinkState.DISCONNECTED
        self._vehicle: Vehicle | None = None
        self._latest: dict[PD, Message] = {}
        self._rate = PacketRate()
        self._packets = 0
        self._last_packet_s: float | None = None
        self._frame_errors_closed = 0  # from vehicles already closed
        self._garbage_closed = 0
        self._round_trip_s: float | None = None
        self._connects = 0
        self._commands = 0
        self._rejected = 0
        self._last_error = ""
        self._seq = 0
        self._history: deque[dict[str, float]] = deque(maxlen=HISTORY_POINTS)
        self._pad_offset: tuple[float, float] | None = None
        self._on_vehicle = on_vehicle
        self._on_link = on_link
        self._said: tuple[LinkState, str] = (LinkState.CONNECTED, "")  # what on_link last got
        self._vehicle_info: VehicleInfo | None = None  # what the connected vehicle said it is
        self._t0_s = clock()
        self._stop = threading.Event()
        self._thread: Worker | None = None

    # -- lifecycle -------------------------------------------------------------------------
    def start(self) -> VehicleBridge:
        """Start the worker thread; returns self."""
        if self._thread is None:
            self._thread = Worker(self._run, "ground-bridge").start()
        return self

    def close(self, timeout_s: float = 3.0) -> None:
        """Stop the worker and close the vehicle link (idempotent)."""
        self._stop.set()
        with self._lock:
            vehicle = self._vehicle
        if vehicle is not None:
            vehicle.close()
        if self._thread is not None:
            self._thread.join(timeout_s)
        with self._lock:
            self._state = next_link_state(self._state, LinkEvent.CLOSE)

    def __enter__(self) -> VehicleBridge:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- state -----------------------------------------------------------------------------
    @property
    def state(self) -> LinkState:
        return self._state

    def _fire(self, event: LinkEvent, error: str = "") -> None:
        news: tuple[LinkState, str] | None = None
        with self._lock:
            if self._state is LinkState.CLOSED:
                return  # closing: the worker's last words change nothing
            self._state = next_link_state(self._state, event)
            if error:
                self._last_error = error
            self._seq += 1
            if self._state is not LinkState.CONNECTING and (self._state, error) != self._said:
                news = self._said = (self._state, error)
        log.info("link %s: %s -> %s %s", self.uri, event.value, self._state.value, error)
        if news is not None and self._on_link is not None:
            self._on_link(*news)

    def quality(self) -> LinkQuality:
        """Link figures now."""
        now = self._clock()
        with self._lock:
            vehicle = self._vehicle
            errors = self._frame_errors_closed
            garbage = self._garbage_closed
            if vehicle is not None:
                errors += vehicle.frame_errors
                garbage += vehicle.parser.garbage_bytes
            last = self._last_packet_s
            return LinkQuality(
                uri=self.uri,
                state=self._state.value,
                packets=self._packets,
                packet_rate_hz=round(self._rate.rate_hz(now), 2),
                frame_errors=errors,
                garbage_bytes=garbage,
                last_packet_age_s=None if last is None else round(now - last, 3),
                round_trip_ms=(
                    None if self._round_trip_s is None else round(self._round_trip_s * 1e3, 1)
                ),
                connects=self._connects,
                commands=self._commands,
                rejected=self._rejected,
                last_error=self._last_error,
            )

    @property
    def seq(self) -> int:
        """Grows with every telemetry frame and state change (for change detection)."""
        return self._seq

    def snapshot(self) -> dict[str, Any]:
        """Telemetry and link quality as one JSON-ready dict."""
        with self._lock:
            latest = dict(self._latest)
            seq = self._seq
        return {
            "type": "telemetry",
            "seq": seq,
            "t_s": round(self._clock() - self._t0_s, 3),
            "link": asdict(self.quality()),
            **telemetry_json(latest),
        }

    def attitude_rad(self) -> tuple[float, float] | None:
        """The vehicle's latest (roll, pitch) from IMU_CALCDATA, for the detector's tilt."""
        msg = self._latest.get(PD.IMU_CALCDATA)
        if not isinstance(msg, ImuCalcData):
            return None
        si = imu_calcdata_to_si(msg)
        return si.roll_rad, si.pitch_rad

    def history(self) -> list[dict[str, float]]:
        """Recent NAV_STATUS samples: t_s, north_m, east_m, height_m, pad dx_m/dy_m."""
        with self._lock:
            return list(self._history)

    # -- receiving (vehicle reader thread) ---------------------------------------------------
    def _on_message(self, msg: Message) -> None:
        if isinstance(msg, Result | Ack):
            return
        now = self._clock()
        with self._lock:
            self._packets += 1
            self._rate.add(now)
            self._last_packet_s = now
            pd = LAYOUTS[type(msg)].pd if type(msg) in LAYOUTS else None
            if pd is not None:
                self._latest[pd] = msg
            if isinstance(msg, PadReport):
                pad = pad_json(msg)
                self._pad_offset = (pad["dx_m"], pad["dy_m"]) if pad["found"] else None
            if isinstance(msg, NavStatus):
                nav = nav_json(msg)
                point = {
                    "t_s": round(now - self._t0_s, 3),
                    "north_m": nav["north_m"],
                    "east_m": nav["east_m"],
                    "height_m": nav["height_m"],
                }
                if self._pad_offset is not None:
                    point["pad_dx_m"], point["pad_dy_m"] = self._pad_offset
                self._history.append(point)
            self._seq += 1
            news = isinstance(msg, VehicleInfo) and msg != self._vehicle_info
            if isinstance(msg, VehicleInfo):
                self._vehicle_info = msg
        if news and self._on_vehicle is not None:
            assert isinstance(msg, VehicleInfo)
            self._on_vehicle(msg)

    # -- commands (web app threads) ------------------------------------------------------------
    def execute(self, command: GroundCommand) -> CommandOutcome:
        """Send one validated command and wait for the vehicle's answer.

        A refusal is an outcome (``ok`` False, the RESULT's code and reason), not an exception.

        Raises:
            VehicleUnavailable: no vehicle is connected, or the link failed during the command.
        """
        with self._lock:
            vehicle = self._vehicle if self._state is LinkState.CONNECTED else None
            self._commands += 1
        if vehicle is None:
            raise VehicleUnavailable(
                f"no vehicle connected (link {self._state.value}: {self._last_error or self.uri})"
            )
        try:
            answer = run_command(vehicle, command)
        except CommandRejected as exc:
            with self._lock:
                self._rejected += 1
            code = exc.code if exc.code is not None else int(ResultCode.REFUSED)
            return CommandOutcome(command.name, False, code, _code_name(code), exc.reason)
        except (LinkTimeout, LinkClosed) as exc:
            raise VehicleUnavailable(f"{command.name}: {exc}") from exc
        reason = answer.reason if isinstance(answer, Result) else ""
        return CommandOutcome(command.name, True, 0, "OK", reason)

    # -- the worker --------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            vehicle = self._connect()
            if vehicle is None:
                self._stop.wait(self.retry_s)
                continue
            try:
                self._supervise(vehicle)
            finally:
                self._drop(vehicle)

    def _connect(self) -> Vehicle | None:
        self._fire(LinkEvent.CONNECT)
        try:
            vehicle = self._open_vehicle(self.uri, self.command_timeout_s)
        except (SkeyeError, OSError) as exc:
            self._fire(LinkEvent.FAILED, str(exc))
            return None
        vehicle.add_callback(self._on_message)
        try:
            vehicle.stream(STREAM_POLL_MASK, STREAM_SKEYE_MASK, self.stream_period_s)
            self._keepalive(vehicle)
        except CommandRejected as exc:
            vehicle.close()
            event = LinkEvent.TURNED_AWAY if exc.code == ResultCode.BUSY else LinkEvent.FAILED
            self._fire(event, exc.reason)
            return None
        except (SkeyeError, OSError) as exc:
            vehicle.close()
            self._fire(LinkEvent.FAILED, str(exc))
            return None
        with self._lock:
            self._vehicle = vehicle
            self._connects += 1
        with self._lock:
            self._last_error = ""  # connected now: an old failure is no longer the news
        self._fire(LinkEvent.UP, "")
        return vehicle

    def _keepalive(self, vehicle: Vehicle) -> None:
        t0 = time.perf_counter()
        vehicle.poll(KEEPALIVE_MASK)
        with self._lock:
            self._round_trip_s = time.perf_counter() - t0

    def _supervise(self, vehicle: Vehicle) -> None:
        while not self._stop.wait(self.keepalive_s):
            if not vehicle.connected:
                self._fire(LinkEvent.LOST, f"{self.uri}: the vehicle closed the link")
                return
            try:
                self._keepalive(vehicle)
            except (LinkTimeout, CommandRejected) as exc:
                log.info("keep-alive failed: %s", exc)
            except (LinkClosed, SkeyeError, OSError) as exc:
                self._fire(LinkEvent.LOST, str(exc))
                return
            last = self._last_packet_s
            if last is not None and self._clock() - last > self.stale_s:
                self._fire(LinkEvent.LOST, f"no packet for {self.stale_s:g} s")
                return

    def _drop(self, vehicle: Vehicle) -> None:
        vehicle.close()
        with self._lock:
            if self._vehicle is vehicle:
                self._vehicle = None
            # What the lost vehicle last said is not its state now: the page shows no telemetry
            # (and the link's state and error) until a vehicle speaks again.
            self._latest.clear()
            self._pad_offset = None
            self._vehicle_info = None
            self._seq += 1
            self._frame_errors_closed += vehicle.frame_errors
            self._garbage_closed += vehicle.parser.garbage_bytes
            self._round_trip_s = None


def _code_name(code: int) -> str:
    try:
        return ResultCode(code).name
    except ValueError:
        return f"CODE_{code}"
