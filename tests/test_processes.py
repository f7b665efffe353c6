"""skeye.processes.start_skeye: the child's output pipe is closed once it has been read to its
end, not left for the garbage collector."""

from __future__ import annotations

import time

from skeye.processes import start_skeye, stop_process


def _wait(predicate, timeout_s: float = 30.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def test_the_output_pipe_of_a_started_child_is_closed_after_its_end() -> None:
    proc, found = start_skeye(["--help"], [r"^usage: skeye"], "skeye --help", timeout_s=60)
    try:
        assert found[0].group(0) == "usage: skeye"
        assert proc.wait(60) == 0
        assert proc.stdout is not None
        assert _wait(lambda: proc.stdout.closed), "the drained pipe was left open"
    finally:
        stop_process(proc)

