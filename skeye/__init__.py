"""skeye: a distributed development environment for small unmanned aerial vehicles."""

from skeye.errors import (
    CommandRejected,
    ConfigError,
    LinkTimeout,
    LocalProtocolError,
    PhysicsError,
    RemoteProtocolError,
    SkeyeError,
)

__version__ = "0.1.0"

__all__ = [
    "CommandRejected",
    "ConfigError",
    "LinkTimeout",
    "LocalProtocolError",
    "PhysicsError",
    "RemoteProtocolError",
    "SkeyeError",
    "__version__",
]
