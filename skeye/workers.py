"""Worker threads whose failures reach their owner.

How this works: a :class:`Worker` is a daemon thread running one target. If the target raises,
the exception is kept (:attr:`Worker.error`), logged with its traceback, put on the owner's
error queue when one was given (as Gymnasium's ``AsyncVectorEnv`` workers report to their
parent through an error queue), and handed to the ``on_error`` callback, which runs on the
dying worker's thread and must not block. A failing callback is logged, never re-raised. So no
thread of skeye dies silently: the owner learns of it at once (callback) or when it next looks
(:meth:`Worker.check`, the queue).

Stopping: :meth:`Worker.stop` sets :attr:`Worker.stopping` (a target that loops watches it) and
calls the ``on_stop`` callback, which wakes a target blocked elsewhere (closes its socket,
notifies its condition); :meth:`Worker.join` waits with a deadline and says whether the thread
ended. Joining from the worker's own thread returns at once.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable
from typing import Any

from skeye.errors import SkeyeError

log = logging.getLogger(__name__)

ErrorQueue = queue.Queue[tuple[str, BaseException]]


class WorkerFailed(SkeyeError):
    """A worker thread stopped on an exception; the message names the worker and the cause."""

    def __init__(self, worker: str, cause: BaseException) -> None:
        super().__init__(f"{worker} failed: {type(cause).__name__}: {cause}")
        self.worker = worker
        self.cause = cause


class Worker:
    """A daemon thread whose exception reaches its owner (see the module comment).

    Args:
        target: what the thread runs; its return value is ignored.
        name: the thread's name, used in messages.
        on_error: called once with the exception if ``target`` raises.
        errors: a queue that receives ``(name, exception)`` if ``target`` raises.
        args: positional arguments for ``target``.
        on_stop: called by :meth:`stop` to wake the target (it must not block).
    """

    def __init__(
        self,
        target: Callable[..., Any],
        name: str,
        *,
        on_error: Callable[[BaseException], None] | None = None,
        errors: ErrorQueue | None = None,
        args: tuple[Any, ...] = (),
        on_stop: Callable[[], None] | None = None,
    ) -> None:
        self.name = name
        self.error: BaseException | None = None
        self.stopping = threading.Event()
        """Set by :meth:`stop`: the target should return soon."""
        self._on_stop = on_stop
        self._target = target
        self._args = args
        self._on_error = on_error
        self._errors = errors
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> Worker:
        self._thread.start()
        return self

    def _run(self) -> None:
        try:
            self._target(*self._args)
        except BaseException as exc:
            self.error = exc
            log.error("worker thread %s failed", self.name, exc_info=exc)
            if self._errors is not None:
                self._errors.put_nowait((self.name, exc))
            if self._on_error is not None:
                try:
                    self._on_error(exc)
                except Exception:
                    log.exception("error callback of worker %s failed", self.name)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def is_alive(self) -> bool:
        """As :meth:`threading.Thread.is_alive`."""
        return self._thread.is_alive()

    @property
    def thread(self) -> threading.Thread:
        return self._thread

    def stop(self) -> None:
        """Ask the target to end (idempotent): set :attr:`stopping`, call ``on_stop``."""
        self.stopping.set()
        if self._on_stop is not None:
            try:
                self._on_stop()
            except Exception:
                log.exception("stop callback of worker %s failed", self.name)

    def join(self, timeout_s: float | None = None) -> bool:
        """Wait up to ``timeout_s`` for the thread to end; True when it has (or never started).

        From the worker's own thread it returns at once (False: the thread is still running).
        """
        if self._thread is threading.current_thread():
            return False
        if self._thread.is_alive():
            self._thread.join(timeout_s)
        return not self._thread.is_alive()

    def check(self) -> None:
        """Raise :class:`WorkerFailed` if the target raised."""
        if self.error is not None:
            raise WorkerFailed(self.name, self.error) from self.error
