"""The bytes the pilot sends one ground client, sent by that client's own thread.

How this works: the pilot's loop and its reader never write to a ground link themselves (a
client that stops reading would block them: the loop would stop ticking, and in lockstep the
simulator's clock with it). They ``put`` encoded packets into the client's ``Outbox``; one
sender thread alone calls ``link.send``. The queue is bounded in bytes:

- streamed telemetry (``droppable=True``) is dropped when the queue holds ``max_bytes`` or
  more, and counted (``dropped``, ``dropped_bytes``): a slow client gets fewer frames, never
  stale ones in a growing queue;
- answers to the client's own commands are always queued, up to ``hard_max_bytes``; beyond
  that the client is closed (it sends commands and reads nothing);
- a send that the peer does not take within the link's send timeout (``TcpLink``:
  ``send_timeout_s``) closes the link: the client is gone as far as the vehicle is concerned,
  and the boards' link-loss failsafe applies as for any lost ground station.

Nothing here touches the boards or the vehicle: ground-link trouble is never vehicle trouble.
"""

from __future__ import annotations

import logging
import threading
from collections import deque

from skeye.errors import InvalidArgument, LinkTimeout
from skeye.link.transport import Link, LinkClosed
from skeye.workers import Worker

log = logging.getLogger(__name__)

DEFAULT_MAX_BYTES = 64 * 1024
DEFAULT_HARD_MAX_BYTES = 1024 * 1024


class Outbox:
    """A bounded send queue and its sender thread for one link (a context manager).

    Args:
        link: the client's link; closed here when the client stops taking bytes.
        max_bytes: above this, droppable packets are dropped.
        hard_max_bytes: above this, the client is closed.
    """

    def __init__(
        self,
        link: Link,
        *,
        max_bytes: int = DEFAULT_MAX_BYTES,
        hard_max_bytes: int = DEFAULT_HARD_MAX_BYTES,
    ) -> None:
        if not 0 < max_bytes <= hard_max_bytes:
            raise InvalidArgument(
                f"need 0 < max_bytes <= hard_max_bytes, got {max_bytes}, {hard_max_bytes}"
            )
        self.link = link
        self.max_bytes = max_bytes
        self.hard_max_bytes = hard_max_bytes
        self.dropped = 0
        self.dropped_bytes = 0
        self.sent_bytes = 0
        self.close_reason = ""
        self._queue: deque[bytes] = deque()
        self._queued_bytes = 0
        self._cond = threading.Condition()
        self._closed = False
        self._thread = Worker(self._run, f"pilot-send-{link.name}")

    def start(self) -> Outbox:
        self._thread.start()
        return self

    @property
    def queued_bytes(self) -> int:
        return self._queued_bytes

    def put(self, data: bytes, *, droppable: bool) -> bool:
        """Queue ``data``; False when it was dropped (or the outbox is closed)."""
        if not data:
            return True
        with self._cond:
            if self._closed:
                return False
            if droppable and self._queued_bytes >= self.max_bytes:
                self.dropped += 1
                self.dropped_bytes += len(data)
                return False
            if self._queued_bytes + len(data) > self.hard_max_bytes:
                overflow = True
            else:
                overflow = False
                self._queue.append(data)
                self._queued_bytes += len(data)
                self._cond.notify()
        if overflow:
            self._give_up(f"over {self.hard_max_bytes} bytes of answers not read")
            return False
        return True

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop the sender (idempotent); the link is left to its owner."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(timeout_s)

    def __enter__(self) -> Outbox:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _give_up(self, reason: str) -> None:
        with self._cond:
            if not self.close_reason:
                self.close_reason = reason
            self._closed = True
            self._queue.clear()
            self._queued_bytes = 0
            self._cond.notify_all()
        log.warning("ground control on %s: %s; closing that link", self.link.name, reason)
        self.link.close()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._closed:
                    self._cond.wait(1.0)
                if self._closed:
                    return
                chunks = list(self._queue)
                self._queue.clear()
                size = self._queued_bytes
                self._queued_bytes = 0
            try:
                self.link.send(b"".join(chunks))
                self.sent_bytes += size
            except LinkTimeout as exc:
                self._give_up(f"stopped reading ({exc})")
                return
            except LinkClosed:
                with self._cond:
                    self._closed = True
                return
