"""SIGTERM always stops a skeye process that waits for it (``skeye sim``, ``skeye pilot``,
``skeye up``): a signal handler that sets the stop Event must never find the main thread
holding that Event's lock.

A ``skeye sim`` left behind by a killed test run hung for good on its SIGTERM: the signal came
while the main thread, in ``stop.wait(0.2)``, held the Event's lock, and the handler's
``stop.set()`` waited for that lock in the same thread. The child below makes that moment
certain: it sends itself SIGTERM from inside the Event's lock, if the main thread ever takes
it; else a timer sends it a second later."""

from __future__ import annotations

import subprocess
import sys
import textwrap

from tests.robustness.helpers import stopped_at_its_first_line

CHILD = textwrap.dedent("""
    import os, signal, threading
    from skeye.processes import wait_for_signal

    stop = threading.Event()
    fired = []
    original_exit = threading.Condition.__exit__

    def exit_with_a_signal(self, *args):
        # the main thread, still holding the stop Event's lock: the worst moment for SIGTERM
        if self is stop._cond and threading.current_thread() is threading.main_thread() \\
                and not fired:
            fired.append(True)
            os.kill(os.getpid(), signal.SIGTERM)
        return original_exit(self, *args)

    threading.Condition.__exit__ = exit_with_a_signal
    threading.Timer(1.0, lambda: fired or fired.append(True) or os.kill(os.getpid(),
                                                                        signal.SIGTERM)).start()
    wait_for_signal(stop)
    print("stopped", flush=True)
""")


def test_sigterm_stops_the_wait_whenever_it_comes() -> None:
    child = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True,
                           timeout=60)
    assert child.returncode == 0 and child.stdout == "stopped\n", child


def test_a_stop_signal_the_moment_the_simulator_prints_its_address_stops_it_in_order() -> None:
    """``skeye sim`` printed its control address and went on starting its image server before
    it took SIGTERM: a script (or a user) that stopped it on reading that line killed it
    outright (status -15), its recording's last records unwritten. The handlers are now in
    place before the address is printed."""
    status, out, err = stopped_at_its_first_line(["sim", "--port", "0", "--image-port", "0"])
    assert status == 0, (out, err)
    assert out.startswith("skeye sim: world") and "control protocol on" in out.splitlines()[0]
    assert out.rstrip().endswith("skeye sim: stopping"), out
