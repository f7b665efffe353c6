"""Start ``skeye`` commands as child processes and learn where they listen.

Every server prints its address on stdout once it listens (``control protocol on 127.0.0.1:N``,
``image server on ...``, ``ground control on tcp://...``); :func:`start_skeye` waits for those
lines, returns their regex matches, and then keeps draining the child's output so it never
blocks on a full pipe. Used by ``skeye validate`` and the benchmarks.

No child outlives its parent: every child started here (and by ``skeye up``) asks the kernel
for SIGTERM when its parent dies (Linux ``PR_SET_PDEATHSIG``, set between fork and exec, so it
holds even when the parent is SIGKILLed), every child is stopped by an ``atexit`` hook if the
parent exits without stopping it, and :func:`stop_processes` stops a group of children with one
shared deadline: SIGTERM to all, then SIGKILL to whoever is left.

Also here: :func:`machine_scale` and :func:`scaled_s`, which stretch a wall-clock safety
deadline with the machine's load (``skeye validate`` and its calibration wait on sim time where
they can; what is left is a guard against a child that stopped making progress);
:func:`check_ports_free` (``skeye up`` and ``skeye pilot`` check their ports before
starting anything) and :class:`ParentWatch` (``skeye up`` stops when ``make run`` is signalled).
"""

from __future__ import annotations

import atexit
import ctypes
import errno
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from typing import IO, Any

from skeye.errors import ConfigError, SkeyeError

EXIT_LOST_SIMULATOR = 4
"""``skeye pilot``'s exit status when it could not reach its simulator or the link failed before
it served (once serving, a lost simulator is a failsafe, not an exit): ``skeye up`` then waits
for the simulator's own exit status, the root cause."""

_PR_SET_PDEATHSIG = 1


TIMEOUT_SCALE_ENV = "SKEYE_TIMEOUT_SCALE"


def machine_scale() -> float:
    """How much slower than a quiet machine this one runs now: the one-minute load average per
    core, at least 1 (a quiet machine: 1; two busy loops on two cores: about 2). The
    environment variable ``SKEYE_TIMEOUT_SCALE`` (a number >= 1) sets it instead."""
    given = os.environ.get(TIMEOUT_SCALE_ENV)
    if given:
        try:
            value = float(given)
        except ValueError:
            raise ConfigError(f"{TIMEOUT_SCALE_ENV} must be a number, got {given!r}") from None
        if not (value >= 1.0 and value < 1e6):
            raise ConfigError(f"{TIMEOUT_SCALE_ENV} must be >= 1, got {given!r}")
        return value
    try:
        load = os.getloadavg()[0]
    except OSError:
        return 1.0
    return max(1.0, load / (os.cpu_count() or 1))


def scaled_s(base_s: float) -> float:
    """A wall-clock deadline of ``base_s`` on a quiet machine, stretched by :func:`machine_scale`
    (taken now: the load when the wait starts)."""
    return base_s * machine_scale()


def die_with_parent() -> Callable[[], None] | None:
    """A ``preexec_fn`` that makes the child get SIGTERM when this process dies (Linux; None
    elsewhere). If this process is already gone when the child runs it, the child stops."""
    if not sys.platform.startswith("linux"):
        return None
    parent = os.getpid()

    def preexec() -> None:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        if os.getppid() != parent:  # the parent died before the request took effect
            os.kill(os.getpid(), signal.SIGTERM)

    return preexec


def stop_processes(procs: Sequence[subprocess.Popen[Any]], timeout_s: float = 15.0) -> None:
    """SIGTERM every running process, wait for all with one deadline, SIGKILL the rest.

    Each SIGTERM is followed by a SIGCONT, as systemd does ("to ensure that even suspended
    tasks can be terminated cleanly", systemd.kill(5)): a stopped child (SIGSTOP, Ctrl-Z)
    keeps a SIGTERM it handles pending, and used to be waited for the whole ``timeout_s`` and
    then killed (``skeye up`` over a simulator stopped with SIGSTOP: 10 s, then SIGKILL)."""
    for proc in procs:
        if proc.poll() is None:
            try:
                proc.terminate()
                proc.send_signal(signal.SIGCONT)
            except OSError:
                pass
    deadline = time.monotonic() + timeout_s
    for proc in procs:
        try:
            proc.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


_children: list[subprocess.Popen[Any]] = []
_children_lock = threading.Lock()


def _stop_remaining_children() -> None:
    with _children_lock:
        left = [p for p in _children if p.poll() is None]
    stop_processes(left, timeout_s=10.0)


atexit.register(_stop_remaining_children)


def start_skeye(
    args: Sequence[str],
    patterns: Sequence[str],
    what: str,
    timeout_s: float = 180.0,
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
                            stderr=subprocess.STDOUT, text=True, errors="replace", env=child_env,
                            preexec_fn=die_with_parent())
    with _children_lock:
        _children[:] = [p for p in _children if p.poll() is None]
        _children.append(proc)
    assert proc.stdout is not None
    found: list[re.Match[str]] = []
    deadline = time.monotonic() + timeout_s
    seen: list[str] = []
    # readline() blocks while the child is silent: at the deadline the child is killed, which
    # ends the read, so a child that never prints the line fails here instead of hanging
    killer = threading.Timer(timeout_s, proc.kill)
    killer.daemon = True
    killer.start()
    try:
        while len(found) < len(patterns):
            line = proc.stdout.readline()
            if not line or time.monotonic() > deadline:
                proc.kill()
                proc.wait(5)
                proc.stdout.close()
                late = f" within {timeout_s:g} s" if time.monotonic() > deadline else ""
                said = " | ".join(text for text in (s.rstrip() for s in seen[-5:]) if text)
                raise SkeyeError(f"{what} did not start{late}: {said or 'no output'}")
            seen.append(line)
            m = re.search(patterns[len(found)], line)
            if m:
                found.append(m)
    finally:
        killer.cancel()
    threading.Thread(target=_drain, args=(proc.stdout,), name=f"drain-{what}",
                     daemon=True).start()
    return proc, found


def _drain(stream: IO[str]) -> None:
    """Read a child's output to its end (it never blocks on a full pipe), then close the pipe:
    its descriptor must not wait for the garbage collector."""
    with stream:
        stream.read()


def stop_process(proc: subprocess.Popen[str], timeout_s: float = 15.0) -> None:
    """SIGTERM, then SIGKILL if it has not exited within ``timeout_s``."""
    stop_processes([proc], timeout_s)


def port_in_use(host: str, port: int, what: str = "") -> bool:
    """Whether something already listens on ``host:port`` (a test bind; TIME_WAIT is free).

    Raises:
        ConfigError: ``host`` is not an address of this machine (or a name that does not
            resolve), or the port cannot be bound for another reason than being taken (one
            below 1024 without the privilege): "in use" would send the user the wrong way.
    """
    where = f"{host} for {what}" if what else host
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))  # port 0 too: it checks the host
        except socket.gaierror as exc:
            raise ConfigError(f"cannot listen on {where}: {host!r} is not an address or a name "
                              f"this machine resolves ({exc.strerror})") from None
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                return True
            if exc.errno == errno.EADDRNOTAVAIL:
                raise ConfigError(f"cannot listen on {where}: {host} is not an address of "
                                  "this machine (give one of its own: 127.0.0.1, or 0.0.0.0 "
                                  "for all)") from None
            raise ConfigError(f"cannot listen on {where}, port {port}: "
                              f"{exc.strerror or exc}") from None
    return False


def check_ports_free(ports: Sequence[tuple[str, str, int, str]]) -> None:
    """Check every ``(what, host, port, option)`` before anything starts.

    Raises:
        ConfigError: two of them share a port, or one is taken; the message names the port,
            what wanted it and the option that moves it.
        ConfigError: a host that is not this machine's (see :func:`port_in_use`).

    ``option`` is the option that moves the port (``--port``: "move it with --port PORT"), or
    its whole form when the port sits inside a value (``--ll-board R1=tcp:PORT``).
    """
    seen: dict[int, str] = {}
    for what, _, port, option in ports:
        if port and port in seen:
            raise ConfigError(
                f"port {port} is given to both {seen[port]} and {what}; move one with {option}"
            )
        seen[port] = f"{what} ({option})"
    for what, host, port, option in ports:
        move = option if "PORT" in option else f"{option} PORT"
        if port_in_use(host, port, what):
            raise ConfigError(
                f"port {port} on {host} (for {what}) is already in use - another skeye up or "
                f"server running? Stop it, or move {what} with {move}"
            )


_FATAL_SIGNALS = (signal.SIGHUP, signal.SIGINT, signal.SIGQUIT, signal.SIGTERM)


def _signal_mask(pid: int, field: str) -> int | None:
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith(field + ":"):
                    return int(line.split()[1], 16)
    except (OSError, ValueError):
        return None
    return None


class ParentWatch:
    """Notices when the process that started this one is going away.

    ``make`` catches SIGINT (and SIGTERM, SIGHUP, SIGQUIT) itself and then waits for its
    children without passing SIGINT on, so ``kill -INT <make's pid>`` would leave ``skeye up``
    and its servers running. GNU make's handler first resets the signal to its default
    disposition; this class reads the parent's caught-signal mask (Linux ``/proc``) and reports
    once a fatal signal that the parent used to catch is no longer caught, or once the parent
    has exited (this process was re-parented). Where ``/proc`` is missing it reports only the
    latter.
    """

    def __init__(self) -> None:
        self.pid = os.getppid()
        self._caught = _signal_mask(self.pid, "SigCgt")

    def stopping(self) -> str | None:
        """Why the parent is going away, or None while it is not."""
        if os.getppid() != self.pid:
            return f"parent process {self.pid} exited"
        if self._caught is None:
            return None
        now = _signal_mask(self.pid, "SigCgt")
        if now is None:
            return f"parent process {self.pid} exited"
        for sig in _FATAL_SIGNALS:
            bit = 1 << (sig - 1)
            if self._caught & bit and not now & bit:
                return f"parent process {self.pid} is handling {sig.name}"
        return None


def sleep_until(stop: threading.Event, seconds: float) -> bool:
    """``stop.wait(seconds)`` for the main thread when a signal handler sets ``stop``: it polls
    ``stop.is_set()`` (no lock) and never holds the Event's lock. A handler runs between the main
    thread's bytecodes, maybe while that thread holds the lock inside ``Event.wait``; its
    ``set()`` then waits for that lock for ever (a SIGTERM hung ``skeye sim`` so)."""
    end = time.monotonic() + seconds
    while not stop.is_set():
        left = end - time.monotonic()
        if left <= 0.0:
            return False
        time.sleep(min(left, 0.05))
    return True


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""The signals that stop a skeye server in order: Ctrl-C, SIGTERM, and SIGHUP (its terminal or
SSH session closed: a pilot started over SSH on a vehicle's computer stops as on Ctrl-C, its
recording closed and its airframe let go, where the default disposition killed it outright)."""


def on_stop_signals(handler: Callable[[int, Any], None]) -> dict[int, Any]:
    """Install ``handler`` for each of :data:`STOP_SIGNALS` and return the handlers it replaced.

    A SIGHUP this process was started ignoring is left ignored: ``nohup skeye sim`` keeps running
    when its terminal closes, as nohup promises. (SIGINT and SIGTERM are always taken: a shell
    starts a background job with SIGINT ignored, and ``kill -INT`` must still stop it.)"""
    before: dict[int, Any] = {}
    for sig in STOP_SIGNALS:
        if sig == signal.SIGHUP and signal.getsignal(sig) is signal.SIG_IGN:
            continue
        before[sig] = signal.signal(sig, handler)
    return before


def wait_for_signal(stop: threading.Event, failed: threading.Event | None = None) -> None:
    """Wait for a stop signal (:data:`STOP_SIGNALS`; or ``failed`` to be set)."""
    def handler(signum: int, frame: Any) -> None:
        stop.set()

    on_stop_signals(handler)
    while not sleep_until(stop, 0.2):
        if failed is not None and failed.is_set():
            return
