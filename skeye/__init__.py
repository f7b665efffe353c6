"""skeye: a distributed development environment for small unmanned aerial vehicles."""

from typing import TYPE_CHECKING

from skeye import native as _native

_native.install()  # before any simulator module: compiled or source (see skeye.native)

from skeye.errors import (  # noqa: E402
    CommandRejected,
    ConfigError,
    InvalidArgument,
    LinkClosed,
    LinkTimeout,
    LocalProtocolError,
    PhysicsError,
    RemoteProtocolError,
    SkeyeError,
    UnknownName,
)

if TYPE_CHECKING:
    from skeye.control import connect

__version__ = "0.1.0"


def __getattr__(name: str) -> object:
    """``skeye.connect`` without importing the control interface (numpy, OpenCV) up front."""
    if name == "connect":
        from skeye.control import connect

        return connect
    raise AttributeError(f"module 'skeye' has no attribute {name!r}")


__all__ = [
    "CommandRejected",
    "ConfigError",
    "InvalidArgument",
    "LinkClosed",
    "LinkTimeout",
    "LocalProtocolError",
    "PhysicsError",
    "RemoteProtocolError",
    "SkeyeError",
    "UnknownName",
    "__version__",
    "connect",
]
