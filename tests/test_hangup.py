"""SIGHUP (the terminal or SSH session that started it closed) stops a skeye server in order,
as Ctrl-C does; ``nohup`` keeps it running.

Before, only ``skeye sweep`` and ``skeye validate`` took SIGHUP: a ``skeye sim`` or ``skeye
pilot`` started over SSH on a vehicle's computer died of the signal's default disposition when
the session dropped (status -1), its recording's last half second never written and its
airframe not let go; ``skeye up`` died the same way, and its children were SIGTERMed all at
once by the kernel (``PR_SET_PDEATHSIG``), not stopped in order."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
from pathlib import Path

from skeye.processes import start_skeye, stop_process
from skeye.recording.records import SENT, RecordingReader

START_TIMEOUT_S = 180.0  # a loaded machine's start of a simulator with a renderer


def test_sighup_stops_simulator_and_pilot_in_order_keeping_the_recording(tmp_path: Path) -> None:
    path = tmp_path / "hangup.rec"
    sim, found = start_skeye(["sim", "--port", "0", "--record", str(path)],
                             [r"control protocol on [\d.]+:(\d+)"], "simulator",
                             timeout_s=START_TIMEOUT_S)
    try:
        pilot, _ = start_skeye(["pilot", "--sim", f"127.0.0.1:{found[0].group(1)}",
                                "--port", "0"], [r"ground control on"], "pilot",
                               timeout_s=START_TIMEOUT_S)
        try:
            pilot.send_signal(signal.SIGHUP)
            assert pilot.wait(60) == 0
        finally:
            stop_process(pilot)
        sim.send_signal(signal.SIGHUP)
        assert sim.wait(60) == 0
    finally:
        stop_process(sim)
    # The simulator's stop closed the recording: whole, with the pilot's stream in it.
    reader = RecordingReader(path)
    records = list(reader.records())
    assert reader.bad_lines == 0
    assert any(r.direction == SENT and r.line.startswith(("SEN ", "STA ")) for r in records)


HANGUP_CHILD = textwrap.dedent("""
    import os, signal, threading
    from skeye.processes import wait_for_signal

    def hang_up():
        print("hung up", flush=True)
        os.kill(os.getpid(), signal.SIGHUP)

    timer = threading.Timer(0.5, hang_up)
    timer.daemon = True
    timer.start()
    wait_for_signal(threading.Event())
    print("stopped", flush=True)
""")


def test_sighup_stops_the_wait() -> None:
    child = subprocess.run([sys.executable, "-c", HANGUP_CHILD], capture_output=True, text=True,
                           timeout=60)
    assert child.returncode == 0 and child.stdout == "hung up\nstopped\n", child


NOHUP_CHILD = textwrap.dedent("""
    import signal
    from skeye.processes import on_stop_signals

    def handler(signum, frame):
        pass

    on_stop_signals(handler)
    print(*(signal.getsignal(s) is handler for s in (signal.SIGINT, signal.SIGTERM,
                                                     signal.SIGHUP)))
""")


def test_sighup_ignored_by_nohup_stays_ignored() -> None:
    ignoring = subprocess.run([sys.executable, "-c", NOHUP_CHILD], capture_output=True,
                              text=True, timeout=60,
                              preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_IGN))
    assert ignoring.stdout == "True True False\n", ignoring
    plain = subprocess.run([sys.executable, "-c", NOHUP_CHILD], capture_output=True, text=True,
                           timeout=60)
    assert plain.stdout == "True True True\n", plain
