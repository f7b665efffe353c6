"""benchmarks/gpu_figures.sh on a Ctrl-C: the running benchmark and what it started are stopped,
and the script goes no further.

The script's PYTHON argument is a stand-in here, a Python script that records its own process
id and that of a child it starts (as a benchmark starts ``skeye sim``), then waits on that child;
no benchmark runs. A terminal's Ctrl-C is SIGINT to the script's foreground process group.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

STAND_IN = textwrap.dedent("""\
    import subprocess, sys
    with subprocess.Popen([sys.executable, "-c", "import time; time.sleep(300)"]) as child:
        with open(sys.argv[0] + ".pids", "a") as f:
            f.write(f"{__import__('os').getpid()} {child.pid}\\n")
        child.wait()
""")


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def wait_until(condition: object, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():  # type: ignore[operator]
            return True
        time.sleep(0.05)
    return False


def test_ctrl_c_stops_the_running_benchmark_and_the_script(tmp_path: Path) -> None:
    """The script ran each benchmark under ``timeout``, which puts it in a process group of its
    own: a Ctrl-C reached the script and its ``tee`` only, the benchmark and its simulators ran
    on to the end of their 150 s, and the script then went on with the next benchmark."""
    stand_in = tmp_path / "python"
    stand_in.write_text(f"#!{sys.executable}\n{STAND_IN}")
    stand_in.chmod(0o755)
    pids_file = Path(f"{stand_in}.pids")
    env = {k: v for k, v in os.environ.items() if k != "OUT"} | {"OUT": str(tmp_path)}
    script = subprocess.Popen(
        ["bash", str(ROOT / "benchmarks" / "gpu_figures.sh"), str(stand_in)],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    pids: list[int] = []
    try:
        assert wait_until(lambda: pids_file.exists() and pids_file.read_text().endswith("\n"),
                          60), "the stand-in never started"
        pids = [int(p) for p in pids_file.read_text().split()]
        os.killpg(script.pid, signal.SIGINT)
        assert script.wait(timeout=30) == 130
        assert wait_until(lambda: not any(alive(p) for p in pids), 30), \
            [p for p in pids if alive(p)]
        assert len(pids_file.read_text().splitlines()) == 1  # no benchmark after it
        assert "gpu_figures.sh: interrupted" in (tmp_path / "gpu_figures.txt").read_text()
    finally:
        if script.poll() is None:
            os.killpg(script.pid, signal.SIGKILL)
            script.wait(timeout=30)
        for pid in pids:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
