"""``skeye sim --ll-board``'s help names every option its spec takes.

How this works: the options ``parse_ll_board`` accepts are read from its own refusal of an
unknown one (which lists them), each is checked to be accepted, and ``skeye sim --help`` (the
real parser, in this process) must name each as ``key=``: a user reads the options there.
"""

from __future__ import annotations

import re

import pytest

from skeye.cli import main
from skeye.errors import ConfigError
from skeye.hil.cli import parse_ll_board

_EXAMPLE = {"robot": "hummingbird", "start": "Pad1", "baud": "57600", "serial_timeout": "1",
            "rate": "1"}
"""A value each option takes (baud on a serial line)."""


def ll_board_options() -> list[str]:
    with pytest.raises(ConfigError, match="unknown option") as refused:
        parse_ll_board("R1=pty,no_such_option=1")
    listed = re.search(r"\(([\w, ]+)\)$", str(refused.value))
    assert listed is not None, f"the refusal lists no options: {refused.value}"
    return [key.strip() for key in listed.group(1).split(",")]


def test_sim_help_names_every_ll_board_option(capsys):
    options = ll_board_options()
    assert "serial_timeout" in options and len(options) >= 5, options
    for key in options:  # each listed option is one the parser takes
        line = "serial:/dev/ttyUSB0" if key == "baud" else "pty"
        parse_ll_board(f"R1={line},{key}={_EXAMPLE[key]}")
    with pytest.raises(SystemExit):
        main(["sim", "--help"])
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps the help's lines
    missing = [key for key in options if f"{key}=" not in text]
    assert not missing, f"skeye sim --help does not name --ll-board option(s) {missing}"


@pytest.mark.parametrize("baud", ["\u00b2", "0", "-1", "57600.5", "4000001", "99999999999"])
def test_a_baud_that_is_no_serial_rate_is_refused_naming_it(baud, capsys):
    """``--ll-board R1=serial:DEVICE,baud=...`` out of 1..4000000 or not a whole number: a
    ConfigError naming it, exit status 2 from ``skeye sim`` before anything starts. Until
    2026-11-28 a superscript digit (which ``str.isdigit`` takes and ``int`` refuses) ended
    ``skeye sim`` in a ValueError traceback, and 99999999999 was passed to the serial port."""
    with pytest.raises(ConfigError, match=rf"baud={re.escape(baud)} .*1\.\.4000000"):
        parse_ll_board(f"R1=serial:/dev/ttyUSB0,baud={baud}")
    assert main(["sim", "--port", "0", "--ll-board", f"R1=serial:/dev/ttyUSB0,baud={baud}"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and f"baud={baud}" in err, err


def test_the_start_up_line_is_a_command_a_shell_runs_as_printed(tmp_path):
    """The start-up line's ``skeye pilot`` options, pasted into a shell (docs/onboard.md says
    to), give the pilot the URIs the simulator meant. Until 2026-11-28 they were printed
    unquoted: a serial board in lockstep (``asctec-ll://serial/dev/ttyUSB0?baud=57600&lockstep=1``)
    ran the pilot in the background at ``?baud=57600`` without lockstep, and zsh refused
    the ``?`` of every URI ("no matches found"). The board here is a fake vehicle's on a real
    serial line (the far end of a pseudo-terminal); the shell is bash, as run."""
    import os
    import shlex
    import subprocess
    import time

    from skeye.hil.cli import describe
    from skeye.hil.line import open_line
    from skeye.hil.ll_server import LLBoardServer
    from tests.pilot.fake_airframe import FakeAirframe

    master, slave = os.openpty()
    device = os.ttyname(slave)
    try:
        with LLBoardServer(FakeAirframe(), open_line("serial", device=device), time.monotonic,
                           lockstep=True) as board:
            board.camera = ("Down", 0.952105)
            line = describe(board, image_port=5003)
    finally:
        os.close(slave)
        os.close(master)
    command = re.search(r"\(skeye pilot (.*)\)$", line)
    assert command, line
    (tmp_path / "a?b").write_text("")  # a file a bare "?" would match
    shell = subprocess.run(["bash", "-c", f"printf '%s\\n' {command.group(1)}"], cwd=tmp_path,
                           capture_output=True, text=True, timeout=10)
    assert shell.returncode == 0, shell.stderr
    assert shell.stdout.splitlines() == [
        "--airframe", f"asctec-ll://serial{device}?baud=57600&lockstep=1",
        "--camera", "sim://127.0.0.1:5003/R1/Down?fov_rad=0.952105"], line
    assert shlex.split(command.group(1))[1].endswith("&lockstep=1")


def test_rate_on_a_realtime_simulator_is_refused_not_ignored(capsys):
    """``rate=R`` makes the board drive a lockstep simulator's clock; on a realtime one
    (``--mode realtime``, the default) it was taken and ignored without a word, the board
    running at real time whatever R said. It is refused naming it, exit 2, before anything
    starts."""
    assert main(["sim", "--port", "0", "--ll-board", "R1=pty,rate=2"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "rate=2" in err and "--mode lockstep" in err, err
