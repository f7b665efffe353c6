"""Where trials run: a local pool (default) or a Ray cluster (``pip install skeye[ray]``).

How this works: both backends take trials as JSON-able dicts and yield result rows as each trial
finishes, in completion order; each trial runs through
:func:`skeye.sweep.worker.run_trial_process` (its own process group, free loopback ports of the
machine it runs on), so the two give the same figures for the same trial.

- ``LocalBackend``: at most ``workers`` trials at a time on this machine (threads that each wait
  on one trial process).
- ``RayBackend``: one Ray task per trial, asking for ``cpus`` (and ``gpus``) per trial, retried
  up to ``max_retries`` times when its worker or node dies; ``address`` joins a running cluster
  (``auto``, or ``HOST:PORT``), none starts a private local one (loopback only, no dashboard).
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from importlib.util import find_spec
from types import TracebackType
from typing import Any, Protocol

from skeye.errors import LocalProtocolError
from skeye.sweep.worker import base_row, run_trial_process, trials_allowed

Row = dict[str, Any]
OnStart = Callable[[int], None]  # the number of trials running now: before each wait, and
# after it, before the finished trials' rows are yielded


class Backend(Protocol):
    workers: int

    def run(self, trials: list[dict[str, Any]], on_running: OnStart | None = None
            ) -> Iterator[Row]: ...

    def close(self) -> None: ...


class _Closing:
    """``with backend:`` closes it on any exit."""

    def close(self) -> None:
        pass

    def __enter__(self) -> _Closing:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


class LocalBackend(_Closing):
    """A pool of ``workers`` trial processes on this machine."""

    def __init__(self, workers: int | None = None, keep: Callable[[dict[str, Any]], dict[str, str]]
                 | None = None) -> None:
        self.workers = workers or max(1, (os.cpu_count() or 2) // 2)
        if self.workers < 1:
            raise LocalProtocolError(f"--workers must be >= 1, got {self.workers}")
        self.keep = keep  # trial -> extra run_trial_process arguments (validate's series)

    def run(self, trials: list[dict[str, Any]], on_running: OnStart | None = None
            ) -> Iterator[Row]:
        with trials_allowed(), ThreadPoolExecutor(max_workers=self.workers,
                                                  thread_name_prefix="trial") as pool:
            pending: set[Future[Row]] = set()
            queue = list(trials)
            while queue or pending:
                submitted = False
                while queue and len(pending) < self.workers:
                    t = queue.pop(0)
                    extra = self.keep(t) if self.keep else {}
                    pending.add(pool.submit(run_trial_process, t, **extra))
                    submitted = True
                if on_running and submitted:  # else the count is the one said after the wait
                    on_running(len(pending))
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                if on_running:
                    on_running(len(pending))  # the finished ones are no longer running
                for fut in done:
                    yield fut.result()


RAY_MISSING = "the Ray backend needs Ray: pip install 'skeye[ray]'"

RAY_CONNECT_TIMEOUT_S = 5.0
"""How long ``--address HOST:PORT`` may take to accept a TCP connection."""


def check_ray_address(address: str) -> None:
    """``--address`` is ``auto`` (Ray finds the cluster), a Ray Client ``ray://`` URI (Ray
    checks it), or ``HOST:PORT`` where something listens: Ray's own client retries an
    unreachable address for minutes (``--address 127.0.0.1:1`` hung past 5 minutes), and a
    malformed one was a ValueError traceback.

    Raises:
        LocalProtocolError: naming the address, and what to give instead.
    """
    if address == "auto" or address.startswith("ray://"):
        return
    host, sep, port_text = address.rpartition(":")
    host = host.removeprefix("[").removesuffix("]")
    if not sep or not host or not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
        raise LocalProtocolError(
            f"--address must be auto or HOST:PORT (a Ray cluster's head, as `ray start --head "
            f"--port 6379` makes it), got {address!r}")
    try:
        with socket.create_connection((host, int(port_text)), timeout=RAY_CONNECT_TIMEOUT_S):
            pass
    except OSError as exc:
        raise LocalProtocolError(
            f"--address {address}: no Ray cluster answers there ({exc.strerror or exc}); start "
            f"one with `ray start --head --port {port_text}` on {host}, or give --address auto "
            "on a machine of a running cluster") from None


def _ray_trial(trial: dict[str, Any]) -> Row:
    return run_trial_process(trial)


class RayBackend(_Closing):
    """One Ray task per trial on a cluster (joined, or started here on loopback)."""

    def __init__(self, address: str | None = None, workers: int | None = None, cpus: float = 1.0,
                 gpus: float = 0.0, max_retries: int = 3) -> None:
        try:
            import ray
        except ImportError:
            raise LocalProtocolError(RAY_MISSING) from None
        self.ray = ray
        self.cpus, self.gpus, self.max_retries = cpus, gpus, max_retries
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # nothing leaves this machine
        # Trials see their node's environment (MUJOCO_GL, SKEYE_PURE_PYTHON, ...).
        if address:
            check_ray_address(address)
            try:
                ray.init(address=address, log_to_driver=False)
            except (ValueError, ConnectionError) as exc:  # Ray's words for a bad address
                raise LocalProtocolError(f"--address {address}: {exc}") from None
        else:
            ray.init(num_cpus=workers or max(1, (os.cpu_count() or 2) // 2), num_gpus=0,
                     include_dashboard=False, _node_ip_address="127.0.0.1",
                     object_store_memory=100 * 1024 * 1024, log_to_driver=False)
        self.workers = int(ray.cluster_resources().get("CPU", 1) // max(cpus, 1e-9))
        self._remote = ray.remote(_ray_trial).options(
            num_cpus=cpus, num_gpus=gpus, max_retries=max_retries, retry_exceptions=False)

    def run(self, trials: list[dict[str, Any]], on_running: OnStart | None = None
            ) -> Iterator[Row]:
        ray = self.ray
        refs = {self._remote.remote(t): t for t in trials}
        if on_running and refs:
            on_running(min(len(refs), self.workers))
        while refs:
            done, _ = ray.wait(list(refs), num_returns=1)
            trial = refs.pop(done[0])
            if on_running:
                on_running(min(len(refs), self.workers))  # the finished one no longer runs
            try:
                yield ray.get(done[0])
            except ray.exceptions.RayError as exc:  # retries used up, node lost for good
                from skeye.sweep.spec import Trial

                row = base_row(Trial.from_json(trial))
                row["error"] = f"ray: {type(exc).__name__}: {str(exc).splitlines()[0]}"
                yield row

    def close(self) -> None:
        """Disconnect (and stop the cluster if this started it); idempotent."""
        if self.ray.is_initialized():
            self.ray.shutdown()


def check_backend(name: str, address: str | None, workers: int | None) -> None:
    """What :func:`make_backend` would refuse, checked without starting anything (Ray is
    looked up, not imported; ``--address`` by :func:`check_ray_address`, which the Ray backend
    runs again as it joins), so a command can say it before it makes its output folder.

    Raises:
        LocalProtocolError: naming the option, or the extra that is missing.
    """
    _check_choice(name, address, workers)
    if name == "local":
        return
    if find_spec("ray") is None:
        raise LocalProtocolError(RAY_MISSING)
    if address:
        check_ray_address(address)


def make_backend(name: str, address: str | None, workers: int | None, cpus: float = 1.0,
                 gpus: float = 0.0) -> Backend:
    _check_choice(name, address, workers)
    if name == "local":
        return LocalBackend(workers)
    return RayBackend(address, workers, cpus, gpus)


def _check_choice(name: str, address: str | None, workers: int | None) -> None:
    """The backend's name, ``--address`` (Ray's alone) and ``--workers``, as given."""
    if workers is not None and workers < 1:
        raise LocalProtocolError(f"--workers must be >= 1, got {workers}")
    if name == "local":
        if address:
            raise LocalProtocolError("--address is for --backend ray")
    elif name != "ray":
        raise LocalProtocolError(f"unknown backend {name!r}: local or ray")
