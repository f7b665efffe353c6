"""``skeye sweep``: a small E2 sweep (2 F_max values x 2 seeds, quick, 1 s holds) on the local
pool and on a real Ray cluster on loopback (a worker killed mid-trial), identical figures per
trial; resuming runs only what is missing; failed trials are rows."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from skeye.sweep.cli import sweep

# Real flights (two process stacks per trial): generous on a busy 2-core machine.
pytestmark = pytest.mark.timeout(1200)

SPEC = """
name = "test sweep"
experiment = "E2"
quick = true
seeds = {seeds}
[grid]
f_max_n = {forces}
wind = ["random_force"]
e2_duration_s = [1.0]
vision_latency = ["40"]
"""
# A fixed detector latency (ms of sim time): the default, "measured", takes each detection's
# wall-clock processing time, so on a busy machine the figures would follow the load (a run
# with two busy test workers gave a mean 5 um off the local backend's); fixed, a trial repeats
# bit for bit on any backend.
FIGURES = ("mean_m", "std_m", "max_m", "final_m", "duration_s", "samples", "velocity_mean_m",
           "velocity_std_m", "velocity_max_m", "velocity_final_m", "attitude_mean_m",
           "attitude_std_m", "attitude_max_m", "attitude_final_m")


def _spec(tmp: Path, seeds: str = "[1, 2]", name: str = "spec.toml",
          forces: str = "[0.1, 0.4]") -> Path:
    path = tmp / name
    path.write_text(SPEC.format(seeds=seeds, forces=forces))
    return path


@pytest.fixture(scope="module")
def local_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[tuple, dict]]:
    tmp = tmp_path_factory.mktemp("sweep")
    out = tmp / "local"
    result = sweep(_spec(tmp), out, "local", workers=2, show_progress=False)
    assert (result.ran, result.skipped, result.failed) == (4, 0, 0)
    rows = {(r["f_max_n"], r["seed"]): r for r in result.rows}
    return out, rows


def test_local_sweep_writes_one_row_per_trial_and_a_report(local_run):
    out, rows = local_run
    assert sorted(rows) == [(0.1, 1), (0.1, 2), (0.4, 1), (0.4, 2)]
    for row in rows.values():
        assert row["error"] == "" and row["quick"] is True and row["e2_duration_s"] == 1.0
        assert row["wall_s"] > 0 and row["host"] and row["skeye_version"]
        for name in FIGURES:
            assert isinstance(row[name], int | float), name
        assert 0 < row["mean_m"] <= row["max_m"] < 0.5
    # Different seeds (and forces) fly differently.
    assert rows[0.1, 1]["mean_m"] != rows[0.1, 2]["mean_m"] != rows[0.4, 2]["mean_m"]
    with open(out / "results.csv") as f:
        table = list(csv.DictReader(f))
    assert len(table) == 4 and {"f_max_n", "seed", "mean_m", "wall_s", "host", "error"} <= set(
        table[0])
    for t in table:
        assert float(t["mean_m"]) == rows[float(t["f_max_n"]), int(t["seed"])]["mean_m"]
    pq = pytest.importorskip("pyarrow.parquet")
    assert pq.read_table(out / "results.parquet").num_rows == 4
    report = (out / "report.md").read_text()
    assert "## by f_max_n" in report and "plot_f_max_n.png" in report
    assert (out / "plot_f_max_n.png").stat().st_size > 0
    assert "## by seed" not in report and "e2_duration_s" not in report.split("## by")[1]
    # The run's descriptors (series length) are rows, not figures to summarise or plot.
    assert "duration_s" not in report.split("## by")[1] and "samples" not in report


def test_resumed_sweep_runs_only_what_is_missing(local_run, tmp_path: Path):
    out, rows = local_run
    before = {p.name: p.stat().st_mtime_ns for p in (out / "trials").glob("*.json")}
    again = sweep(_spec(tmp_path), out, "local", workers=2, show_progress=False)
    assert (again.ran, again.skipped) == (0, 4)
    # An interrupted sweep: the row of the trial that was running is missing.
    lost = rows[0.4, 2]["key"]
    (out / "trials" / f"{lost}.json").unlink()
    more = sweep(_spec(tmp_path), out, "local", workers=2, show_progress=False)
    assert (more.ran, more.skipped, more.failed) == (1, 3, 0)
    new = {(r["f_max_n"], r["seed"]): r for r in more.rows}
    assert sorted(new) == sorted(rows)
    for name, mtime in before.items():
        if name != f"{lost}.json":
            assert (out / "trials" / name).stat().st_mtime_ns == mtime  # not run again
    for name in FIGURES:  # the rerun trial gives the same figures
        assert new[0.4, 2][name] == rows[0.4, 2][name]


def _parent(pid: int) -> int:
    return int((Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[1])


def _descends_from(pid: int, ancestor: int) -> bool:
    while pid > 1:
        if pid == ancestor:
            return True
        try:
            pid = _parent(pid)
        except (OSError, ValueError, IndexError):
            return False
    return False


def _worker_procs(ancestor: int) -> dict[int, tuple[int, str]]:
    """pid -> (parent pid, trial) of every trial process (skeye.sweep.worker) under
    ``ancestor``."""
    found = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().split(b"\0")
            if b"skeye.sweep.worker" not in cmd:
                continue
            if not _descends_from(int(d.name), ancestor):
                continue
            ppid = _parent(int(d.name))
            found[int(d.name)] = (ppid, Path(cmd[cmd.index(b"skeye.sweep.worker") + 1].decode())
                                  .read_text())
        except (OSError, ValueError, IndexError):
            continue
    return found


def test_ray_cluster_gives_the_same_figures_and_retries_a_killed_worker(local_run,
                                                                       tmp_path: Path):
    pytest.importorskip("ray")
    _, rows = local_run
    out = tmp_path / "ray"
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED="0")
    # Two of the local run's four trials (one force, both seeds): enough to kill one worker
    # mid-trial and compare figures, at half the cost of the whole grid.
    spec = _spec(tmp_path, forces="[0.4]")
    proc = subprocess.Popen([sys.executable, "-m", "skeye.cli", "sweep", str(spec),
                             "--out", str(out), "--backend", "ray", "--workers", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    killed: tuple[int, str] | None = None
    restarted = False
    deadline = time.monotonic() + 600
    try:
        while proc.poll() is None and time.monotonic() < deadline:
            procs = _worker_procs(proc.pid)
            if killed is None and procs:
                pid, (ray_worker, trial) = next(iter(procs.items()))
                os.kill(ray_worker, signal.SIGKILL)  # the Ray worker running this trial
                killed = (pid, trial)
            elif killed is not None and not restarted:
                restarted = any(pid != killed[0] and trial == killed[1]
                                for pid, (_, trial) in procs.items())
            time.sleep(0.2)
        output = proc.communicate(timeout=60)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, output
    assert killed is not None and restarted, "the killed trial was not run again"
    with open(out / "results.csv") as f:
        table = list(csv.DictReader(f))
    assert len(table) == 2
    for t in table:
        assert t["error"] == ""
        local = rows[float(t["f_max_n"]), int(t["seed"])]
        assert t["key"] == local["key"]
        for name in FIGURES:
            assert float(t[name]) == local[name], (name, t, local)
    killed_trial = json.loads(killed[1])
    assert (killed_trial["params"]["f_max_n"], killed_trial["seed"]) in rows
    assert _worker_procs(os.getpid()) == {}  # no trial (nor its sim and pilot) left behind


FAILING = """
import os
import time

def trial(settings, params, workdir):
    if params["mode"] == "raise":
        raise RuntimeError("the flight went wrong")
    if params["mode"] == "hang" and not os.environ.get("SWEEP_TEST_NO_HANG"):
        time.sleep(600)
    if params["mode"] == "crash":
        os._exit(3)
    return {"height_m": 1.5 + settings.seed, "mode_len": len(params["mode"])}
"""


def test_failed_trials_are_rows_with_their_error(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch):
    (tmp_path / "flight.py").write_text(FAILING)
    spec = tmp_path / "s.toml"
    spec.write_text('experiment = "script"\nscript = "flight.py"\nseeds = [4]\ntimeout_s = 10\n'
                    '[grid]\nmode = ["ok", "raise", "hang", "crash"]\n')
    result = sweep(spec, tmp_path / "out", "local", workers=2, show_progress=False)
    rows = {r["mode"]: r for r in result.rows}
    assert (result.ran, result.failed) == (4, 3)
    assert rows["ok"]["error"] == "" and rows["ok"]["height_m"] == 5.5
    assert rows["raise"]["error"] == "RuntimeError: the flight went wrong"
    assert rows["hang"]["error"].startswith("timeout") and rows["hang"]["wall_s"] >= 10
    assert "exited with code 3" in rows["crash"]["error"]
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## failed trials" in report and "the flight went wrong" in report
    # A rerun retries only the failed trials (the hang no longer hangs: the suite's time).
    monkeypatch.setenv("SWEEP_TEST_NO_HANG", "1")
    again = sweep(spec, tmp_path / "out", "local", workers=2, show_progress=False)
    assert (again.ran, again.skipped) == (3, 1)


CLOBBERING = """
def trial(settings, params, workdir):
    if params["mode"] == "key":
        return {"key": 1.0, "height_m": 1.0}
    if params["mode"] == "param":
        return {"mode": 5.0, "wall_s": 0.0, "height_m": 2.0}
    if params["mode"] == "big":
        return {"count": 10**400}
    return {"height_m": 3.0, "seed": settings.seed}
"""


def test_script_figures_that_would_overwrite_the_row_or_not_fit_it_are_the_trials_error(
        tmp_path: Path):
    """A figure named like one of the row's own columns replaced it: ``key`` stored the row as
    ``trials/1.0.json`` (the summary said "3 trials: 4 run now", one trial missing from
    results.csv, run again on every resume), ``mode`` rewrote the trial's parameter. An integer
    beyond 64 bits ended the sweep in pyarrow's OverflowError traceback. Each is the trial's
    error now, naming the figures; the other trials run and are stored under their keys."""
    (tmp_path / "flight.py").write_text(CLOBBERING)
    spec = tmp_path / "s.toml"
    spec.write_text('experiment = "script"\nscript = "flight.py"\nseeds = [1]\ntimeout_s = 60\n'
                    '[grid]\nmode = ["ok", "key", "param", "big"]\n')
    out = tmp_path / "out"
    result = sweep(spec, out, "local", workers=2, show_progress=False)
    assert (len(result.rows), result.ran, result.failed) == (4, 4, 3)
    rows = {r["mode"]: r for r in result.rows}
    assert set(rows) == {"ok", "key", "param", "big"}
    assert rows["ok"]["error"] == "" and rows["ok"]["height_m"] == 3.0  # a seed is dropped
    assert "figures named key, which name columns the row has already" in rows["key"]["error"]
    assert "figures named mode, wall_s," in rows["param"]["error"]
    assert "integer figures beyond 64 bits (count)" in rows["big"]["error"]
    assert sorted(p.stem for p in (out / "trials").glob("*.json")) == sorted(
        r["key"] for r in result.rows)
    with open(out / "results.csv") as f:
        assert sorted(r["mode"] for r in csv.DictReader(f)) == ["big", "key", "ok", "param"]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('experiment = "E3"', "experiment must be E1, E2 or script"),
        # said "experiment must be E1, E2 or script, got None": None is Python's, not the file's
        ('name = "no experiment"\nseeds = 2',
         r'^the spec names no experiment: give experiment = "E1", "E2" or "script"$'),
        ('experiment = "E2"\nseeds = 0', "seeds must be >= 1"),
        ('experiment = "E2"\nseeds = [1, 1]', "seeds repeat"),
        # a name that is no file name: the report's plot_a/b.png ended the sweep, after every
        # trial, in a "No such file or directory" (and "../x" wrote outside --out)
        ('experiment = "script"\nscript = "flight.py"\n[grid]\n"a/b" = [1, 2]',
         r"parameter name\(s\) \['a/b'\]: a parameter's name is letters, digits"),
        ('experiment = "script"\nscript = "flight.py"\n[[trials]]\n"../x" = 1\n"" = 2',
         r"parameter name\(s\) \['', '\.\./x'\]"),
        # a flight script's parameter named like a column of the row: "key" stored every row
        # under its value (none found again: results.csv empty, a rerun ran all again)
        ('experiment = "script"\nscript = "flight.py"\n[grid]\nkey = [1, 2]',
         r"parameter\(s\) \['key'\] name columns every row has already"),
        ('experiment = "script"\nscript = "flight.py"\n[[trials]]\nerror = "x"\nhost = "a"',
         r"parameter\(s\) \['error', 'host'\] name columns"),
        # the same parameter set twice ran its trials twice (one key: the row written twice,
        # results.csv holding it twice, the report counting it twice)
        ('experiment = "script"\nscript = "flight.py"\n[grid]\ngain = [0.1, 0.2, 0.1]',
         r"parameter set \{'gain': 0\.1\} repeats"),
        ('experiment = "script"\nscript = "flight.py"\n[grid]\ngain = [1]\nmode = ["a"]\n'
         '[[trials]]\ngain = 1\nmode = "a"', r"parameter set \{'gain': 1, 'mode': 'a'\} repeats"),
        ('experiment = "E2"\n[grid]\ngain = [1, 2]', "E2 has no parameter"),
        ('experiment = "E2"\n[grid]\nf_max_n = ["x"]', "f_max_n must be a number"),
        ('experiment = "E2"\n[grid]\nf_max_n = []', "non-empty list"),
        ('experiment = "E2"\n[grid]\ncamera = ["fisheye"]', "camera must be one of ideal, webcam"),
        ('experiment = "E1"\n[grid]\nestimator = ["ekf"]', "estimator must be one of"),
        ('experiment = "E2"\n[grid]\nworld = ["moon"]', "world must be one of pad, indoor"),
        ('experiment = "E2"\ncolour = 1', "unknown spec keys"),
        ('experiment = "script"\nscript = "nope.py"', "does not exist"),
        ('experiment = "E2"\n[grid\n', "not valid TOML"),
        ('experiment = "E2"\ntimeout_s = -1', "timeout_s must be > 0"),
        # Settings of the wrong kind: ValueError/TypeError tracebacks, or quick = "false" ran
        # shortened trials (bool("false")); a negative seed failed every trial in skeye sim
        ('experiment = "E2"\ntimeout_s = "abc"', "timeout_s must be a finite number, got 'abc'"),
        ('experiment = "E2"\ntimeout_s = [1]', r"timeout_s must be a finite number, got \[1\]"),
        ('experiment = "E2"\ntimeout_s = inf', "timeout_s must be a finite number, got inf"),
        ('experiment = "E2"\nquick = "false"', "quick must be true or false, got 'false'"),
        ('experiment = "E2"\n[resources]\ncpus = "abc"',
         r"\[resources\] cpus must be a finite number, got 'abc'"),
        ('experiment = "E2"\n[resources]\ngpus = -1', r"\[resources\] gpus must be >= 0"),
        ('experiment = "E2"\nseeds = [3, -1]', "seeds must be >= 0, got -1"),
        # a count or a grid too big for memory (seeds = 1e11 ended in MemoryError)
        ('experiment = "E2"\nseeds = 100000000000', "a sweep makes at most 100000 trials"),
        ('experiment = "E2"\nseeds = 2\n[grid]\n' + "\n".join(
            f"{name} = [{', '.join(['0.1'] * 100)}]" for name in ("f_max_n", "e2_duration_s",
                                                                   "deadband_m")),
         "make 2000000 trials; a sweep makes at most 100000"),
        # Out-of-range values, by the rule the trial's processes apply (refused before any runs)
        ('experiment = "E2"\n[grid]\nf_max_n = [0.1, -0.1]',
         r"\[grid\]: f_max_n must be in \[0, 50\] N .*got -0\.1"),
        ('experiment = "E2"\n[grid]\nwind = ["bogus"]', r"wind must be one of .*got 'bogus'"),
        ('experiment = "E2"\n[grid]\nvision_latency = ["abc"]',
         r"vision_latency must be 'measured' or a number of ms .*got 'abc'"),
        ('experiment = "E1"\n[grid]\ncalibration = ["/nonexistent.toml"]',
         "calibration: /nonexistent.toml: cannot read calibration file"),
        ('experiment = "E2"\n[grid]\ne2_duration_s = [-1.0]',
         r"e2_duration_s must be at least one pilot tick .*got -1\.0"),
        ('experiment = "E2"\n[grid]\ndeadband_m = [-0.05]', "deadband_m -0.05 does not fit"),
        ('experiment = "E2"\n[grid]\npad_source = ["oracle"]', "pad_source must be one of"),
        ('experiment = "E2"\n[grid]\nwind_params = ["gusty"]', "wind_params 'gusty'"),
        ('experiment = "E2"\n[[trials]]\nwind = "dryden"\nwind_params = "f_max_n=1"',
         r"parameter set .*unknown parameter 'f_max_n' for mode 'dryden'"),
        ('experiment = "script"\nscript = "flight.py"\n[grid]\nf_max_n = [-1.0]',
         r"f_max_n must be in \[0, 50\]"),
    ],
)
def test_bad_specs_are_refused_with_the_reason(tmp_path: Path, text: str, match: str):
    from skeye.errors import LocalProtocolError

    spec = tmp_path / "bad.toml"
    spec.write_text(text)
    if "flight.py" in text:
        (tmp_path / "flight.py").write_text(FAILING)
    with pytest.raises(LocalProtocolError, match=match):
        sweep(spec, tmp_path / "out", "local", show_progress=False)
    assert not (tmp_path / "out" / "trials").exists() or not any(
        (tmp_path / "out" / "trials").iterdir())  # nothing ran


def test_a_spec_that_is_not_utf8_is_refused(tmp_path: Path):
    from skeye.errors import LocalProtocolError

    spec = tmp_path / "bad.toml"
    spec.write_bytes(b"\xff\xfeexperiment = 'E2'")  # raised UnicodeDecodeError
    with pytest.raises(LocalProtocolError, match=r"bad\.toml: not valid TOML \(not UTF-8"):
        sweep(spec, tmp_path / "out", "local", show_progress=False)


def test_a_folder_where_the_spec_or_its_script_goes_is_named_as_a_folder(tmp_path: Path):
    """A folder given as the spec was '[Errno 21] Is a directory', and a folder given as a
    spec's script 'flight script ... does not exist' (it does): each is now named as a
    folder where a file goes, before anything runs."""
    from skeye.errors import LocalProtocolError

    (tmp_path / "flights").mkdir()
    with pytest.raises(LocalProtocolError) as info:
        sweep(tmp_path / "flights", tmp_path / "out", "local", show_progress=False)
    assert str(info.value) == (f"sweep spec {tmp_path / 'flights'} is a folder, not a spec "
                               "file (give its .toml file)")
    spec = tmp_path / "spec.toml"
    spec.write_text('experiment = "script"\nscript = "flights"\n')
    with pytest.raises(LocalProtocolError) as info:
        sweep(spec, tmp_path / "out", "local", show_progress=False)
    assert str(info.value) == (f"flight script {tmp_path / 'flights'} is a folder, not a "
                               "Python file (give the .py file with trial(settings, params, "
                               "workdir))")
    assert not (tmp_path / "out").exists()  # nothing ran


def test_bad_command_lines_are_refused(tmp_path: Path):
    spec = _spec(tmp_path)
    for args, match in ((["--workers", "0"], "argument --workers: must be a whole number >= 1"),
                        (["--address", "auto"], "--address is for --backend ray")):
        run = subprocess.run([sys.executable, "-m", "skeye.cli", "sweep", str(spec), "--out",
                              str(tmp_path / "o"), *args], capture_output=True, text=True,
                             timeout=120)
        assert run.returncode != 0 and match in run.stderr + run.stdout


@pytest.mark.timeout(300)
@pytest.mark.parametrize(("address", "said"), [
    ("headnode", "--address must be auto or HOST:PORT"),  # a ValueError traceback
    ("127.0.0.1:{free}", "--address 127.0.0.1:{free}: no Ray cluster answers there"),  # hung
])
def test_a_ray_address_that_is_no_cluster_is_refused_at_once(tmp_path: Path, address: str,
                                                             said: str):
    """Ray's own client retried an address where nothing listens for minutes (past 5 with
    --address 127.0.0.1:1), and refused one without a port with a ValueError traceback."""
    pytest.importorskip("ray")
    from tests.ports import free_port

    free = free_port()  # nothing listens there
    spec = _spec(tmp_path)
    start = time.monotonic()
    run = subprocess.run([sys.executable, "-m", "skeye.cli", "sweep", str(spec), "--out",
                          str(tmp_path / "o"), "--backend", "ray",
                          "--address", address.format(free=free)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2, run.stderr
    assert run.stderr.startswith(f"skeye sweep: error: {said.format(free=free)}"), run.stderr
    assert "Traceback" not in run.stderr and time.monotonic() - start < 60


def _skeye_without(module: str, *args: str) -> subprocess.CompletedProcess[str]:
    """``skeye ARGS`` where ``module`` cannot be imported (as on an install without its
    extra; nothing is uninstalled)."""
    code = (f"import sys; sys.modules[{module!r}] = None; from skeye.cli import main; "
            "sys.exit(main(sys.argv[1:]))")
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          timeout=120)


@pytest.mark.parametrize(("module", "options", "said"), [
    ("ray", ["--backend", "ray"], "the Ray backend needs Ray: pip install 'skeye[ray]'"),
    ("matplotlib", [], "matplotlib is not installed: this command needs skeye's sim extra"),
])
def test_a_missing_extra_is_named_before_the_output_folder_is_made(tmp_path: Path, module: str,
                                                                    options: list[str],
                                                                    said: str):
    """A sweep that cannot run (Ray missing for ``--backend ray``; matplotlib, which draws the
    report, missing) is refused before anything is made: exit 2, the extra named, no ``--out``
    folder. Until 2026-11-28 the folder was made (with its lock file) first, and without
    matplotlib every trial ran before the report failed."""
    out = tmp_path / "o"
    run = _skeye_without(module, "sweep", str(_spec(tmp_path)), "--out", str(out), *options)
    assert run.returncode == 2, run.stderr
    assert run.stderr.startswith(f"skeye sweep: error: {said}"), run.stderr
    assert not out.exists(), sorted(p.name for p in out.iterdir())


SLOW = """
import os
import time

def trial(settings, params, workdir):
    if params["mode"] == "hang":
        with open(os.environ["SWEEP_TEST_PIDFILE"], "w") as f:
            f.write(str(os.getpid()))
        time.sleep(600)
    return {"height_m": 1.0}
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_sweep_off_a_terminal_logs_lines_and_a_stop_signal_leaves_nothing_behind(
        tmp_path: Path, sig: signal.Signals):
    """Issue 34 item 6: with stderr not a terminal, each finished trial is a plain line; a
    SIGTERM kills the running trials, removes their temporary folders and keeps the rows. So
    does SIGINT, Ctrl-C (docs/sweeps.md): it waited for the running trials to end by
    themselves (a trial runs in a process group of its own, out of the terminal's reach), and
    then said "skeye sweep: ; the finished trials ..." with no reason."""
    (tmp_path / "flight.py").write_text(SLOW)
    spec = tmp_path / "s.toml"
    spec.write_text('experiment = "script"\nscript = "flight.py"\nseeds = [1]\n'
                    'timeout_s = 900\n[grid]\nmode = ["ok", "hang"]\n')
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    pidfile = tmp_path / "hang.pid"
    env = dict(os.environ, TMPDIR=str(tmp), SWEEP_TEST_PIDFILE=str(pidfile))
    # as from a terminal: SIGINT not ignored (a background job of a non-interactive shell, as
    # `./.ci/run &`, starts with it ignored, and the sweep then leaves it so, as it should)
    proc = subprocess.Popen([sys.executable, "-m", "skeye.cli", "sweep", str(spec), "--out",
                             str(tmp_path / "out"), "--workers", "2"],
                            stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env=env,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert proc.stderr is not None
    lines = []
    try:
        for line in proc.stderr:  # an event wait: the ok trial's line
            lines.append(line)
            if "1/2 trial" in line:
                break
        deadline = time.monotonic() + 300  # a stuck guard: the hang trial has started
        while not pidfile.exists() or not pidfile.read_text():
            assert time.monotonic() < deadline, lines
            time.sleep(0.05)
        hang_pid = int(pidfile.read_text())
        assert list(tmp.glob("skeye-trial-*")), "the running trial has its folder"
        proc.send_signal(sig)
        assert proc.wait(60) == 130
        rest = proc.stderr.read()
    finally:
        proc.kill()
        proc.stderr.close()
    assert "2 trials to run" in lines[0] and "ok in" in lines[-1], lines
    assert f"stopped by signal {sig.name}" in rest and "rerun to resume" in rest, rest
    assert not list(tmp.glob("skeye-trial-*")), list(tmp.iterdir())
    assert not Path(f"/proc/{hang_pid}").exists() or \
        Path(f"/proc/{hang_pid}/stat").read_text().split(")")[1].split()[0] == "Z"
    assert len(list((tmp_path / "out" / "trials").glob("*.json"))) == 1  # the ok row kept


def test_a_stop_while_a_trial_process_is_starting_kills_it(tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch):
    """A stop (Ctrl-C, SIGTERM) that came while a pool thread was starting a trial process,
    its temporary folder made and the process not yet entered among the running ones, killed
    nothing: the stop's KeyboardInterrupt then waited in the pool's shutdown for that trial to
    end by itself (a validation's E2 trial, minutes: `skeye validate` was not out within 60 s
    of Ctrl-C on a loaded machine, where the start takes longest). A trial is now started and
    entered under the lock the stop takes, and a trial not yet started when the stop came is
    not started."""
    import threading

    from skeye.sweep import worker
    from skeye.sweep.spec import Trial

    (tmp_path / "flight.py").write_text(SLOW)
    monkeypatch.setenv("SWEEP_TEST_PIDFILE", str(tmp_path / "hang.pid"))
    hang = Trial("script", {"mode": "hang"}, 1, script=str(tmp_path / "flight.py"),
                 timeout_s=60.0).to_json()
    stopped: list[int] = []
    stopper: list[threading.Thread] = []
    real_popen = subprocess.Popen

    def lock_free() -> bool:  # can another thread take the stop's lock now?
        taken = worker._running_lock.acquire(blocking=False)
        if taken:
            worker._running_lock.release()
        return taken

    def popen(*args, **kwargs):  # the stop comes while the trial's process is being started
        probe: list[bool] = []
        checker = threading.Thread(target=lambda: probe.append(lock_free()))
        checker.start()
        checker.join(30)
        assert probe == [False], "the trial's process is started outside the stop's lock"
        stopper.append(threading.Thread(target=lambda: stopped.append(
            worker.stop_running_trials())))
        stopper[0].start()  # it waits for the lock: the start and its entry among the running
        return real_popen(*args, **kwargs)

    with worker.trials_allowed():
        monkeypatch.setattr(worker.subprocess, "Popen", popen)
        row = worker.run_trial_process(hang)
        stopper[0].join(60)
        assert stopped == [1], stopped  # the starting trial was killed, not left to run
        assert row["error"].startswith("trial process exited with code -9"), row["error"]
        monkeypatch.setattr(worker.subprocess, "Popen", real_popen)
        again = worker.run_trial_process(hang)  # after the stop: not started
        assert again["error"].startswith("stopped: the run was stopped"), again["error"]


STORE_BLOCKED = """
import os
import time
from pathlib import Path

def trial(settings, params, workdir):
    pidfile = Path(os.environ["SWEEP_TEST_PIDFILE"])
    if params["mode"] == "hang":
        pidfile.write_text(str(os.getpid()))
        time.sleep(600)
    deadline = time.monotonic() + 120  # ends once the other trial runs: one is then running
    while not pidfile.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    return {"height_m": 1.0}
"""


def test_a_row_that_cannot_be_stored_stops_the_sweep_naming_it_and_keeps_its_figures(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """A trial's row that cannot be written (a full disk: ENOSPC; here its temporary name is
    taken by a folder) ended the sweep with the bare OSError ("[Errno 28] No space left on
    device": no file, the row's figures lost) only after every running trial had run to its
    end or its timeout, their rows lost as well. Now the error names the file and holds the
    row, and the running trials are killed at once."""
    from skeye.errors import ConfigError
    from skeye.sweep.spec import load_spec

    (tmp_path / "flight.py").write_text(STORE_BLOCKED)
    spec = tmp_path / "s.toml"
    spec.write_text('experiment = "script"\nscript = "flight.py"\nseeds = [1]\ntimeout_s = 90\n'
                    '[grid]\nmode = ["ok", "hang"]\n')
    pidfile = tmp_path / "hang.pid"
    monkeypatch.setenv("SWEEP_TEST_PIDFILE", str(pidfile))
    ok = next(t for t in load_spec(spec).trials if t.params["mode"] == "ok")
    trials = tmp_path / "out" / "trials"
    (trials / f"{ok.key}.tmp").mkdir(parents=True)
    start = time.monotonic()
    with pytest.raises(ConfigError) as err:
        sweep(spec, tmp_path / "out", "local", workers=2, show_progress=False)
    assert time.monotonic() - start < 60, "the hanging trial was waited for"
    text = str(err.value)
    assert f"cannot store trial {ok.key}'s row in {trials / ok.key}.json: Is a directory" in text
    assert '"height_m": 1.0' in text and '"mode": "ok"' in text, text  # the figures, kept
    assert "stopped (1 running trial(s) killed); the rows stored before are kept in " \
        f"{trials} (rerun to resume)" in text, text
    hang_pid = int(pidfile.read_text())
    assert not Path(f"/proc/{hang_pid}").exists() or \
        Path(f"/proc/{hang_pid}/stat").read_text().split(")")[1].split()[0] == "Z"


def test_a_second_sweep_into_a_folder_in_use_is_refused_naming_the_first(tmp_path: Path):
    """Two sweeps given one --out both ran every trial (twice the work) and raced on each row's
    temporary file (the two finish a trial together: the second rename found none). The
    second is refused at once now, naming the process that holds the folder."""
    from skeye.errors import ConfigError
    from skeye.outputs import folder_lock

    (tmp_path / "flight.py").write_text(SLOW)
    spec = tmp_path / "s.toml"
    spec.write_text('experiment = "script"\nscript = "flight.py"\nseeds = [1]\n'
                    'timeout_s = 60\n[grid]\nmode = ["hang"]\n')
    out = tmp_path / "out"
    pidfile = tmp_path / "hang.pid"
    first = subprocess.Popen([sys.executable, "-m", "skeye.cli", "sweep", str(spec), "--out",
                              str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                             text=True, env=dict(os.environ, SWEEP_TEST_PIDFILE=str(pidfile)))
    try:
        deadline = time.monotonic() + 120  # a stuck guard: the first sweep's trial runs
        while not pidfile.exists() or not pidfile.read_text():
            assert first.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        with pytest.raises(ConfigError, match=rf"--out {out} is in use by another skeye sweep "
                                              rf"\(pid {first.pid}\): wait for it to end"):
            sweep(spec, out, "local", show_progress=False)
    finally:
        first.terminate()
        first.communicate(timeout=60)
    with folder_lock(out, "skeye sweep"):  # free again once the first has ended
        pass


def test_a_signal_ignored_at_start_stays_ignored():
    """``nohup skeye sweep ...`` keeps running when its terminal hangs up: the stop handlers
    leave a signal the sweep was started ignoring alone, and put every handler back after."""
    from skeye.sweep.cli import stop_cleanly_on_signals

    before = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        with stop_cleanly_on_signals():
            assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
            assert signal.getsignal(signal.SIGTERM) not in (signal.SIG_IGN, signal.SIG_DFL)
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGHUP, before)


def test_the_progress_line_counts_a_finished_trial_as_done_not_running(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]):
    """The line after a trial finishes counts only the trials still in flight as running: the
    last one says 0 running (it said 1 when the last trial was counted as still running)."""
    from skeye.sweep import backends
    from skeye.sweep.cli import run_trials
    from skeye.sweep.spec import SweepSpec, Trial
    from skeye.sweep.worker import base_row

    def fake_trial(trial: dict, **_: object) -> dict:
        return {**base_row(Trial.from_json(trial)), "wall_s": 0.0, "error": ""}

    monkeypatch.setattr(backends, "run_trial_process", fake_trial)
    (tmp_path / "none.py").write_text("")  # never run: the trial process is faked
    trials = [Trial("script", {"mode": m}, 1, script=str(tmp_path / "none.py"))
              for m in ("a", "b", "c")]
    result = run_trials(SweepSpec("script", trials, ["mode"]), tmp_path / "out",
                        backends.LocalBackend(2), "test")
    assert result.ran == 3
    lines = [line for line in capsys.readouterr().err.splitlines() if " trial " in line]
    assert len(lines) == 3, lines
    for line in lines:
        done = int(line.split(": ", 1)[1].split("/", 1)[0])
        running = int(line.split(" failed, ", 1)[1].split(" running", 1)[0])
        assert done + running <= 3, line  # a finished trial is not also running
    assert "0 failed, 0 running" in lines[-1], lines


EXITING = """
import sys

def trial(settings, params, workdir):
    if params["mode"] == "exit":
        sys.exit(3)
    return {"height_m": 1.0}
"""


def test_a_trial_process_ends_with_its_own_status_not_an_interpreter_abort(tmp_path: Path):
    """Every trial process aborted at exit (SIGABRT, ``Fatal Python error:
    _enter_buffered_busy: could not acquire lock for <_io.BufferedReader name='<stdin>'>``):
    its parent-watch thread sat in a buffered read of stdin, whose lock the interpreter needs
    to shut down. A trial that had written its row hid it (and left a core dump where they are
    kept); a flight script's ``sys.exit(3)`` became "exited with code -6" and the abort's text.
    Now a trial process ends with the status it exits with."""
    from skeye.sweep.spec import Trial
    from skeye.sweep.worker import run_trial_process

    (tmp_path / "flight.py").write_text(EXITING)
    ok, exiting = (Trial("script", {"mode": m}, 1, script=str(tmp_path / "flight.py"),
                         timeout_s=60.0) for m in ("ok", "exit"))
    (tmp_path / "trial.json").write_text(json.dumps(ok.to_json()))
    # The trial process as run_trial_process starts it: its stdin a pipe that stays open.
    proc = subprocess.Popen(
        [sys.executable, "-m", "skeye.sweep.worker", str(tmp_path / "trial.json"),
         str(tmp_path / "result.json"), str(tmp_path / "work"), ""],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        start_new_session=True, text=True)
    assert proc.stdin is not None and proc.stdout is not None
    try:
        status = proc.wait(60)  # what it prints is a few lines: the pipe does not fill
        assert status == 0, f"exit status {status}: {proc.stdout.read()[-300:]}"
    finally:
        proc.stdin.close()
        proc.stdout.close()
    assert json.loads((tmp_path / "result.json").read_text()) == {
        "figures": {"height_m": 1.0}, "error": ""}
    row = run_trial_process(exiting.to_json())
    assert row["error"].startswith("trial process exited with code 3"), row["error"]
    assert "Fatal Python error" not in row["error"], row["error"]


MULTILINE = """
def trial(settings, params, workdir):
    raise RuntimeError("the flight went wrong\\n  at waypoint 3\\n")
"""


def test_a_trial_error_of_several_lines_is_said_in_one(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]):
    """An exception whose text runs over several lines (a subprocess's output, a validation
    listing) was stored as it was: off a terminal the sweep's line for the trial, one per
    finished trial, came out in pieces, and the report's table of failed trials broke at the
    line break. Its lines are now joined with ' | ', as a crashed trial process's last lines
    are."""
    (tmp_path / "flight.py").write_text(MULTILINE)
    spec = tmp_path / "s.toml"
    spec.write_text('experiment = "script"\nscript = "flight.py"\nseeds = [1]\ntimeout_s = 60\n')
    result = sweep(spec, tmp_path / "out", "local", workers=1, show_progress=True)
    error = "RuntimeError: the flight went wrong | at waypoint 3"
    assert [r["error"] for r in result.rows] == [error]
    said = [line for line in capsys.readouterr().err.splitlines() if "failed: " in line]
    assert len(said) == 1 and f"failed: {error} in " in said[0], said
    report = (tmp_path / "out" / "report.md").read_text().splitlines()
    cell = error.replace("|", "/")  # the table's own separator, in a cell
    assert [line for line in report if line.startswith("| ") and line.endswith(f"| {cell} |")]
