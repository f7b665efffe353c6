"""Shared argparse ``type=`` validators for every ``skeye`` sub-command.

A bad value is refused while the command line is parsed: argparse prints one line naming the
option (``skeye sim: error: argument --port: must be a port 0..65535, got '-1'``) and exits
with status 2, before anything starts. Each validator raises
:class:`argparse.ArgumentTypeError` with what the option takes and what it got; none of them
imports anything beyond the standard library (and :mod:`skeye.values`, which does not either), so
the parser stays cheap to build.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Sequence
from pathlib import Path

from skeye.values import MAX_BAUD, baud_rate

MAX_PORT = 65535
EXTRA_OF = {"mujoco": "sim", "matplotlib": "sim", "rich": "sim", "fastapi": "ground",
            "uvicorn": "ground", "pymavlink": "mavlink", "av": "mavlink"}
"""A dependency that lives in an extra (pyproject.toml) -> the extra's name."""


def not_installed(modules: Sequence[str]) -> str:
    """What a command that imports ``modules`` (each a key of :data:`EXTRA_OF`) lacks, in the
    words ``skeye`` says when an import fails (``rich is not installed: this command needs
    skeye's sim extra (pip install 'skeye[sim]'; ...)``), or '' when every one is there. A
    command asks this before it makes anything, rather than failing at the import later; a
    module is looked up, not imported (MuJoCo's import takes a while)."""
    from importlib.util import find_spec

    return missing_extra([module for module in modules if find_spec(module) is None])


def missing_extra(missing: Sequence[str]) -> str:
    """What ``skeye`` says of modules of its extras that are not installed (each a key of
    :data:`EXTRA_OF`; '' for none): their names, the extras and the pip command."""
    if not missing:
        return ""
    extras = list(dict.fromkeys(EXTRA_OF[module] for module in missing))
    named = ", ".join(missing[:-1]) + " and " + missing[-1] if len(missing) > 1 else missing[0]
    install = ",".join(extras)
    return (f"{named} {'is' if len(missing) == 1 else 'are'} not installed: this command "
            f"needs skeye's {' and '.join(extras)} extra{'s' if len(extras) > 1 else ''} (pip "
            f"install 'skeye[{install}]'; the base install is the onboard pilot's, "
            "docs/onboard.md)")


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number, got {text!r}") from None


def _float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def _port(text: str, lowest: int) -> int:
    value = _int(text)
    if not lowest <= value <= MAX_PORT:
        raise argparse.ArgumentTypeError(f"must be a port {lowest}..{MAX_PORT}, got {text!r}")
    return value


def port(text: str) -> int:
    """A TCP/UDP port 0..65535 (0: any free one, where the option's help says so)."""
    return _port(text, 0)


def fixed_port(text: str) -> int:
    """A port 1..65535: one that others are told to connect to, so not 0 ("any free")."""
    return _port(text, 1)


def seed(text: str) -> int:
    """A random seed: a non-negative whole number."""
    value = _int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a non-negative whole number, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """A whole number >= 1 (a count of workers, seeds, clients, a baud rate)."""
    value = _int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}")
    return value


def baud(text: str) -> int:
    """A serial line's baud rate: a whole number 1..4000000, the rule of every ``baud=`` in a
    URI (:func:`skeye.values.baud_rate`); ``--baud 99999999999`` went to the serial port."""
    value = baud_rate(text)
    if value is None:
        raise argparse.ArgumentTypeError(f"must be a whole number 1..{MAX_BAUD}, got {text!r}")
    return value


def _float_from(text: str, bound: float, inclusive: bool) -> float:
    value = _float(text)
    if value < bound or (value == bound and not inclusive):
        raise argparse.ArgumentTypeError(
            f"must be a number {'>=' if inclusive else '>'} {bound:g}, got {text!r}")
    return value


def path(text: str) -> str:
    """A file or folder name: not empty (``--out ''`` was the current folder, written into;
    ``--robot-dir ''`` the current folder searched; ``--record ''`` "recording . is a
    directory")."""
    if not text:
        raise argparse.ArgumentTypeError("must name a file or folder, got ''")
    return text


def file_path(text: str) -> Path:
    """:func:`path` as a ``Path``."""
    return Path(path(text))


def positive_float(text: str) -> float:
    """A finite number > 0 (a timeout or period in seconds, a rate in Hz)."""
    return _float_from(text, 0.0, inclusive=False)


def non_negative_float(text: str) -> float:
    """A finite number >= 0 (0 has a meaning the option's help gives)."""
    return _float_from(text, 0.0, inclusive=True)


def float_at_least(low: float, why: str) -> Callable[[str], float]:
    """An argparse type: a finite number >= ``low``, the refusal saying ``why`` that is the
    least (a benchmark's run shorter than one sample measures nothing)."""
    def check(text: str) -> float:
        value = _float(text)
        if not value >= low:
            raise argparse.ArgumentTypeError(f"must be a number >= {low:g} ({why}), got "
                                             f"{text!r}")
        return value
    return check
