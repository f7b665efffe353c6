"""One trial in its own process group: ``python -m skeye.sweep.worker TRIAL.json RESULT.json``.

How this works: :func:`run_trial_process` (called by a local pool thread or inside a Ray task)
starts this module as a child in a new session, so the trial and everything it starts (``skeye
sim``, ``skeye pilot``) form one process group that is killed as a whole on a timeout. The child
runs the experiment (:func:`run_experiment`) with the ground client in its own main thread, writes
its figures to RESULT.json (atomically) and exits. It watches its stdin, a pipe from the parent:
if the parent dies (a Ray worker killed mid-trial) the pipe closes and the child kills its whole
group, so a retried trial never races a leftover simulator. Whatever goes wrong (a crash, a
timeout, an exception in the flight) becomes a row with ``error`` set, never an exception here.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import math
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import skeye
from skeye.errors import SkeyeError
from skeye.sweep.spec import Trial

LOG_TAIL_LINES = 8

# Trial process groups running now in this process (their pids), so that a sweep stopped by a
# signal can end them at once: each waiting thread then cleans up its temporary folder. A trial
# is started and entered here under the lock, and a stop marks the run stopped under it: a stop
# that came while a trial thread was starting its process (its temporary folder made, the
# process not yet entered) found nothing to kill, and the pool's shutdown then waited for that
# trial to end by itself. The lock is re-entrant: the stop runs in a signal handler, which may
# interrupt the main thread inside this module's own ``with _running_lock``.
_running: set[int] = set()
_running_lock = threading.RLock()
_stopped = False  # a stop came: trials not yet started are not started


def stop_running_trials() -> int:
    """Kill every trial process group this process is running; how many there were. Trials
    not yet started are not started until :func:`trials_allowed` opens a new run."""
    global _stopped
    with _running_lock:
        _stopped = True
        pids = list(_running)
    for pid in pids:
        try:
            os.killpg(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return len(pids)


@contextmanager
def trials_allowed() -> Iterator[None]:
    """A run of trials: trials may start (again) inside it, until a stop; after it, a stop
    made during it no longer refuses the trials of a later run in this process."""
    global _stopped
    with _running_lock:
        _stopped = False
    try:
        yield
    finally:
        with _running_lock:
            _stopped = False


def _figures_only(figures: dict[str, Any]) -> dict[str, float]:
    return {k: v for k, v in figures.items() if k != "seed"}


def run_experiment(trial: Trial, workdir: Path) -> tuple[dict[str, float], dict[str, Any]]:
    """Run the trial's experiment here; its figures and its series (for ``skeye validate``)."""
    from skeye.validate.experiments import e1_runs, e2_runs
    from skeye.validate.report import add_uncalibrated, e1_figures, e2_figures

    settings = trial.settings()
    if trial.experiment == "E1":
        e1 = e1_runs(settings, workdir)
        figures = e1_figures(e1["E1"], trial.seed)
        if "E1_uncalibrated" in e1:
            add_uncalibrated(figures, e1_figures(e1["E1_uncalibrated"], trial.seed))
        return _figures_only(figures), {k: dataclasses.asdict(v) for k, v in e1.items()}
    if trial.experiment == "E2":
        e2 = e2_runs(settings, workdir)
        figures = e2_figures(e2["E2"], e2["E2_velocity"], e2["E2_attitude"], settings)
        return _figures_only(figures), {k: dataclasses.asdict(v) for k, v in e2.items()}
    assert trial.script is not None
    spec = importlib.util.spec_from_file_location("skeye_sweep_script", trial.script)
    if spec is None or spec.loader is None:
        raise SkeyeError(f"cannot load flight script {trial.script}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    entry = getattr(module, "trial", None)
    if not callable(entry):
        raise SkeyeError(f"{trial.script} has no function trial(settings, params, workdir)")
    figures = entry(settings, dict(trial.params), workdir)
    if not isinstance(figures, dict) or not all(
            isinstance(k, str) and isinstance(v, int | float) and not isinstance(v, bool)
            for k, v in figures.items()):
        raise SkeyeError(f"{trial.script}: trial() must return a dict of figure name -> number, "
                         f"got {figures!r}")
    _check_script_figures(trial, figures)
    return _figures_only(figures), {}


INT64_MAX = 2**63 - 1  # the tables' integer columns (parquet's int64)


def _check_script_figures(trial: Trial, figures: dict[str, int | float]) -> None:
    """A script's figures may not take the name of a column its row already has (the trial's
    key, a parameter, the run's host...: the figure replaced it, and a figure named ``key``
    stored the row under another trial's name), and an integer figure must fit the tables'
    64 bits (a larger one ended the sweep, after every trial, in a traceback)."""
    from skeye.sweep.results import FIXED, TAIL

    own = [c for c in dict.fromkeys([*FIXED, *trial.params, *TAIL]) if c != "seed"]
    taken = [k for k in figures if k in own]  # a seed is dropped, as E1's and E2's is
    if taken:
        raise SkeyeError(
            f"{trial.script}: trial() returned figures named {', '.join(taken)}, which name "
            f"columns the row has already (the trial's {', '.join(own)}): "
            "rename them")
    big = [k for k, v in figures.items() if isinstance(v, int) and abs(v) > INT64_MAX]
    if big:
        raise SkeyeError(f"{trial.script}: trial() returned integer figures beyond 64 bits "
                         f"({', '.join(big)}): return them as floats, or smaller")


def base_row(trial: Trial) -> dict[str, Any]:
    return {"key": trial.key, "experiment": trial.experiment, **trial.params,
            "seed": trial.seed, "quick": trial.quick}


def run_trial_process(trial_json: dict[str, Any], workdir: str | None = None,
                      series_file: str | None = None) -> dict[str, Any]:
    """Run one trial in a child process group; its result row (``error`` set on failure)."""
    trial = Trial.from_json(trial_json)
    row = base_row(trial)
    start = time.monotonic()
    error = ""
    figures: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="skeye-trial-") as tmp:
        trial_file, result_file, log_file = (Path(tmp) / n for n in
                                             ("trial.json", "result.json", "log.txt"))
        trial_file.write_text(json.dumps(trial_json))
        args = [sys.executable, "-m", "skeye.sweep.worker", str(trial_file), str(result_file),
                workdir or str(Path(tmp) / "work"), series_file or ""]
        with _running_lock, open(log_file, "w") as log:
            if _stopped:
                return _finished(row, trial, start,
                                 "stopped: the run was stopped before this trial started")
            proc = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=log,
                                    stderr=subprocess.STDOUT, start_new_session=True)
            _running.add(proc.pid)
        try:
            proc.wait(trial.timeout_s)
        except subprocess.TimeoutExpired:
            error = f"timeout: the trial ran longer than {trial.timeout_s:g} s"
        finally:
            try:
                os.killpg(proc.pid, signal.SIGKILL)  # the trial and its sim and pilot
            except ProcessLookupError:
                pass
            proc.wait()
            with _running_lock:
                _running.discard(proc.pid)
            if proc.stdin is not None:
                proc.stdin.close()
        if result_file.exists():
            result = json.loads(result_file.read_text())
            figures, error = result["figures"], result["error"] or error
        elif not error:
            tail = log_file.read_text().splitlines()[-LOG_TAIL_LINES:]
            error = f"trial process exited with code {proc.returncode}: " + " | ".join(tail)
    row.update(figures)
    return _finished(row, trial, start, error)


def _finished(row: dict[str, Any], trial: Trial, start: float, error: str) -> dict[str, Any]:
    row.update(wall_s=round(time.monotonic() - start, 3), host=socket.gethostname(),
               skeye_version=skeye.__version__, code_version=trial.code, error=error)
    return row


def one_line(text: str) -> str:
    """``text`` on one line: its non-blank lines, trimmed, joined with `` | `` (a row's error
    is one line of the sweep's log and one cell of the report's table)."""
    return " | ".join(line.strip() for line in text.splitlines() if line.strip())


def _die_with_parent() -> None:
    """Block until the parent's pipe closes, then kill this whole process group.

    Reads the pipe's descriptor itself, not ``sys.stdin``: a thread blocked in a buffered read
    holds the stream's lock, which the interpreter takes to shut down, so every trial process
    ended in an abort (SIGABRT, ``Fatal Python error: _enter_buffered_busy``), whatever its own
    exit status."""
    fd = sys.stdin.fileno()
    try:
        while os.read(fd, 65536):
            pass
    finally:
        os.killpg(os.getpgid(0), signal.SIGKILL)


def main(argv: list[str]) -> int:
    trial_file, result_file, workdir, series_file = argv
    threading.Thread(target=_die_with_parent, name="parent-watch", daemon=True).start()
    trial = Trial.from_json(json.loads(Path(trial_file).read_text()))
    figures: dict[str, float] = {}
    error = ""
    series: dict[str, Any] = {}
    try:  # a working folder that cannot be made (a file in its place) is the trial's error too
        Path(workdir).mkdir(parents=True, exist_ok=True)
        figures, series = run_experiment(trial, Path(workdir))
    except Exception as exc:  # a failed flight is a row with its error, not a crash
        error = one_line(f"{type(exc).__name__}: {exc}")
    clean: dict[str, float | None] = {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v)
        for k, v in figures.items()}
    if series_file and series:
        Path(series_file).write_text(json.dumps(series))
    tmp = Path(result_file + ".tmp")
    tmp.write_text(json.dumps({"figures": clean, "error": error}))
    tmp.replace(result_file)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
