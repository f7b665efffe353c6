"""Install skeye with ``pip`` and show what the install is doing while it runs.

``make run`` and ``make test`` call ``python skeye/buildprogress.py [pip install arguments]``
instead of a quiet ``pip install``: the install (dependencies, then mypyc and the C compiler on
the simulator's hot path, see setup.py) takes minutes on a slow machine, and a silent terminal
looks hung. This runs ``pip install -v ARGS``, prints each ``skeye setup:`` progress line and
pip's own milestones (which package it collects, what it installs) with the time since the
start, and hides the rest. On failure it prints the last 60 lines pip wrote and exits with
pip's status.

It runs before skeye is installed, so it imports only the standard library.
"""

from __future__ import annotations

import subprocess
import sys
import time
from collections import deque
from collections.abc import Sequence

_MILESTONES = ("Collecting ", "Installing collected packages", "Successfully installed",
               "Building editable", "Building wheel", "Created wheel")


def progress_line(line: str) -> str | None:
    """The part of one pip output line worth showing, or None to hide it."""
    text = line.strip()
    if "skeye setup:" in text:
        return text[text.index("skeye setup:"):]
    for start in _MILESTONES:
        if text.startswith(start):
            return text if len(text) <= 120 else text[:117] + "..."
    return None


def main(argv: Sequence[str]) -> int:
    cmd = [sys.executable, "-m", "pip", "install", "-v", "--progress-bar", "off", *argv]
    started = time.monotonic()
    print(f"skeye install: pip install {' '.join(argv)} (progress below; the simulator's "
          "compile is the long step)", flush=True)
    tail: deque[str] = deque(maxlen=60)
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                          errors="replace") as pip:
        assert pip.stdout is not None
        for line in pip.stdout:
            tail.append(line.rstrip("\n"))
            shown = progress_line(line)
            if shown is not None:
                print(f"[{time.monotonic() - started:5.0f} s] {shown}", flush=True)
        status = pip.wait()
    if status != 0:
        print("skeye install: pip failed; its last lines:", file=sys.stderr)
        print("\n".join(tail), file=sys.stderr, flush=True)
    else:
        print(f"skeye install: done in {time.monotonic() - started:.0f} s", flush=True)
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
