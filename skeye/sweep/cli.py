"""``skeye sweep SPEC.toml --out DIR [--backend local|ray] [--address ADDR] [--workers N]``.

How this works: the spec expands to trials (:mod:`skeye.sweep.spec`); those whose rows already
exist in ``DIR/trials`` without an error are skipped; the rest go to the backend, and each row
is stored the moment it comes back. On a terminal a rich progress bar shows trials done, failed
and running and the time left; elsewhere (a log file, a batch job) one line per finished trial
says the same. At the end the tables and the report are written from every row of the spec.
SIGTERM or SIGHUP stop a sweep as Ctrl-C does: the running trials are killed, their temporary
folders removed, and the stored rows kept (rerun to resume).
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from skeye import cliargs
from skeye.cliargs import not_installed
from skeye.errors import ConfigError
from skeye.outputs import folder_lock, output_folder
from skeye.sweep.backends import Backend, check_backend, make_backend
from skeye.sweep.results import ResultStore, write_report, write_tables
from skeye.sweep.spec import SweepSpec, load_spec
from skeye.sweep.worker import stop_running_trials


@dataclass
class SweepResult:
    rows: list[dict[str, Any]] = field(default_factory=list)  # one per trial of the spec
    ran: int = 0  # trials run by this invocation
    skipped: int = 0  # trials whose rows existed already
    failed: int = 0


def run_trials(spec: SweepSpec, out: Path, backend: Backend, label: str = "sweep",
               show_progress: bool = True) -> SweepResult:
    """Run the spec's missing trials on ``backend``; rows stored as they arrive."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    store = ResultStore(out)
    todo = [t for t in spec.trials if not store.done(t.key)]
    result = SweepResult(skipped=len(spec.trials) - len(todo))
    counts = {"failed": 0, "running": 0}
    on_terminal = show_progress and sys.stderr.isatty()
    progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                        TextColumn("failed {task.fields[failed]}, running {task.fields[running]}"),
                        TimeElapsedColumn(), TextColumn("left"), TimeRemainingColumn(),
                        disable=not on_terminal, transient=False)
    start = time.monotonic()

    def log_line(text: str) -> None:  # off a terminal the bar is silent: plain lines instead
        if show_progress and not on_terminal:
            print(f"[{time.monotonic() - start:7.0f} s] {label}: {text}", file=sys.stderr,
                  flush=True)

    log_line(f"{len(todo)} trials to run, {result.skipped} done before, on {backend.workers} "
             "worker(s)")
    with progress:
        task = progress.add_task(f"{label}: {len(todo)} to run, {result.skipped} done before",
                                 total=len(todo), failed=0, running=0)

        def on_running(n: int) -> None:
            counts["running"] = n
            progress.update(task, running=n)

        for row in backend.run([t.to_json() for t in todo], on_running):
            try:
                store.put(row)
            except ConfigError as exc:  # a full disk: the running trials' rows would be lost
                # too, so they are not waited for (an hour each, maybe)
                stopped = stop_running_trials()
                raise ConfigError(f"{exc}; stopped ({stopped} running trial(s) killed)"
                                  ) from None
            result.ran += 1
            if row.get("error"):
                counts["failed"] += 1
            progress.update(task, advance=1, failed=counts["failed"])
            left = len(todo) - result.ran
            eta = (time.monotonic() - start) / result.ran * left
            outcome = f"failed: {row['error']}" if row.get("error") else "ok"
            log_line(f"{result.ran}/{len(todo)} trial {row['key']} (seed {row.get('seed')}) "
                     f"{outcome} in {row.get('wall_s', 0):.0f} s; {counts['failed']} failed, "
                     f"{counts['running']} running, about {eta:.0f} s left")
    result.failed = counts["failed"]
    result.rows = [r for t in spec.trials if (r := store.get(t.key)) is not None]
    return result


def sweep(spec_path: Path, out: Path, backend_name: str = "local", address: str | None = None,
          workers: int | None = None, quick: bool | None = None, show_progress: bool = True
          ) -> SweepResult:
    """Run a sweep spec and write results.csv/.parquet and report.md into ``out``. What
    cannot run (a missing extra, Ray for ``--backend ray``, a bad ``--address``) is refused
    before ``out`` is made."""
    spec = load_spec(spec_path, quick)
    check_backend(backend_name, address, workers)
    missing = not_installed(sweep_needs(spec))
    if missing:
        raise ConfigError(missing)
    output_folder(out)
    with folder_lock(out, "skeye sweep"):  # two there ran every trial twice, racing on rows
        start = time.monotonic()
        backend = make_backend(backend_name, address, workers, spec.cpus, spec.gpus)
        try:
            result = run_trials(spec, out, backend, spec.name, show_progress)
        except ConfigError as exc:  # a row could not be stored: the others are
            raise ConfigError(f"{exc}; the rows stored before are kept in {out / 'trials'} "
                              "(rerun to resume)") from None
        finally:
            backend.close()
        write_tables(out, result.rows, spec.param_names)
        write_report(out, spec, result.rows, backend_name, time.monotonic() - start)
    return result


def sweep_needs(spec: SweepSpec) -> tuple[str, ...]:
    """The modules of an extra that running ``spec`` imports: rich (the progress), MuJoCo
    (the simulator, for E1 and E2; a flight script brings its own imports), and matplotlib
    when a parameter takes several values (the report plots the figures against it)."""
    needs = ["rich"]
    if any(t.experiment in ("E1", "E2") for t in spec.trials):
        needs.append("mujoco")
    if any(len({repr(t.params.get(p)) for t in spec.trials}) > 1 for p in spec.param_names):
        needs.append("matplotlib")
    return tuple(needs)


@contextmanager
def stop_cleanly_on_signals() -> Iterator[None]:
    """Ctrl-C (SIGINT), SIGTERM and SIGHUP end the run with a KeyboardInterrupt through the
    ``finally`` blocks, after killing the running trials, so none outlives the sweep and every
    temporary folder is removed. SIGINT too: Python's own KeyboardInterrupt left the trials
    running (each in a process group of its own, out of the terminal's reach), and the pool's
    shutdown waited for them to end by themselves. A signal the sweep was started ignoring stays
    ignored (``nohup`` ignores SIGHUP; a shell's background job, SIGINT). Only in the main
    thread (where Python delivers signals)."""

    def stop(signum: int, frame: Any) -> None:
        stop_running_trials()
        raise KeyboardInterrupt(f"stopped by signal {signal.Signals(signum).name}")

    before = {sig: signal.signal(sig, stop)
              for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
              if signal.getsignal(sig) is not signal.SIG_IGN}
    try:
        yield
    except KeyboardInterrupt:
        stop_running_trials()
        raise
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)


def cmd_sweep(args: argparse.Namespace) -> int:
    try:
        with stop_cleanly_on_signals():
            result = sweep(Path(args.spec), Path(args.out), args.backend, args.address,
                           args.workers, True if args.quick else None)
    except KeyboardInterrupt as exc:
        print(f"skeye sweep: {str(exc) or 'interrupted'}; the finished trials are kept in "
              f"{args.out}/trials (rerun to resume)", file=sys.stderr)
        return 130
    print(f"{len(result.rows)} trials: {result.ran} run now, {result.skipped} from earlier runs, "
          f"{result.failed} failed; results in {args.out}/results.csv, report in "
          f"{args.out}/report.md", file=sys.stderr)
    return 1 if result.failed else 0


def register(sub: Any) -> None:
    p = sub.add_parser("sweep", help="run an experiment over a grid of parameters and seeds",
                       description="Run the trials of SPEC.toml (docs/sweeps.md) on a local "
                                   "process pool or a Ray cluster; rerun to resume.")
    p.add_argument("spec", help="sweep specification (TOML)")
    p.add_argument("--out", type=cliargs.path, required=True,
                   help="output folder (rerun with it to resume)")
    p.add_argument("--backend", choices=("local", "ray"), default="local")
    p.add_argument("--address", default=None,
                   help="Ray cluster to join (auto, or HOST:PORT); none starts a local one")
    p.add_argument("--workers", type=cliargs.positive_int, default=None,
                   help="trials at a time (local), CPUs of the local Ray cluster")
    p.add_argument("--quick", action="store_true", help="shortened runs, whatever the spec says")
    p.set_defaults(func=cmd_sweep)
