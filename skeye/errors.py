"""One error hierarchy for the whole project, split by whose fault it is."""

from __future__ import annotations


class SkeyeError(Exception):
    """Base class of every error skeye raises on purpose."""


class LocalProtocolError(SkeyeError):
    """Our caller broke a protocol or API rule (a malformed command, a bad argument)."""


class RemoteProtocolError(SkeyeError):
    """The peer sent something that breaks the protocol."""


class ConfigError(SkeyeError):
    """A configuration file or value is wrong; the message names the file and the key."""


class PhysicsError(SkeyeError):
    """The simulation diverged (NaN, runaway state); the robot is stopped."""


class CommandRejected(SkeyeError):
    """The vehicle or simulator refused a command; ``code`` says why in the protocol's terms."""

    def __init__(self, reason: str, code: int | None = None) -> None:
        super().__init__(reason if code is None else f"{reason} (code {code})")
        self.reason = reason
        self.code = code


class LinkTimeout(SkeyeError):
    """A link or peer did not answer within its deadline."""


class AnswerLost(LinkTimeout):
    """An answer came corrupted (a bad frame in its place), so it will not come: said at once
    instead of at the deadline, on a line that carries only answers (an AscTec LL board's)."""


class VehicleLost(SkeyeError):
    """The vehicle below a pilot stopped answering (its HEALTH says LOST: the simulator gone or
    frozen), so what was waited for cannot come until it is back."""


class LinkClosed(SkeyeError):
    """A link is gone (closed locally, by the peer, or broken); nothing more can be sent or
    received. Raised by every client: the simulator connection, the image client, the vehicle
    link (:mod:`skeye.link.transport`)."""


class UnknownHost(LinkClosed):
    """A link's host name that does not resolve (no such name, or no DNS answer): nothing
    listens there to start, since there is no there."""


class PeerClosed(LinkClosed):
    """The peer ended the connection in order (end of stream, a serial line hung up)."""


class InvalidArgument(LocalProtocolError, ValueError):
    """A caller passed a value out of range or of the wrong kind; also a ``ValueError``, so code
    that catches that keeps working."""


class UnknownName(ConfigError, KeyError):
    """A name that is not in its table (a pad, a robot class); also a ``KeyError``."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""
