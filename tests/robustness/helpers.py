"""Shared helpers of the robustness tests: resource counts and a simulator process."""

from __future__ import annotations

import os
import re
import resource
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from skeye.processes import die_with_parent, stop_process


def open_fds() -> int:
    """File descriptors this process holds (Linux /proc)."""
    return len(os.listdir("/proc/self/fd"))


def wait_for(predicate: Callable[[], bool], timeout_s: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


def stopped_at_its_first_line(args: list[str], sig: int = signal.SIGTERM
                              ) -> tuple[int, str, str]:
    """Start ``python -m skeye.cli ARGS``, send it ``sig`` the moment its first stdout line is
    read (as a script stops a server on reading its address), and let it end; returns (status,
    stdout, stderr). The first line must say where it listens."""
    proc = subprocess.Popen([sys.executable, "-m", "skeye.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True,
                            preexec_fn=die_with_parent())
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()  # blocks until its first line (or its end)
        assert " on " in first, first
        proc.send_signal(sig)
        rest, err = proc.communicate(timeout=120)
    finally:
        stop_process(proc)  # type: ignore[arg-type]
    return proc.returncode, first + rest, err


def thread_count() -> int:
    return threading.active_count()


@contextmanager
def sim_process(
    *extra: str, max_file_bytes: int | None = None
) -> Iterator[tuple[subprocess.Popen[str], dict[str, int], list[str]]]:
    """``skeye sim --port 0 ...`` as a child process; yields (process, ports, banner lines).

    ``max_file_bytes`` limits the size of any file it writes (``ulimit -f``: a write past it
    fails with EFBIG, as on a full disk)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    env.setdefault("MUJOCO_GL", "egl")
    die = die_with_parent()

    def preexec() -> None:
        if die is not None:
            die()
        if max_file_bytes is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (max_file_bytes, max_file_bytes))
    proc = subprocess.Popen(
        [sys.executable, "-m", "skeye.cli", "sim", "--port", "0", *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
        cwd=Path(__file__).resolve().parents[2],
        preexec_fn=preexec,
    )
    ports: dict[str, int] = {}
    banner: list[str] = []
    try:
        assert proc.stdout is not None
        while True:
            line = proc.stdout.readline()
            if not line:
                raise RuntimeError(f"simulator exited: {banner}")
            banner.append(line.strip())
            if m := re.search(r"control protocol on [\d.]+:(\d+)", line):
                ports["control"] = int(m.group(1))
            if m := re.search(r"image server on [\d.]+:(\d+)", line):
                ports["image"] = int(m.group(1))
            if "bound to" in line or "all interfaces" in line:
                break
        yield proc, ports, banner
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)
        if proc.stdout is not None:
            proc.stdout.close()


def skeye_under_a_file_size_limit(args: list[str], limit_bytes: int
                                  ) -> subprocess.CompletedProcess[str]:
    """``python -m skeye ARGS`` in a child whose files cannot grow past ``limit_bytes``
    (RLIMIT_FSIZE, ``ulimit -f``): a write past it fails with EFBIG, as one on a full disk does.
    Its output is captured as text."""

    def small_files() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    return subprocess.run(
        [sys.executable, "-m", "skeye", *args], capture_output=True, text=True,
        cwd=Path(__file__).resolve().parents[2],
        env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"), preexec_fn=small_files, check=False)
