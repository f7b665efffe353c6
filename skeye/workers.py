"""Worker threads whose failures reach their owner.

How this works: a :class:`Worker` is a daemon thread running one target. If the target raises,
the exception is kept (:attr:`Worker.error`), logged with its traceback, put on the owner's
error queue when one was given (as Gymnasium's ``AsyncVectorEnv`` workers report to their
parent through an error queue), and handed to the ``on_error`` callback, which runs on the
dying worker's thread and must not block. A failing callback is logged, never re-raised. So no
thread of skeye dies silently: the owner learns of it at once (callback) or when it next looks
(:meth:`Worker.check`, the queue).
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
    """

    def __init__(
        self,
        target: Callable[..., Any],
        name: str,
        *,
        on_error: Callable[[BaseException], None] | None = None,
        errors: ErrorQueue | None = None,
        args: tuple[Any, ...] = (),
    ) -> None:
        self.name = name
        self.error: BaseException | None = None
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

    def join(self, timeout_s: float | None = None) -> None:
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)

    def check(self) -> None:
        """Raise :class:`WorkerFailed` if the target raised."""
        if self.error is not None:
            raise WorkerFailed(self.name, self.error) from self.error
