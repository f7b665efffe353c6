"""What the tests that drive skeye with MAVSDK-Python (unchanged, as a user's script does)
share: MAVSDK as a ground station listening where the vehicle sends, a wait on its telemetry,
and the vehicle's STATUSTEXTs. Import it after ``pytest.importorskip("mavsdk")``."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from mavsdk import ComponentType, Configuration, Mavsdk
from mavsdk.plugins.telemetry import Telemetry

METRES_PER_DEG_LAT = 111_320.0


def until(pred: Callable[[], bool], what: str, timeout_s: float = 120.0) -> None:
    """Wait for a condition of the vehicle's telemetry; the timeout is a stuck guard only."""
    deadline = time.monotonic() + timeout_s
    while not pred():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


@contextmanager
def ground_station(port: int, timeout_s: float = 60.0) -> Iterator[Any]:
    """MAVSDK as a ground station on ``udpin://127.0.0.1:PORT``; the first autopilot heard."""
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    with Mavsdk(config) as sdk:
        sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = sdk.first_autopilot(timeout_s)
        assert system is not None, "no autopilot heard"
        yield system


class StatusTexts:
    """The vehicle's STATUSTEXTs as MAVSDK hands them over (subscribed at construction)."""

    def __init__(self, telemetry: Telemetry) -> None:
        self.texts: list[str] = []
        self._changed = threading.Condition()
        # Kept: a plugin collected by the garbage collector ends its subscriptions, and callers
        # write StatusTexts(Telemetry(system)) (the texts stopped coming whenever a collection
        # ran after the constructor, depending on what else the process allocated).
        self.telemetry = telemetry
        telemetry.subscribe_status_text(self._on_text)

    def _on_text(self, status: Any, _user_data: Any) -> None:
        with self._changed:
            self.texts.append(status.text)
            self._changed.notify_all()

    def seen(self, part: str, timeout_s: float) -> str | None:
        """The first text holding ``part``, waited for up to ``timeout_s``; None if none."""
        def found() -> str | None:
            return next((t for t in self.texts if part in t), None)

        with self._changed:
            self._changed.wait_for(lambda: found() is not None, timeout_s)
            return found()

    def wait_for(self, part: str, timeout_s: float = 10.0) -> str:
        """The first text holding ``part``, waited for up to ``timeout_s`` (a stuck guard)."""
        text = self.seen(part, timeout_s)
        assert text is not None, f"no STATUSTEXT with {part!r}; got {self.texts}"
        return text
