"""skeye.processes.start_skeye: the child's output pipe is closed once it has been read to its
end, not left for the garbage collector; output that is not UTF-8 is read all the same."""

from __future__ import annotations

import os
import signal

import pytest

from skeye.errors import SkeyeError
from skeye.processes import _signal_mask, start_skeye, stop_process, stop_processes
from tests.robustness.helpers import wait_for


def test_the_output_pipe_of_a_started_child_is_closed_after_its_end() -> None:
    proc, found = start_skeye(["--help"], [r"^usage: skeye"], "skeye --help", timeout_s=60)
    try:
        assert found[0].group(0) == "usage: skeye"
        assert proc.wait(60) == 0
        stdout = proc.stdout
        assert stdout is not None
        assert wait_for(lambda: stdout.closed, timeout_s=30), "the drained pipe was left open"
    finally:
        stop_process(proc)


def test_output_that_is_not_utf8_is_quoted_not_a_decoding_error() -> None:
    """A child writing another encoding (here latin-1: 'wörld' as one byte 0xF6) is quoted with
    a replacement character; a strict decoder raised UnicodeDecodeError in the reader (or killed
    the drain thread)."""
    with pytest.raises(SkeyeError, match=r"did not start: .*unknown world 'w\ufffdrld'") as info:
        start_skeye(["sim", "--world", "wörld", "--port", "0"], [r"control protocol on"],
                    "skeye sim", timeout_s=120, env={"PYTHONIOENCODING": "latin-1"})
    # One line, the child's lines joined (a line break in it split a sweep's progress line).
    assert "\n" not in str(info.value), str(info.value)


def test_a_stopped_child_is_woken_to_handle_its_sigterm() -> None:
    """``skeye up`` stops its children with stop_processes. A ``skeye sim`` stopped with SIGSTOP
    kept the SIGTERM it handles pending, and was waited for the whole timeout, then SIGKILLed
    (10 s, status -9). A SIGCONT now follows the SIGTERM, as systemd sends one: the simulator
    handles its SIGTERM and exits 0 at once."""
    proc, _ = start_skeye(["sim", "--port", "0"], [r"control protocol on"], "skeye sim",
                          timeout_s=120)
    try:
        term = 1 << (signal.SIGTERM - 1)  # its handler is in place (it is set after the line)
        assert wait_for(lambda: (_signal_mask(proc.pid, "SigCgt") or 0) & term, timeout_s=60)
        os.kill(proc.pid, signal.SIGSTOP)
        # a stuck guard: without the SIGCONT it is never handled, and the kill comes then
        stop_processes([proc], timeout_s=60.0)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGCONT)
        stop_process(proc)
    assert proc.returncode == 0, proc.returncode  # its own handler, not SIGKILL
