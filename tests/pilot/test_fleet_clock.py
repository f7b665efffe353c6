"""Two ``skeye pilot --lockstep-sync`` on one lockstep simulator keep the clock together: each
steps its robot's control period with ``STEP {Sync true}`` (skeye.sim.clock_barrier), so the world
advances once for both, and each pilot's steps add up to the world's own. With plain STEPs they
added up to twice the world's: sim time ran at twice each pilot's pace, and each robot's
control ticked every other period of its own."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from contextlib import ExitStack

from tests.control.conftest import sim_running
from tests.robustness.helpers import wait_for

COUNT = re.compile(rb"^STEP \{Count (\d+)\}")


def test_two_pilots_in_lockstep_each_step_as_far_as_the_world(tmp_path) -> None:
    asked: dict[int, int] = {}  # connection -> physics steps its STEPs asked for

    def observe(conn_id: int, direction: str, data: bytes) -> None:
        m = COUNT.match(data) if direction == "<" else None
        if m:
            asked[conn_id] = asked.get(conn_id, 0) + int(m.group(1))

    with ExitStack() as stack:
        handle = stack.enter_context(sim_running())
        handle.server.observers.append(observe)
        sim = handle.runner.sim
        for name, where in (("R1", ["--start", "Pad1"]), ("R2", ["--location", "3,0,0"])):
            err = stack.enter_context(open(tmp_path / f"{name}.err", "w"))
            pilot = subprocess.Popen(
                [sys.executable, "-m", "skeye.cli", "pilot", "--sim", handle.address, "--port",
                 "0", "--name", name, *where, "--lockstep-rate", "5", "--lockstep-sync"],
                stdout=subprocess.DEVNULL, stderr=err, stdin=subprocess.DEVNULL)
            stack.callback(pilot.wait, 30)
            stack.callback(pilot.send_signal, signal.SIGINT)
        assert wait_for(lambda: len(asked) == 2, 120), (
            asked, (tmp_path / "R1.err").read_text(), (tmp_path / "R2.err").read_text())
        start_steps, start_asked = sim.steps, dict(asked)
        deadline = time.monotonic() + 300  # a stuck stack, not a slow one
        while sim.steps < start_steps + 2000:  # 2 s of sim time, 40 periods of each pilot
            assert time.monotonic() < deadline, "the pilots stopped stepping"
            time.sleep(0.05)
        world, mine = sim.steps - start_steps, {c: asked[c] - start_asked[c] for c in asked}
    # each pilot's steps follow the world's, a control period (50 steps) either way at the ends
    assert all(abs(steps - world) <= 100 for steps in mine.values()), (world, mine)
