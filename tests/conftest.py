"""Suite-wide safety net: no process a test started survives the test session.

Tests stop their own children (context managers, fixture finalizers); children started through
:mod:`skeye.processes` also die with this process (PR_SET_PDEATHSIG) and are stopped at exit.
This finalizer catches whatever is left anyway, stops it (SIGTERM, a deadline, SIGKILL) and
says so, so a leak shows up as a warning instead of a process running for hours."""

from __future__ import annotations

import os
import signal
import time
import warnings
from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, settings

# Hypothesis times each example against a wall-clock deadline (200 ms) and flags slow data
# generation: both fail on a busy host for reasons that are not the code's. Property tests here
# check correctness, never speed (speed lives in benchmarks/).
settings.register_profile(
    "skeye", deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile("skeye")

# SIGHUP at its default in this process and every child it starts: a suite started under
# `nohup` (SIGHUP ignored, inherited) made every skeye process keep ignoring it, as nohup
# promises (skeye.processes.on_stop_signals), and the tests that stop one with SIGHUP failed.
signal.signal(signal.SIGHUP, signal.SIG_DFL)


def child_pids(pid: int) -> list[int]:
    """The direct children of ``pid`` (Linux /proc; empty elsewhere)."""
    out: list[int] = []
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except FileNotFoundError:
        return out
    for task in tasks:
        try:
            with open(f"/proc/{pid}/task/{task}/children") as f:
                out += [int(p) for p in f.read().split()]
        except FileNotFoundError:
            pass
    return out


def _running(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, IndexError):
        return False


@pytest.fixture(scope="session", autouse=True)
def own_cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """What skeye keeps in the user's cache (``skeye up``'s camera calibration) goes to the
    run's own folder: tests never write in the home directory, and start from nothing. The
    run's pytest-xdist workers share it, as two ``skeye up`` of one user share theirs: the
    calibration is made once a run, not once a worker (10 s of CPU each)."""
    before = os.environ.get("XDG_CACHE_HOME")
    if os.environ.get("PYTEST_XDIST_WORKER"):  # the run's folder, above each worker's own
        shared = tmp_path_factory.getbasetemp().parent / "xdg-cache"
        shared.mkdir(exist_ok=True)
        os.environ["XDG_CACHE_HOME"] = str(shared)
    else:
        os.environ["XDG_CACHE_HOME"] = str(tmp_path_factory.mktemp("xdg-cache"))
    yield
    if before is None:
        os.environ.pop("XDG_CACHE_HOME", None)
    else:
        os.environ["XDG_CACHE_HOME"] = before


@pytest.fixture(scope="session", autouse=True)
def no_orphans() -> Iterator[None]:
    yield
    left = [pid for pid in child_pids(os.getpid()) if _running(pid)]
    if not left:
        return
    warnings.warn(f"processes left running by the tests, stopped now: {left}", stacklevel=1)
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in left:
            try:
                os.kill(pid, sig)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and any(_running(p) for p in left):
            time.sleep(0.1)
