"""How ``skeye up`` stops when a child will not: a second Ctrl-C or SIGTERM kills what is still
running at once, and a Ctrl-C ends the wait for the simulator's exit status.

These run the real ``skeye up`` (its signal handling, stop order and reporting) with stand-ins
for its three children: each a small interpreter listening on the ports ``skeye up`` waits for,
so the stop is seen in a second instead of the minutes three MuJoCo imports take. A stand-in
that ignores SIGTERM is a child hung at its stop (a simulator stuck in its engine, a pilot
waiting on a frozen link), which ``skeye up`` SIGKILLs only after ``STOP_TIMEOUT_S`` (10 s),
one child after the other: 30 s for three.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from skeye.ground.cli import STOP_TIMEOUT_S
from tests.ground.conftest import wait_until
from tests.ground.test_up import _children, _read_until_open
from tests.ports import free_ports

# A child of skeye up: listens on every port given after --port, --image-port, --video-port;
# SKEYE_STANDIN_HUNG=1: ignores SIGTERM (else exits 0 on it); SIGUSR1 makes it exit with 4.
# SKEYE_STANDIN_STARTING=pilot: the pilot never listens (it is still starting): it says
# "standin pilot starting" and exits 130 on SIGINT, as a Ctrl-C in a terminal ends it.
STANDIN = r"""
import os, signal, socket, sys
argv = sys.argv[1:]
starting = os.environ.get("SKEYE_STANDIN_STARTING") == argv[0]
ports = [int(argv[i + 1]) for i, a in enumerate(argv) if a in ("--port", "--image-port",
                                                               "--video-port")]
servers = [] if starting else [socket.create_server(("127.0.0.1", p)) for p in ports]
hung = os.environ.get("SKEYE_STANDIN_HUNG") == "1"
signal.signal(signal.SIGTERM, signal.SIG_IGN if hung else lambda *_: os._exit(0))
signal.signal(signal.SIGINT, (lambda *_: os._exit(130)) if starting else signal.SIG_IGN)
if starting:
    print(f"standin {argv[0]} starting", flush=True)
signal.signal(signal.SIGUSR1, lambda *_: os._exit(4))
log = os.environ.get("SKEYE_STANDIN_LOG")
if log:  # as the real children: Ctrl-C or SIGTERM stops it; it says which came
    def stopped(signum, frame):
        with open(log, "a") as f:
            f.write(f"{argv[0]}:{signal.Signals(signum).name}\n")
        os._exit(0)
    signal.signal(signal.SIGTERM, stopped)
    signal.signal(signal.SIGINT, stopped)
while True:
    signal.pause()
"""

# skeye up itself, with the stand-ins in place of `python -m skeye.cli sim|pilot|ground`.
UP = r"""
import sys
import skeye.ground.cli as up
from skeye.cli import main
standin = sys.argv[1]
up._child_argv = lambda *args: [sys.executable, standin, *args]
sys.exit(main(["up", *sys.argv[2:]]))
"""


@pytest.fixture
def standin(tmp_path: Path) -> Path:
    path = tmp_path / "standin.py"
    path.write_text(STANDIN)
    return path


def _spawn_up(standin: Path, env: dict[str, str], *, stderr: int = subprocess.STDOUT
              ) -> subprocess.Popen[str]:
    """``skeye up`` over the stand-in children, on free ports, in its own session, with
    ``env`` added to the environment (the stand-in's switches)."""
    sim, img, pilot, ground, video = free_ports(5)
    argv = [sys.executable, "-c", UP, str(standin), "--sim-port", str(sim), "--image-port",
            str(img), "--pilot-port", str(pilot), "--ground-port", str(ground),
            "--video-port", str(video), "--calibration", "none", "--no-mavlink"]
    return subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=stderr, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1", **env},
                            start_new_session=True)


def _kill_up(proc: subprocess.Popen[str]) -> None:
    """Kill skeye up's group and each child's own, whatever the test left (a hung stand-in
    ignores the SIGTERM of its parent's death)."""
    for pid in (proc.pid, *(_children(proc.pid) if proc.poll() is None else ())):
        try:
            os.killpg(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    proc.wait(30)


def _start_up(standin: Path, hung: bool) -> Iterator[tuple[subprocess.Popen[str], list[str]]]:
    proc = _spawn_up(standin, {"SKEYE_STANDIN_HUNG": "1" if hung else "0"})
    try:
        yield proc, _read_until_open(proc)
    finally:
        _kill_up(proc)


@pytest.fixture
def hung_up(standin: Path) -> Iterator[tuple[subprocess.Popen[str], list[str]]]:
    yield from _start_up(standin, hung=True)


@pytest.fixture
def up(standin: Path) -> Iterator[tuple[subprocess.Popen[str], list[str]]]:
    yield from _start_up(standin, hung=False)


def _gone(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_second_stop_signal_kills_children_that_will_not_stop(hung_up, sig) -> None:
    """Before, a second Ctrl-C did nothing: three children hung at their stop took 30 s (10 s
    each, one after the other), as docker compose's stop would, but without its way out, a
    second Ctrl-C. Now the first asks each child to stop, saying how to force it, and the second
    kills what is still running at once."""
    proc, _ = hung_up
    children = _children(proc.pid)
    assert len(children) == 3
    assert proc.stdout is not None
    proc.send_signal(sig)
    said = proc.stdout.readline()
    assert said == ("skeye up: stopping (Ctrl-C or SIGTERM again kills what is still running "
                    "at once)\n"), said
    start = time.monotonic()
    proc.send_signal(sig)
    assert proc.wait(STOP_TIMEOUT_S / 2) == 0  # hung ground control alone held it 10 s
    took = time.monotonic() - start
    rest = proc.stdout.read()
    assert "skeye up: killed ground control, pilot, simulator at a second stop signal" in rest
    assert rest.rstrip().endswith("skeye up: stopped"), rest
    assert all(_gone(pid) for pid in children)
    assert took < STOP_TIMEOUT_S / 2


def test_ctrl_c_ends_the_wait_for_the_simulators_exit_status(up) -> None:
    """A pilot that lost its simulator (status 4) makes skeye up wait up to 30 s for the
    simulator's own status, which names the root cause. A simulator that is stuck never gives
    one, and Ctrl-C did nothing for those 30 s (and then 10 s more for each child that would
    not stop). Now Ctrl-C ends the wait: the pilot's exit is still named, and everything stops."""
    proc, _ = up
    pids = {open(f"/proc/{pid}/cmdline").read().split("\0")[2]: pid
            for pid in _children(proc.pid)}
    os.kill(pids["pilot"], signal.SIGUSR1)  # the pilot exits 4: "it lost the simulator"
    # skeye up reaps it (its /proc entry goes) and then waits for the simulator's status
    wait_until(lambda: not os.path.exists(f"/proc/{pids['pilot']}"), 10,
               "skeye up to see the pilot's exit")
    start = time.monotonic()
    proc.send_signal(signal.SIGINT)
    assert proc.wait(STOP_TIMEOUT_S / 2) == 1  # the pilot failed: status 1, as before
    took = time.monotonic() - start
    assert proc.stdout is not None
    rest = proc.stdout.read()
    assert "skeye up: pilot exited (4: it lost the simulator); stopping" in rest, rest
    assert rest.rstrip().endswith("skeye up: stopped"), rest
    assert all(_gone(pid) for pid in pids.values())
    assert took < STOP_TIMEOUT_S / 2


@pytest.mark.parametrize("group", [False, True], ids=["to skeye up", "to its process group"])
def test_ctrl_c_while_starting_stops_with_status_0(standin: Path, group: bool) -> None:
    """Ctrl-C while a child was starting ended ``skeye up`` with status 1 and ``stopped while
    pilot was starting`` on stderr, as if the pilot had failed; the same Ctrl-C a moment later,
    once started, gave 0. A stop asked for is now status 0 whenever it comes. A terminal's
    Ctrl-C goes to the whole process group: it reached the starting pilot too, which exited 130
    (``pilot exited (130)``, said as its failure; the children now have their own group)."""
    proc = _spawn_up(standin, {"SKEYE_STANDIN_STARTING": "pilot"}, stderr=subprocess.PIPE)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line == "standin pilot starting\n", line
        children = _children(proc.pid)
        assert len(children) == 2  # the simulator and the starting pilot
        if group:
            os.killpg(proc.pid, signal.SIGINT)
        else:
            proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, (out, err)
        assert "skeye up: stopped while pilot was starting\n" in out, out
        assert out.endswith("skeye up: stopped\n"), out
        assert "exited" not in out and err == "", (out, err)
        assert all(_gone(pid) for pid in children)
    finally:
        _kill_up(proc)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGHUP], ids=["Ctrl-C", "hang-up"])
def test_a_terminals_ctrl_c_stops_the_children_in_order(standin: Path, tmp_path: Path,
                                                        sig: int) -> None:
    """A terminal's Ctrl-C goes to the whole foreground process group, which held the
    children too: ground control, the pilot and the simulator each got SIGINT at once, and
    ground control logged the pilot gone (``no link to the vehicle: ... the vehicle closed the
    link``) at a normal stop, the order of docs/ground.md not kept. The children now run in
    their own process group, so the Ctrl-C reaches ``skeye up`` alone, which stops them in
    order with SIGTERM. The terminal closing (SIGHUP to the group) stops them so too: it used
    to kill ``skeye up`` outright (status -1), and the kernel SIGTERMed the three at once."""
    log = tmp_path / "stopped"
    proc = _spawn_up(standin, {"SKEYE_STANDIN_LOG": str(log)})
    try:
        _read_until_open(proc)
        children = _children(proc.pid)
        assert len(children) == 3
        os.killpg(proc.pid, sig)  # what a terminal's Ctrl-C, or its closing, does
        assert proc.wait(60) == 0
        assert log.read_text().splitlines() == ["ground:SIGTERM", "pilot:SIGTERM",
                                                "sim:SIGTERM"], log.read_text()
        assert all(_gone(pid) for pid in children)
    finally:
        _kill_up(proc)


def test_a_child_killed_while_starting_is_named_with_its_signal(standin: Path) -> None:
    """A child killed while starting was said as ``pilot exited with status -9 while
    starting`` (Popen's negative status), and again as ``pilot exited (SIGKILL); stopping``.
    It is named once, with its signal, and ``skeye up`` exits 1."""
    proc = _spawn_up(standin, {"SKEYE_STANDIN_STARTING": "pilot"}, stderr=subprocess.PIPE)
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline() == "standin pilot starting\n"
        pids = {open(f"/proc/{pid}/cmdline").read().split("\0")[2]: pid
                for pid in _children(proc.pid)}
        os.kill(pids["pilot"], signal.SIGKILL)
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 1, (out, err)
        said = out + err
        assert "-9" not in said, said
        assert said.count("pilot exited") == 1, said
        assert "skeye up: pilot exited (SIGKILL) while starting" in err, said
    finally:
        _kill_up(proc)
