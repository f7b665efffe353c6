"""Start ``skeye`` commands as child processes and learn where they listen.

Every server prints its address on stdout once it listens (``control protocol on 127.0.0.1:N``,
``image server on ...``, ``ground control on tcp://...``); :func:`start_skeye` waits for those
lines, returns their regex matches, and then keeps draining the child's output so it never
blocks on a full pipe. Used by ``skeye validate`` and the benchmarks.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
from collections.abc import Mapping, Sequence

from skeye.errors import SkeyeError


def start_skeye(
    args: Sequence[str],
    patterns: Sequence[str],
    what: str,
    timeout_s: float = 60.0,
    env: Mapping[str, str] | None = None,
) -> tuple[subprocess.Popen[str], list[re.Match[str]]]:
    """Start ``python -m skeye.cli ARGS``; wait for a stdout line matching each pattern, in order.
    ``env`` adds to (or overrides) this process's environment.

    Raises:
        SkeyeError: the child exited or took longer than ``timeout_s``; the message quotes its
            last output lines.
    """
    child_env = dict(os.environ, PYTHONUNBUFFERED="1")
    child_env.setdefault("MUJOCO_GL", "egl")
    child_env.update(env or {})
    proc = subprocess.Popen([sys.executable, "-m", "skeye.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=child_env)
    assert proc.stdout is not None
    found: list[re.Match[str]] = []
    deadline = time.monotonic() + timeout_s
    seen: list[str] = []
    while len(found) < len(patterns):
        line = proc.stdout.readline()
        if not line or time.monotonic() > deadline:
            proc.kill()
            proc.wait(5)
            raise SkeyeError(f"{what} did not start: {''.join(seen[-5:]) or 'no output'}")
        seen.append(line)
        m = re.search(patterns[len(found)], line)
        if m:
            found.append(m)
    stdout = proc.stdout
    threading.Thread(target=stdout.read, name=f"drain-{what}", daemon=True).start()
    return proc, found


def stop_process(proc: subprocess.Popen[str], timeout_s: float = 15.0) -> None:
    """SIGTERM, then SIGKILL if it has not exited within ``timeout_s``."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)
