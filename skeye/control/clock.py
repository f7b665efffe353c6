"""Who moves time: the wall clock (realtime simulator) or the client itself (lockstep).

How this works: motion control runs one *control tick* per control period (compute PI outputs,
send a ``DRIVE``). The clock decides when:

- :class:`RealtimeClock` owns a control thread that ticks every period of wall time; callers
  that wait for a motion sleep on a condition the thread signals after each tick.
- :class:`LockstepClock` has no thread. Whoever waits steps the simulator: at each period
  boundary it ticks, then sends ``STEP`` for (the rest of) one period and waits for its answer,
  which arrives after every message those steps produced. Control therefore sees exactly the
  readings up to the tick's sim time, and a run is repeatable bit for bit.

Invariants: the control period is an integer multiple of the physics step (checked up front);
every wait has a wall-clock deadline (LinkTimeout) and ends early with the link's error.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from skeye.errors import ConfigError, LinkTimeout, LocalProtocolError, SkeyeError
from skeye.workers import Worker

MAX_RUN_FOR_S = 86_400.0
"""The most sim time one call lets pass or holds a command for (``run_for``, ``step``,
``set_velocity``'s ``duration_s``): a day, far beyond what the robot files' batteries (2100 and
4000 mAh) fly; a longer run is several calls. Without a bound a finite but huge value (1e300 s)
would step for ever."""

log = logging.getLogger(__name__)

Tick = Callable[[], None]
ErrorSource = Callable[[], SkeyeError | None]


def period_steps(control_rate_hz: float, time_step_s: float) -> int:
    """Physics steps per control period; ConfigError unless it is a whole number."""
    if not control_rate_hz > 0 or not time_step_s > 0:
        raise ConfigError(
            f"control rate ({control_rate_hz} Hz) and time step ({time_step_s} s) must be > 0"
        )
    steps = round(1.0 / (control_rate_hz * time_step_s))
    if steps < 1 or abs(steps * time_step_s * control_rate_hz - 1.0) > 1e-6:
        raise ConfigError(
            f"the control period 1/{control_rate_hz:g} s is not a whole number of physics "
            f"steps of {time_step_s:g} s"
        )
    return steps


class Clock:
    """Common interface: ``advance`` moves sim time, ``wait_until`` blocks on a predicate."""

    mode = ""

    def __init__(self, tick: Tick, error: ErrorSource, period_s: float) -> None:
        self._tick = tick
        self._error = error
        self.period_s = period_s

    def _check(self) -> None:
        err = self._error()
        if err is not None:
            raise err

    def advance(self, seconds: float) -> None:
        """Let ``seconds`` of sim time pass, control ticks included."""
        raise NotImplementedError

    def advance_period(self) -> None:
        """Let (the rest of) one control period pass."""
        raise NotImplementedError

    def wait_until(self, predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
        """Block until ``predicate()`` holds; LinkTimeout after ``timeout_s`` of wall time."""
        raise NotImplementedError

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop the clock's thread, if any (idempotent)."""


class RealtimeClock(Clock):
    """The wall clock paces the simulator; a control thread ticks every period."""

    mode = "realtime"

    def __init__(self, tick: Tick, error: ErrorSource, period_s: float) -> None:
        super().__init__(tick, error, period_s)
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self.ticks = 0
        self._thread = Worker(self._run, "skeye-control-motion").start()

    def _run(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            try:
                self._tick()
            except Exception:  # the tick reports motion errors itself; this is a last resort
                log.exception("control tick failed")
            with self._cond:
                self.ticks += 1
                self._cond.notify_all()
            next_t += self.period_s
            delay = next_t - time.monotonic()
            if delay < -self.period_s:  # fell behind: do not burst
                next_t = time.monotonic()
                delay = 0.0
            self._stop.wait(max(0.0, delay))

    def poke(self) -> None:
        """Wake waiters now (the link died, a motion was cancelled)."""
        with self._cond:
            self._cond.notify_all()

    def advance(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while True:
            self._check()
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return
            with self._cond:
                self._cond.wait(min(remaining, self.period_s))

    def advance_period(self) -> None:
        self.advance(self.period_s)

    def wait_until(self, predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while True:
            if predicate():
                return
            self._check()
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise LinkTimeout(f"{what}: not done within {timeout_s:g} s")
            with self._cond:
                self._cond.wait(min(remaining, self.period_s))

    def close(self, timeout_s: float = 2.0) -> None:
        self._stop.set()
        self.poke()
        self._thread.join(timeout_s)


class LockstepClock(Clock):
    """The client steps the simulator: one control tick at each period boundary.

    Args:
        step: sends ``STEP {Count n}`` and returns once its answer arrived.
        steps_per_period: physics steps per control period.
    """

    mode = "lockstep"

    def __init__(
        self,
        tick: Tick,
        error: ErrorSource,
        step: Callable[[int], float],
        time_step_s: float,
        steps_per_period: int,
    ) -> None:
        super().__init__(tick, error, steps_per_period * time_step_s)
        self._step = step
        self.time_step_s = time_step_s
        self.steps_per_period = steps_per_period
        self._phase = 0  # physics steps into the current control period
        self._lock = threading.RLock()

    def advance_steps(self, count: int) -> None:
        """Advance ``count`` physics steps, ticking control at every period boundary."""
        if count < 0:
            raise LocalProtocolError(f"cannot step {count} steps")
        with self._lock:
            while count > 0:
                self._check()
                if self._phase == 0:
                    self._tick()
                n = min(count, self.steps_per_period - self._phase)
                self._step(n)
                self._phase = (self._phase + n) % self.steps_per_period
                count -= n

    def advance(self, seconds: float) -> None:
        if seconds < 0:
            raise LocalProtocolError(f"cannot advance {seconds} s")
        self.advance_steps(round(seconds / self.time_step_s))

    def advance_period(self) -> None:
        with self._lock:
            self.advance_steps(self.steps_per_period - self._phase)

    def wait_until(self, predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                raise LinkTimeout(f"{what}: not done within {timeout_s:g} s of wall time")
            self.advance_period()
