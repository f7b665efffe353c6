"""The engine thread: the only way other threads touch a :class:`~skeye.sim.engine.Simulation`.

How this works: :class:`SimulationRunner` owns one thread that steps the simulation and runs
tasks. It paces the clock: ``realtime`` follows the wall clock (slipping, and saying so, if it
falls behind); ``lockstep`` advances only when a task steps it (the control server's ``STEP``).
Everything that changes the world (spawn, remove, drive, wind) is a task executed on the engine
thread between steps, so the order of effects is the order of commands, and a lockstep run is
reproducible.

The engine never stops silently: an exception escaping a step (or a task submitted as
``fatal``, like a lockstep ``STEP``) ends the engine thread, is kept in
:attr:`SimulationRunner.error`, fails every queued and later task at once, and is handed to each
of :attr:`SimulationRunner.failure_listeners` (the control server tells every client).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, TypeVar

from skeye.errors import LocalProtocolError, SkeyeError
from skeye.sim.engine import Simulation
from skeye.workers import Worker, WorkerFailed

log = logging.getLogger(__name__)
T = TypeVar("T")

MAX_LAG_S = 0.5
"""In realtime, how far the sim time may fall behind the wall clock before the clock slips (it
then resumes 20 ms behind, and ``behind_events`` counts the slip) rather than run a burst."""


class SimulationRunner:
    """Owns the engine thread; the only way other threads touch a :class:`Simulation`."""

    def __init__(self, sim: Simulation, mode: str = "realtime") -> None:
        if mode not in ("realtime", "lockstep"):
            raise LocalProtocolError(f"mode must be 'realtime' or 'lockstep', got {mode!r}")
        self.sim = sim
        self.mode = mode
        self._tasks: queue.Queue[tuple[Callable[[Simulation], Any], Future[Any], bool] | None] = (
            queue.Queue()
        )
        self._stop = threading.Event()
        self.behind_events = 0
        self.wall_start = time.monotonic()
        self.sim_start_s = sim.time_s
        # Why the engine thread died (None while it runs or after a clean stop).
        self.error: WorkerFailed | None = None
        self.failed = threading.Event()
        # Called once, on the dying engine thread, with the failure; must not block.
        self.failure_listeners: list[Callable[[WorkerFailed], None]] = []
        self._fatal: BaseException | None = None
        self._engine = Worker(self._run, "skeye-engine", on_error=self._on_engine_error)
        self._engine.start()

    def __enter__(self) -> SimulationRunner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self, timeout_s: float = 5.0) -> None:
        if self._stop.is_set():
            return
        self._stop.set()
        self._tasks.put(None)
        self._engine.join(timeout_s)

    @property
    def alive(self) -> bool:
        """The engine thread runs and has not failed."""
        return self._engine.alive and not self.failed.is_set()

    def _on_engine_error(self, exc: BaseException) -> None:
        self.error = WorkerFailed("the simulation engine", exc)
        self.failed.set()
        self._drain()
        for listener in list(self.failure_listeners):
            try:
                listener(self.error)
            except Exception:
                log.exception("engine failure listener %r failed", listener)

    def _refusal(self) -> SkeyeError:
        if self.error is not None:
            return self.error
        return SkeyeError("the simulator is shutting down")

    def submit(self, fn: Callable[[Simulation], T], *, fatal: bool = False) -> Future[T]:
        """Run ``fn(sim)`` on the engine thread between steps. With ``fatal``, an exception
        from ``fn`` also ends the engine (for tasks that step the physics)."""
        fut: Future[T] = Future()
        if self._stop.is_set() or self.failed.is_set():
            fut.set_exception(self._refusal())
            return fut
        self._tasks.put((fn, fut, fatal))
        if self.failed.is_set():  # it died between the check and the put
            self._drain()
        return fut

    def call(self, fn: Callable[[Simulation], T], timeout_s: float = 30.0, *,
             fatal: bool = False) -> T:
        """Run ``fn(sim)`` on the engine thread and return its result.

        Raises:
            TimeoutError: the engine did not take the task up within ``timeout_s`` (busy: in
                lockstep, another client's long STEP): it is withdrawn and never runs, so the
                caller's error is the whole truth; or, once begun, it took ``timeout_s`` more.
        """
        fut = self.submit(fn, fatal=fatal)
        try:
            return fut.result(timeout_s)
        except TimeoutError:
            if fut.cancel():
                raise TimeoutError(
                    f"the simulator did not take it up within {timeout_s:g} s (busy: another "
                    "client's long STEP?); not done") from None
        try:
            return fut.result(timeout_s)  # it had begun: it runs between steps, so it ends
        except TimeoutError:
            raise TimeoutError(
                f"the simulator is still at it after {2 * timeout_s:g} s") from None

    def _run_task(self, item: tuple[Callable[[Simulation], Any], Future[Any], bool]) -> None:
        fn, fut, fatal = item
        if not fut.set_running_or_notify_cancel():
            return
        try:
            fut.set_result(fn(self.sim))
        except BaseException as exc:  # delivered to the caller; ends the engine only if fatal
            fut.set_exception(exc)
            if fatal and not isinstance(exc, SkeyeError):
                raise

    def _run(self) -> None:
        if self.mode == "lockstep":
            while True:
                item = self._tasks.get()
                if item is None:
                    break
                self._run_task(item)
            self._drain()
            return
        sim = self.sim
        dt = sim.dt
        self.wall_start = time.monotonic()
        self.sim_start_s = sim.time_s
        while not self._stop.is_set():
            while True:
                try:
                    item = self._tasks.get_nowait()
                except queue.Empty:
                    break
                if item is None:
                    self._drain()
                    return
                self._run_task(item)
            target = self.sim_start_s + (time.monotonic() - self.wall_start)
            due = int((target - sim.time_s) / dt)
            if due <= 0:
                # Wait for the next step's wall time, waking at once for a command.
                wait = sim.time_s + dt - target
                try:
                    item = self._tasks.get(timeout=max(0.0001, min(0.002, wait)))
                except queue.Empty:
                    continue
                if item is None:
                    break
                self._run_task(item)
                continue
            if due * dt > MAX_LAG_S:
                # Too far behind: slip the clock rather than run a burst.
                self.behind_events += 1
                if self.behind_events == 1 or self.behind_events % 100 == 0:
                    log.warning(
                        "simulation is running slower than real time (slipped %d times)",
                        self.behind_events,
                    )
                self.wall_start += due * dt - 0.02
                due = int(0.02 / dt)
            sim.step(min(due, max(1, int(0.01 / dt))))
        self._drain()

    def _drain(self) -> None:
        while True:
            try:
                item = self._tasks.get_nowait()
            except queue.Empty:
                return
            if item is not None and not item[1].done():
                item[1].set_exception(self._refusal())

    def realtime_factor(self) -> float:
        wall = time.monotonic() - self.wall_start
        return (self.sim.time_s - self.sim_start_s) / wall if wall > 0 else 0.0
