"""What a robot needs of its connection: the small interface between the two.

How this works: :class:`~skeye.control.connection.Connection` makes a
:class:`~skeye.control.robots.Robot` in ``spawn`` and then feeds it from its message thread
through the robot's public link-facing methods (``configure``, ``await_first_readings``,
``on_sensor``, ``on_status``, ``on_error``, ``link_down``, ``control_tick``, ``close``). The
robot, in turn, sees its connection only as a :class:`RobotHost`, defined here, so the robot
modules never import the connection module and the two do not form an import circle.
"""

from __future__ import annotations

from typing import Any, Protocol

from skeye.errors import SkeyeError

from .clock import Clock
from .image_client import ImageClient


class RobotHost(Protocol):
    """The connection as a robot sees it (``Connection`` implements it)."""

    mode: str
    """``"lockstep"`` or ``"realtime"``."""
    timeout_s: float
    time_s: float
    """The newest sim time seen on the link."""
    silent_s: float
    """How long the link's reader has waited without a byte from the simulator."""
    images_address: tuple[str, int] | None
    clock: Clock

    @property
    def error(self) -> SkeyeError | None:
        """Why the link is down, or None while it is up."""
        ...

    def check(self) -> None:
        """Raise the link's error if it is down."""
        ...

    def send(self, type_word: str, *fields: tuple[str, object],
             timeout_s: float | None = None) -> None:
        """Queue one command line."""
        ...

    def send_message(self, message: Any, timeout_s: float | None = None) -> None:
        """Queue one typed command (a :mod:`skeye.wire.sim_messages` dataclass)."""
        ...

    def request_message(self, message: Any, timeout_s: float | None = None) -> Any:
        """Send one typed command and wait for its typed answer."""
        ...

    def image_client(self) -> ImageClient:
        """A new client of the simulator's image server."""
        ...
