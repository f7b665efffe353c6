"""Flight recording: the record codec, the recorder on a live server, crash safety, replay, plot."""

from __future__ import annotations

import errno
import json
import logging
import os
import re
import signal
import socket
import struct
import subprocess
import threading
import time
import tracemalloc
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from skeye.cli import main
from skeye.errors import ConfigError, LocalProtocolError, RemoteProtocolError
from skeye.recording.plotting import load_tracks, plot_recording
from skeye.recording.records import (
    DEFAULT_MAX_PARTS,
    DIRECTIONS,
    MAX_HEADER_BYTES,
    MAX_RECORD_BYTES,
    NOTE,
    RECEIVED,
    SENT,
    TRUTH,
    Record,
    Recorder,
    RecordingReader,
    format_header,
    format_record,
    parse_header,
    parse_record,
    split_lines,
)
from skeye.recording.replay import ReplayServer
from tests.robustness.helpers import (
    sim_process,
    skeye_under_a_file_size_limit,
    stopped_at_its_first_line,
    wait_for,
)
from tests.sim.conftest import LineClient, running_sim

STREAM_TIMEOUT_S = 60.0
"""Longest wait for the simulator's first reading after INIT (a loaded machine)."""
LINE_TEXT = st.text(
    st.characters(exclude_categories=["Cs"], exclude_characters="\r\n"), max_size=80
)
RECORDS = st.builds(
    Record,
    st.floats(0, 4e9, allow_nan=False),
    st.floats(0, 1e6, allow_nan=False),
    st.integers(0, 10**6),
    st.sampled_from(sorted(DIRECTIONS)),
    LINE_TEXT,
)


@given(RECORDS)
def test_record_round_trip(record: Record) -> None:
    back = parse_record(format_record(record).decode())
    assert back.conn == record.conn and back.direction == record.direction
    assert back.line == record.line
    assert back.wall_s == pytest.approx(record.wall_s, abs=1e-6)
    assert back.sim_s == pytest.approx(record.sim_s, abs=1e-6)


@given(st.text(max_size=120))
def test_parse_record_gives_a_record_or_a_protocol_error(text: str) -> None:
    try:
        parse_record(text)
    except RemoteProtocolError:
        pass


def test_record_rejects_line_breaks_and_unknown_directions() -> None:
    with pytest.raises(LocalProtocolError, match="line break"):
        Record(0.0, 0.0, 1, SENT, "SEN {Time 1}\r\nSEN")
    with pytest.raises(LocalProtocolError, match="direction"):
        Record(0.0, 0.0, 1, "?", "x")
    with pytest.raises(RemoteProtocolError, match="not a skeye recording"):
        parse_header("hello")
    assert parse_header(format_header({"world": "pad"}).decode()) == {"world": "pad"}


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"timestep_s": "fast"}, "timestep_s must be a number of seconds > 0, got 'fast'"),
        ({"timestep_s": -0.001}, "timestep_s must be a number of seconds > 0"),
        ({"world": 5}, "world must be a string, got 5"),
        ({"seed": 1.5}, "seed must be a whole number"),
    ],
)
def test_a_header_setting_of_the_wrong_kind_is_refused_when_the_file_opens(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], settings: dict, message: str
) -> None:
    """Not when a reader first uses it: a replay started, then failed every client with a
    ValueError on a header's "timestep_s": "fast"."""
    path = tmp_path / "bad.rec"
    path.write_bytes(format_header(settings) + format_record(Record(1.0, 0.1, 1, SENT, "PING")))
    with pytest.raises(RemoteProtocolError, match=re.escape(message)):
        RecordingReader(path)
    for command in (["replay", str(path), "--port", "0"], ["plot", str(path), "--out",
                                                            str(tmp_path / "p.png")]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("header", "message"),
    [
        (b'{"seed": ' + b"9" * 5000 + b"}", "JSON this program cannot read: Exceeds the limit"),
        (b"[" * 20_000 + b"]" * 20_000, "JSON this program cannot read: maximum recursion"),
        (b"{nope", "recording header is not JSON"),
    ],
)
def test_a_header_json_cannot_take_is_refused_naming_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], header: bytes, message: str
) -> None:
    """A 5000-digit seed or deeply nested JSON raised ValueError and RecursionError from the
    json module: a traceback from skeye replay and skeye plot. Header refusals did not name
    the file either, as the others do."""
    path = tmp_path / "bad.rec"
    path.write_bytes(b"#skeye-recording 1 " + header + b"\n"
                     + format_record(Record(1.0, 0.1, 1, SENT, "PING")))
    with pytest.raises(RemoteProtocolError, match=f"^{re.escape(str(path))}: .*{message}"):
        RecordingReader(path)
    for command in (["replay", str(path), "--port", "0"], ["plot", str(path), "--out",
                                                            str(tmp_path / "p.png")]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert f"error: {path}: recording header" in err and "Traceback" not in err
    assert not (tmp_path / "p.png").exists()


@pytest.mark.parametrize("newline", [b"\n", b""])
def test_a_first_line_longer_than_any_header_is_refused_unread(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], newline: bytes
) -> None:
    """A 200 MB "world" was read whole (skeye plot held 900 MB), kept by skeye replay and read
    again before each client's first line; a file of 300 MB without a line break was read
    whole before "no complete header line". No header is longer than 64 KiB: the recorder
    writes none, and readers read no further."""
    path = tmp_path / "huge.rec"
    huge = {"world": "x" * (MAX_HEADER_BYTES + 1)}
    path.write_bytes(format_header({})[:-1].replace(b"{}", json.dumps(huge).encode()) + newline
                     + format_record(Record(1.0, 0.1, 1, SENT, "PING")))
    with pytest.raises(RemoteProtocolError, match=re.escape(
            f"{path}: not a skeye recording (a first line longer than 64 KiB")):
        RecordingReader(path)
    assert main(["plot", str(path), "--out", str(tmp_path / "p.png")]) == 2
    assert "a first line longer than 64 KiB" in capsys.readouterr().err
    with pytest.raises(LocalProtocolError, match="the most is 64 KiB"):
        Recorder(tmp_path / "new.rec", huge)
    assert not (tmp_path / "new.rec").exists()
    (tmp_path / "edge.rec").write_bytes(b"#skeye-recording 1 {}" + b" " * (MAX_HEADER_BYTES - 21)
                                        + b"\n" + format_record(Record(1.0, 0.1, 1, SENT, "PING")))
    assert [r.line for r in RecordingReader(tmp_path / "edge.rec").records()] == ["PING"]
    # Settings whose header fits, but not once a later part names itself and the one it
    # continues: refused at the start when parts are to be written (it was refused in the
    # writer thread at the first rotation).
    clock = lambda: 1718000000.5  # noqa: E731
    rotated = {"started_unix_s": clock(), "world": "", "part": DEFAULT_MAX_PARTS,
               "continues": f"near.rec.{DEFAULT_MAX_PARTS}"}
    near = {"world": "x" * (MAX_HEADER_BYTES + 1 - len(format_header(rotated)) + 1)}
    with Recorder(tmp_path / "near.rec", near, wall_clock=clock):
        pass  # one part: it fits
    with pytest.raises(LocalProtocolError, match="the most is 64 KiB"):
        Recorder(tmp_path / "near2.rec", near, wall_clock=clock, rotate=True)


def test_a_replay_on_a_taken_port_names_it_and_the_option_that_moves_it(
    recording: tuple[Path, bytes], capsys: pytest.CaptureFixture[str]
) -> None:
    """3000 is the simulator's port too: with a simulator running, the replay said only
    ``[Errno 98] Address already in use (while attempting to bind on address (...))``."""
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        assert main(["replay", str(recording[0]), "--port", str(port)]) == 2
    err = capsys.readouterr().err
    assert (f"skeye replay: error: port {port} on 127.0.0.1 (for the replay) is already in "
            "use") in err, err
    assert "move the replay with --port PORT" in err and "Errno" not in err, err


def test_a_directory_is_named_as_one_and_out_without_extension_is_said_as_written(
    recording: tuple[Path, bytes], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "flight.rec"
    folder.mkdir()
    for command in (["replay", str(folder), "--port", "0"], ["plot", str(folder)]):
        assert main(command) == 2
        assert f"{folder} is a directory, not a recording file" in capsys.readouterr().err
    assert main(["plot", str(recording[0]), "--out", str(tmp_path)]) == 2
    assert f"--out {tmp_path} is a directory" in capsys.readouterr().err
    assert main(["plot", str(recording[0]), "--out", str(tmp_path / "noext")]) == 0
    assert f"wrote {tmp_path / 'noext.png'}" in capsys.readouterr().out
    assert (tmp_path / "noext.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_folder_given_as_the_recording_is_named_before_an_out_inside_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """`skeye plot .` (the default --out, plot.png, in the current folder) and `skeye plot
    FOLDER --out FOLDER/plot.png` said `--out ... is inside the recording FOLDER: ... write it
    elsewhere`; written elsewhere, the run then said the folder is no recording file. The
    folder is said first."""
    monkeypatch.chdir(tmp_path)
    for command, named in ((["plot", "."], "."),
                           (["plot", str(tmp_path), "--out", str(tmp_path / "plot.png")],
                            str(tmp_path))):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert err == f"skeye plot: error: {named} is a directory, not a recording file\n", err
    assert list(tmp_path.iterdir()) == []


def test_a_pipe_or_a_device_is_named_as_no_regular_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A FIFO, /dev/null or a shell's process substitution (`skeye plot <(zcat flight.rec.gz)`,
    a /dev/fd/N pipe) was said to be `recording not found`, though it is there: it is no
    regular file, which the readers need (they seek and read a file more than once)."""
    fifo = tmp_path / "flight.rec"
    os.mkfifo(fifo)
    for path in (fifo, Path(os.devnull)):
        for command in (["replay", str(path), "--port", "0"],
                        ["plot", str(path), "--out", str(tmp_path / "plot.png")]):
            assert main(command) == 2
            err = capsys.readouterr().err
            assert err == (f"skeye {command[0]}: error: {path} is not a regular file (a pipe, a "
                           "device or a socket): give the recording file itself\n"), err
    assert [p.name for p in tmp_path.iterdir()] == ["flight.rec"]


def test_plot_never_writes_over_the_recording_it_draws(
    recording: tuple[Path, bytes], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`skeye plot flight.png --out flight.png` read the recording, then wrote the plot over
    it: the flight was lost. So did `--out flight`, which writes flight.png."""
    path = tmp_path / "flight.png"
    data = recording[0].read_bytes()
    path.write_bytes(data)
    for out in (path, tmp_path / "flight", tmp_path / "." / "flight.png"):
        assert main(["plot", str(path), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert f"is the recording {path} itself" in err and "Traceback" not in err
    assert path.read_bytes() == data


def test_a_pgf_plot_without_tex_is_refused_before_the_recording_is_read(
    recording: tuple[Path, bytes], tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """`--out plot.pgf` is a format matplotlib lists, but it runs xelatex to write it: without
    one, skeye plot (and skeye logs --plot, the same check) ended in a RuntimeError traceback.
    PATH names an empty folder here, so no TeX is found whatever the machine has."""
    monkeypatch.setenv("PATH", str(tmp_path))
    out = tmp_path / "plot.pgf"
    assert main(["plot", str(recording[0]), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"skeye plot: error: --out {out}: .pgf files need xelatex" in err
    assert "Traceback" not in err and not out.exists()


def test_a_plot_that_cannot_be_written_keeps_the_image_that_was_there(
    recording: tuple[Path, bytes], tmp_path: Path
) -> None:
    """skeye plot wrote its image in place: a write that failed part-way (a full disk; here
    the process's file size limit, ``ulimit -f``, which fails a write past it with EFBIG as a
    full disk does) cut the good plot already there short, and the error named neither the
    file nor the option (`skeye plot: error: [Errno 27] File too large`). The image is now
    written beside and renamed over: the old one is left as it was, and no partial file."""
    out = tmp_path / "plot.png"
    assert main(["plot", str(recording[0]), "--out", str(out)]) == 0
    before = out.read_bytes()
    limit = 4096
    assert len(before) > limit
    run = skeye_under_a_file_size_limit(["plot", str(recording[0]), "--out", str(out)], limit)
    assert run.returncode == 2, run.stderr
    assert run.stderr == f"skeye plot: error: --out {out}: cannot write it: File too large\n"
    assert out.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["plot.png"]


def test_reader_skips_a_cut_off_last_line_and_bad_lines(tmp_path: Path) -> None:
    path = tmp_path / "cut.rec"
    good = [Record(1.0, 0.1, 1, SENT, "SEN {Time 0.1}"), Record(2.0, 0.2, 1, RECEIVED, "PING")]
    body = b"".join(format_record(r) for r in good)
    path.write_bytes(format_header({}) + body[:20] + b"garbage\n" + body + b"3.0 0.3 1 > SEN {Ti")
    reader = RecordingReader(path)
    assert list(reader.records())[-2:] == good
    assert reader.truncated and reader.bad_lines == 1


def test_a_line_too_long_for_a_record_is_counted_and_skipped_without_being_held(
    tmp_path: Path
) -> None:
    """A damaged file's line of 20 MiB was read whole (skeye plot took 272 MB of memory for a
    50 MB line, and would have taken all of it for a line of gigabytes), and skeye replay sent
    it to its clients as a STA line. A line longer than MAX_RECORD_BYTES is now counted with
    the bad lines and read past a piece at a time; one that runs to the file's end is a line
    cut off."""
    path = tmp_path / "long.rec"
    good = [Record(1.0, 0.1, 1, SENT, "STA {Name R1}"), Record(2.0, 0.2, 1, SENT, "STA {Name R1}")]
    long_line = b"1.5 0.15 1 > STA {Name R1} " + b"x" * (20 * MAX_RECORD_BYTES) + b"\n"
    edge = format_record(Record(1.6, 0.16, 1, SENT, "STA {Name R1} {X "))
    edge = edge[:-1] + b"y" * (MAX_RECORD_BYTES - len(edge)) + b"}\n"  # just fits
    assert len(edge) == MAX_RECORD_BYTES + 1
    path.write_bytes(format_header({}) + format_record(good[0]) + long_line + edge
                     + format_record(good[1]) + long_line[:-1])
    reader = RecordingReader(path)
    tracemalloc.start()
    try:
        records = list(reader.records())
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert [r.line[:13] for r in records] == ["STA {Name R1}"] * 3
    assert records[0] == good[0] and records[2] == good[1]
    assert reader.bad_lines == 1 and reader.truncated
    assert peak < 8 * MAX_RECORD_BYTES, peak  # the line that fits is held, in a few forms


def test_recorder_refuses_to_overwrite(tmp_path: Path) -> None:
    path = tmp_path / "exists.rec"
    path.write_text("precious")
    with pytest.raises(ConfigError, match="already exists"):
        Recorder(path)
    assert path.read_text() == "precious"
    with pytest.raises(ConfigError, match="cannot create"):
        Recorder(tmp_path / "no-such-folder" / "x.rec")


def test_a_recording_named_as_a_folder_is_refused_as_one(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """`skeye sim --record FOLDER` said `recording FOLDER already exists; choose another name or
    delete it`, and `--record ""` (the folder ".") told the user to delete the current
    folder. A folder is named as one; an empty name is no name (refused with the option)."""
    monkeypatch.chdir(tmp_path)
    command = ["sim", "--mode", "lockstep", "--port", "0", "--record"]
    assert main([*command, str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err == (f"skeye sim: error: recording {tmp_path} is a directory: give a file name "
                   "for the recording\n"), err
    with pytest.raises(SystemExit) as refused:
        main([*command, ""])
    assert refused.value.code == 2
    assert "argument --record: must name a file or folder, got ''" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_a_recording_being_written_is_said_to_be_and_not_offered_for_deletion(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A second simulator given the file a first one was recording to said `recording FILE
    already exists; choose another name or delete it`: deleting it would have lost the first
    one's flight. A recorder now holds its file's lock while it writes, and the second is
    told the file is being written; once the first ends, it is a file that exists."""
    path = tmp_path / "flight.rec"
    command = ["sim", "--mode", "lockstep", "--port", "0", "--record", str(path)]
    with Recorder(path, {"world": "pad"}):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert err == (f"skeye sim: error: recording {path} is being written by another "
                       "process (a simulator recording now); choose another name\n"), err
    assert main(command) == 2
    assert "already exists; choose another name or delete it" in capsys.readouterr().err
    assert list(RecordingReader(path).records()) == []


def test_recorder_flushes_within_a_second_without_closing(tmp_path: Path) -> None:
    path = tmp_path / "flush.rec"
    with Recorder(path, flush_interval_s=0.5) as rec:
        rec.observe(3, RECEIVED, b"PING {Id 1}")
        # Flushed by the timer (0.5 s), not by closing; the deadline only bounds a busy host.
        assert wait_for(lambda: b"PING {Id 1}" in path.read_bytes(), timeout_s=30.0)
    assert [r.line for r in RecordingReader(path).records()] == ["PING {Id 1}"]


def test_recorder_counts_what_it_drops(tmp_path: Path) -> None:
    path = tmp_path / "drop.rec"
    rec = Recorder(path, queue_records=1, flush_interval_s=1.0)
    for i in range(2000):
        rec.observe(1, RECEIVED, b"PING {Id %d}" % i)
    rec.close()
    records = list(RecordingReader(path).records())
    notes = [r.line for r in records if r.direction == NOTE]
    assert rec.dropped > 0 and notes and "dropped" in notes[0]
    kept = sum(1 for r in records if r.direction == RECEIVED)
    assert kept + rec.dropped == 2000


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, bytes]:
    """A lockstep flight: INIT, climb, a bad line, PING; returns (file, bytes the client got)."""
    path = tmp_path_factory.mktemp("rec") / "flight.rec"
    with running_sim() as server, Recorder(path, {"world": "pad"}) as recorder:
        recorder.attach(server, server.runner, truth_rate_hz=20.0)
        client = LineClient(server.port)
        client.expect("NFO")
        assert client.answer("INIT {ClassName hummingbird} {Location 0,0,-1}", "INIT").type == "RES"
        client.step(300)
        client.send("DRIVE {AltitudeVelocity 0.5} {LinearVelocity 1}")
        client.step(1200)
        assert client.answer("NOPE {x", "NOPE").type == "ERR"
        client.answer("PING {Id last}", "PING")
        raw = bytes(client.raw)
        client.close()
        assert wait_for(lambda: server.client_count == 0)
    return path, raw


def test_recording_holds_every_line_sent_and_received(recording: tuple[Path, bytes]) -> None:
    path, client_bytes = recording
    reader = RecordingReader(path)
    records = list(reader.records())
    assert reader.header["world"] == "pad" and not reader.truncated and reader.bad_lines == 0
    sent = b"".join(r.line.encode() + b"\r\n" for r in records if r.direction == SENT)
    assert sent == client_bytes  # byte for byte, in order
    received = [r.line for r in records if r.direction == RECEIVED]
    assert received[0] == "INIT {ClassName hummingbird} {Location 0,0,-1}"
    assert [line.split()[0] for line in received] == [
        "INIT",
        "STEP",
        "DRIVE",
        "STEP",
        "NOPE",
        "PING",
    ]
    assert [r.direction for r in records if r.direction in "+-"] == ["+", "-"]
    truth = [r for r in records if r.direction == TRUTH]
    assert len(truth) == pytest.approx(1.5 * 20, abs=2)
    assert all(r.line.startswith("TRUTH {Name R1}") for r in truth)
    sims = [r.sim_s for r in records]
    assert sims == sorted(sims)


def test_plot_draws_and_summarises(recording: tuple[Path, bytes], tmp_path: Path) -> None:
    path, _ = recording
    tracks, summary = load_tracks(path)
    track = tracks["R1"]
    assert len(track.time_s) == summary.robots["R1"]["samples"]
    assert len(track.time_s) >= 28
    altitudes = [-p[2] for p in track.pos_ned_m]
    assert altitudes[0] == pytest.approx(1.0, abs=0.05) and max(altitudes) > 1.3
    assert track.commands["DRIVE"] == 1 and track.commands["INIT"] == 1
    assert summary.connections == 1 and summary.bad_lines == 0
    out = tmp_path / "plot.png"
    assert main(["plot", str(path), "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert plot_recording(path, tmp_path / "again.png").records == summary.records


def test_replay_plays_the_stream_paced_and_read_only(recording: tuple[Path, bytes]) -> None:
    path, client_bytes = recording
    expected = [line for line in client_bytes.split(b"\r\n") if line.startswith((b"SEN ", b"STA "))]
    with ReplayServer(path, port=0, speed=2.0) as replay:
        assert replay.host == "127.0.0.1" and replay.robot == "R1"
        # Before connecting: the playback's clock starts when the server takes the connection,
        # and timed from the NFO a loaded machine's late NFO shortened it (0.5995 s measured).
        start = time.monotonic()
        client = LineClient(replay.port)
        nfo = client.expect("NFO")
        assert nfo.get("Replay") == "true" and nfo.get("Level") == "pad"
        assert "read-only" in (
            client.answer("INIT {ClassName hummingbird}", "INIT").get("Reason") or ""
        )
        assert client.answer("DRIVE {LinearVelocity 1}", "DRIVE").type == "ERR"
        assert client.answer("STEP", "STEP").type == "ERR"
        ping = client.answer("PING {Id 9}", "PING")
        assert ping.type == "RES" and ping.get("Id") == "9"
        last_time = (
            expected[-1].split(b"{Time ", 1)[1].split(b"}")[0] if b"{Time " in expected[-1] else b""
        )
        client.read_until(
            lambda m: m.type in ("SEN", "STA") and m.get("Time") == last_time.decode(), timeout_s=10
        )
        elapsed = time.monotonic() - start
        got = [line for line in client.raw.split(b"\r\n") if line.startswith((b"SEN ", b"STA "))]
        assert got == expected
        # 1.5 s of sim time at speed 2: not before ~0.7 s of wall time.
        assert elapsed > 0.6
        client.close()
    with pytest.raises(ConfigError, match="no robot"):
        ReplayServer(path, port=0, robot="R9")


def _errors(client: LineClient, lines: tuple[str, ...]) -> list:
    """The ERR each line gets, one line at a time."""
    out = []
    for line in lines:
        client.send(line)
        out.append(client.read_until(lambda m: m.type == "ERR")[1])
    return out


def test_replay_answers_a_line_that_is_no_command_as_the_simulator_does(
        recording: tuple[Path, bytes]) -> None:
    """docs/recording.md: bad lines get the simulator's ERRs; a simulator command a replay
    cannot do keeps "not available in a replay". A PING the simulator refuses (a key it does
    not know, an Id over 1000 characters or holding a control character) the replay refused
    not: it answered, echoing the Id."""
    path, _ = recording
    lines = ("garbage", "FLY {Speed 3}", "NOPE {x", "{Name x}", "PING {Id a} {Extra 1}",
             "PING {Id \x1b[2J}", "PING {Id " + "y" * 1001 + "}")
    with running_sim(mode="realtime") as server:
        sim = LineClient(server.port)
        sim.expect("NFO")
        from_sim = _errors(sim, lines)
        sim.close()
    with ReplayServer(path, port=0) as replay:
        client = LineClient(replay.port)
        client.expect("NFO")
        from_replay = _errors(client, lines)
        assert client.answer("GETGEO {Type Robot}", "GETGEO").get("Reason") == (
            "GETGEO is not available in a replay")
        client.close()
    assert [m.fields for m in from_replay] == [m.fields for m in from_sim]
    assert from_replay[0].get("Reason") == "unknown command GARBAGE"


def test_sim_killed_loses_at_most_the_last_second(tmp_path: Path) -> None:
    """SIGKILL the simulator while it streams: every line the client had received a second
    before the kill is in the recording (the recorder fsyncs at least every 0.5 s).

    Judged on what the server sent, as the client saw it, not on the recording's last wall
    time: on a loaded machine the simulator may send nothing for seconds, and a recording that
    ends early then lost nothing (with both cores busy, the last record was once 2.02 s older
    than the kill)."""
    path = tmp_path / "crash.rec"
    received: list[tuple[float, str]] = []  # (wall time it arrived, line)
    with sim_process("--record", str(path)) as (proc, ports, banner):
        assert any("127.0.0.1 only" in line for line in banner)
        sock = socket.create_connection(("127.0.0.1", ports["control"]))
        sock.settimeout(STREAM_TIMEOUT_S)
        sock.sendall(b"INIT {ClassName hummingbird} {Location 0,0,-2}\r\n")
        pending = b""
        # Stream for 2.5 s of wall time after the first reading arrived (so lines from over a
        # second before the kill exist), bounded by a generous wait for that first reading.
        deadline = time.monotonic() + STREAM_TIMEOUT_S
        first_at: float | None = None
        while time.monotonic() < (deadline if first_at is None else first_at + 2.5):
            data = sock.recv(65536)
            assert data, "the simulator closed the connection"
            now = time.time()
            *lines, pending = (pending + data).split(b"\r\n")
            for line in lines:
                if line.startswith((b"SEN ", b"STA ")):
                    received.append((now, line.decode()))
                    if first_at is None:
                        first_at = time.monotonic()
        assert first_at is not None, f"no reading in {STREAM_TIMEOUT_S} s"
        killed_at = time.time()
        proc.send_signal(signal.SIGKILL)
        proc.wait(5)
        sock.close()
    reader = RecordingReader(path)
    records = list(reader.records())
    assert reader.bad_lines == 0
    sent = {r.line for r in records if r.direction == SENT}
    due = [line for at, line in received if at <= killed_at - 1.0]
    assert due, "no line arrived more than a second before the kill"
    lost = [line for line in due if line not in sent]
    assert not lost, f"{len(lost)} of {len(due)} lines sent over a second before the kill " \
        f"are not in the recording; the first: {lost[0][:80]}"
    assert any(r.direction == TRUTH for r in records)


def test_battery_panel_shows_flight_time_left_only_while_flying(
    recording: tuple[Path, bytes],
) -> None:
    from skeye.recording.plotting import RobotTrack, flight_time_left_min

    path, _ = recording
    track = load_tracks(path)[0]["R1"]
    assert len(track.battery_landed) == len(track.battery_s) > 0
    # On the ground the estimate (charge over the idle current) is hours: left out, not drawn.
    t = RobotTrack("A", battery_time_s=[0.0, 1.0, 2.0, 3.0],
                   battery_s=[31800.0, 31700.0, 600.0, 590.0],
                   battery_landed=[True, True, False, False])
    left = flight_time_left_min(t)
    assert np.isnan(left[:2]).all() and left[2:] == pytest.approx([10.0, 590 / 60])


def _flying_client(port: int) -> socket.socket:
    """A client that spawns a hovering robot: its stream fills the recording."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=30)
    sock.sendall(b"INIT {ClassName hummingbird} {Name R1} {Location 0,0,-2}\r\n")
    return sock


def _records_of(path: Path) -> list[Record]:
    lines = path.read_text().splitlines()
    assert lines[0].startswith("#skeye-recording")
    return [parse_record(line) for line in lines[1:]]


def _read_away(sock: socket.socket, stop: threading.Event) -> None:
    sock.settimeout(0.5)
    while not stop.is_set():
        try:
            if not sock.recv(1 << 16):
                return
        except TimeoutError:
            continue
        except OSError:
            return


@pytest.mark.parametrize("rotate", [False, True])
def test_a_recording_stops_or_rotates_at_its_size_limit(tmp_path: Path, rotate: bool) -> None:
    """Issue 31: a recording grew without bound (80 MB in 23 min). Now it never passes
    --record-max-mb: it stops with a note saying why, or goes on in FILE.2, FILE.3 up to
    --record-parts; the simulator serves on either way."""
    path = tmp_path / "flight.rec"
    limit = 64 * 1024
    extra = ["--record-rotate", "--record-parts", "3"] if rotate else []
    with sim_process("--record", str(path), "--record-max-mb", str(limit / 2**20),
                     *extra) as (_proc, ports, _banner):
        client = _flying_client(ports["control"])
        stop = threading.Event()
        reader = threading.Thread(target=_read_away, args=(client, stop), daemon=True)
        reader.start()
        last = tmp_path / ("flight.rec.3" if rotate else "flight.rec")
        assert wait_for(lambda: last.exists() and "recording stopped" in last.read_text(), 120)
        size = last.stat().st_size
        time.sleep(1.5)  # the stream goes on: nothing more is written
        assert last.stat().st_size == size
        with socket.create_connection(("127.0.0.1", ports["control"]), timeout=30) as s:
            f = s.makefile("rb")
            assert f.readline().startswith(b"NFO")
            s.sendall(b"PING {Id after}\r\n")
            assert f.readline().startswith(b"RES {Command PING}")  # serving on
        stop.set()
        client.close()
    parts = sorted(tmp_path.glob("flight.rec*"))
    assert len(parts) == (3 if rotate else 1), parts
    for part in parts:
        assert part.stat().st_size <= limit, (part, part.stat().st_size)
        assert _records_of(part)  # every part a whole recording
    notes = [r.line for r in _records_of(last) if r.direction == NOTE]
    assert notes and notes[-1].startswith("recording stopped: "), notes
    assert ("3 parts" in notes[-1]) if rotate else ("size limit" in notes[-1])
    if rotate:
        first = [r.line for r in _records_of(parts[0]) if r.direction == NOTE]
        assert first[-1] == "recording continues in flight.rec.2 (size limit 0.0625 MiB)"
        assert json.loads(parts[1].read_text().splitlines()[0].split(" ", 2)[2])["continues"] \
            == "flight.rec"


def test_plot_counts_a_line_whose_values_are_not_numbers_and_draws_the_rest(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A TRUTH {Battery abc} ended the plot ("Battery: 'abc' is not a number", naming no file);
    a SEN {Time abc} raised ValueError. Each is a bad line: counted, skipped."""
    init = Record(1.0, 0.0, 1, SENT, "RES {Command INIT} {Name R1} {Status OK}")
    lines = [init]
    for i, (battery, time_s) in enumerate([("100", "0.0"), ("abc", "0.05"), ("99", "abc"),
                                           ("98", "0.15")]):
        t = 0.05 * i
        lines.append(Record(1.0 + t, t, 0, TRUTH, f"TRUTH {{Name R1}} {{Time {t}}} "
                            f"{{Location 0,0,-1}} {{Battery {battery}}} {{Landed false}}"))
        lines.append(Record(1.0 + t, t, 1, SENT, f"SEN {{Time {time_s}}} {{Type GroundTruth}} "
                            "{Location 0,0,-1}"))
    path = tmp_path / "bad_values.rec"
    path.write_bytes(format_header({}) + b"".join(format_record(r) for r in lines))
    tracks, summary = load_tracks(path)
    assert summary.bad_lines == 2
    assert tracks["R1"].battery_s == [100.0, 99.0, 98.0]
    assert main(["plot", str(path), "--out", str(tmp_path / "p.png")]) == 0
    assert "bad 2" in capsys.readouterr().out


@pytest.mark.parametrize("far", ["1e308,1e308,-1", "1e308,0,-1", "0,0,-1e308", "100000.5,0,-1"])
def test_plot_skips_a_location_beyond_the_simulators_limit_and_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], far: str
) -> None:
    """A Location near 1e308 m summed to "inf m flown", and with two large coordinates
    matplotlib's tick locator raised OverflowError (a traceback). The simulator stops a robot
    beyond MAX_POSITION_M (100 km), so such a line is counted with the bad lines, skipped, and
    the summary says why; the coordinate is checked in each track (TRUTH and SEN)."""
    init = Record(1.0, 0.0, 1, SENT, "RES {Command INIT} {Name R1} {Status OK}")
    lines = [init]
    for i, location in enumerate(["0,0,-1", far, "3,4,-1"]):
        t = 0.05 * i
        lines.append(Record(1.0 + t, t, 0, TRUTH, f"TRUTH {{Name R1}} {{Time {t}}} "
                            f"{{Location {location}}} {{Battery 100}} {{Landed false}}"))
        lines.append(Record(1.0 + t, t, 1, SENT, f"SEN {{Time {t}}} {{Type GroundTruth}} "
                            f"{{Location {location}}}"))
    path = tmp_path / "far.rec"
    path.write_bytes(format_header({}) + b"".join(format_record(r) for r in lines))
    tracks, summary = load_tracks(path)
    assert summary.bad_lines == summary.far_positions == 2
    assert tracks["R1"].pos_ned_m == [(0.0, 0.0, -1.0), (3.0, 4.0, -1.0)]
    assert summary.robots["R1"]["distance_m"] == 5.0
    assert main(["plot", str(path), "--out", str(tmp_path / "p.png")]) == 0
    out = capsys.readouterr().out
    assert ("bad 2 (2 with a Location beyond 100000 m of the origin, the simulator's limit: "
            "skipped)") in out
    assert "R1: 2 samples, 5.00 m flown, altitude 1.00..1.00 m" in out


def test_plot_counts_a_location_that_is_not_three_numbers(tmp_path: Path) -> None:
    """Such a sample was dropped without a word; it is a bad line as a Battery abc is."""
    lines = [Record(1.0 + 0.05 * i, 0.05 * i, 0, TRUTH, f"TRUTH {{Name R1}} {{Location {loc}}}")
             for i, loc in enumerate(["0,0,-1", "1,2", "0,abc,-1", "0,0,-2"])]
    path = tmp_path / "odd.rec"
    path.write_bytes(format_header({}) + b"".join(format_record(r) for r in lines))
    tracks, summary = load_tracks(path)
    assert (summary.bad_lines, summary.far_positions) == (2, 0)
    assert tracks["R1"].pos_ned_m == [(0.0, 0.0, -1.0), (0.0, 0.0, -2.0)]


def test_replay_plays_the_crash_the_client_was_told_of(tmp_path: Path) -> None:
    """A replay left out ``ERR {Command CRASH}``: its stream lines were those of before the
    crash report existed (STA, SEN, ERR PHYSICS), so a client watching a crashed flight saw
    the readings go on and never the crash. Now the replay sends every engine line its client
    was sent, in order: the crash with its cause among them; not the answer to a command of the
    client's that happened to be named CRASH."""
    path = tmp_path / "crash.rec"
    with running_sim() as server, Recorder(path, {"world": "pad"}) as recorder:
        recorder.attach(server, server.runner, truth_rate_hz=0)
        client = LineClient(server.port)
        client.expect("NFO")
        assert client.answer("INIT {ClassName hummingbird} {Location 0,0,-3}", "INIT").type == "RES"
        # an answer to the client's own command named CRASH, not the engine's crash report
        assert client.answer("CRASH", "CRASH").type == "ERR"
        client.step(100)
        client.send("DRIVE {RollAngle 0} {PitchAngle 0} {Thrust 0}")  # motors off: a free fall
        crash = None
        for _ in range(30):  # 3 s of sim time; a 3 m fall takes 0.8 s
            crash = next((m for m in client.step(100)
                          if m.type == "ERR" and m.get("Command") == "CRASH"), None)
            if crash is not None:
                break
        assert crash is not None, "the free fall was not reported as a crash"
        client.step(100)
        raw = bytes(client.raw)
        client.close()
        assert wait_for(lambda: server.client_count == 0)
    assert b"ERR {Command CRASH} {Reason unknown command" in raw
    engine = [line for line in raw.split(b"\r\n")
              if line.startswith((b"SEN ", b"STA ", b"ERR {Command CRASH} {Name R1}"))]
    assert engine[-1].startswith(b"S"), "no reading after the crash to order it against"
    with ReplayServer(path, port=0, speed=1000.0) as replay:
        player = LineClient(replay.port)
        player.expect("NFO")
        player.read_until(lambda _m: engine[-1] + b"\r\n" in player.raw)
        got = [line for line in player.raw.split(b"\r\n")
               if line.startswith((b"SEN ", b"STA ", b"ERR "))]
        player.close()
    assert got == engine
    assert b"ERR {Command CRASH} {Name R1} {Reason crashed: hard impact" in b"\n".join(got)


def test_a_later_part_of_a_rotated_recording_replays_and_plots_on_its_own(
        tmp_path: Path) -> None:
    """docs/recording.md: each part of a rotated recording is a whole recording. Yet a later
    part could not be replayed (``holds no robot (no INIT was answered)``: the INIT answer is in
    part 1) and its plot gave the robot none of the commands its client sent there. The robot's
    connection is now also known by the ``{Name}`` of the STA lines it was sent, which every
    part holds."""
    parts = _record_rotated(tmp_path / "flight.rec", 2)
    # The DRIVE is in part 2, or in a later one where the writer, behind the engine on a busy
    # machine, was still filling part 2 with earlier readings when the test saw it opened.
    holding = [p for p in parts[1:] if any(r.direction == RECEIVED and r.line.startswith("DRIVE")
                                           for r in RecordingReader(p).records())]
    assert len(holding) == 1, parts
    (later,) = holding
    records = list(RecordingReader(later).records())
    assert not any(r.line.startswith("RES {Command INIT}") for r in records)
    tracks, _summary = load_tracks(later)
    assert tracks["R1"].commands["DRIVE"] == 1
    engine = [r.line.encode() for r in records if r.direction == SENT
              and r.line.startswith(("SEN ", "STA "))]
    with ReplayServer(later, port=0, speed=1000.0) as replay:
        assert replay.robot == "R1"
        player = LineClient(replay.port)
        player.expect("NFO")
        player.read_until(lambda _m: engine[-1] + b"\r\n" in player.raw)
        got = [line for line in player.raw.split(b"\r\n") if line.startswith((b"SEN ", b"STA "))]
        player.close()
    assert got == engine


def test_a_recording_that_cannot_be_written_stops_and_the_simulator_still_ends_cleanly(
        tmp_path: Path) -> None:
    """A write that fails (EFBIG past ``ulimit -f`` here; a full disk or a failing device
    alike) stopped the recording with one log line, and the simulator served on, but on Ctrl-C
    ``skeye sim`` ended with ``skeye sim: error: [Errno 27] File too large`` and exit status 2:
    closing the file tried again to write what the failed write had left buffered. Now the
    failure is said once, naming the file, the simulator stops as usual (exit 0), and what was
    written before the failure reads back (the last line, cut off, skipped)."""
    path = tmp_path / "flight.rec"
    output: list[str] = []
    failed = threading.Event()

    def read_output(proc: subprocess.Popen[str]) -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            output.append(line.rstrip("\n"))
            if "write failed" in line:
                failed.set()

    with sim_process("--record", str(path), max_file_bytes=40_000) as (proc, ports, _banner):
        client = _flying_client(ports["control"])
        stop = threading.Event()
        threading.Thread(target=_read_away, args=(client, stop), daemon=True).start()
        watcher = threading.Thread(target=read_output, args=(proc,), daemon=True)
        watcher.start()
        assert failed.wait(STREAM_TIMEOUT_S), f"no write failure logged: {output[-5:]}"
        proc.send_signal(signal.SIGINT)
        assert proc.wait(30) == 0, output[-5:]
        watcher.join(10)
        stop.set()
        client.close()
    said = [line for line in output if str(path) in line and "write failed" in line]
    assert len(said) == 1 and "File too large" in said[0], output
    assert not [line for line in output if "error:" in line], output
    reader = RecordingReader(path)
    records = list(reader.records())
    assert reader.bad_lines == 0 and any(r.direction == TRUTH for r in records)
    assert path.stat().st_size <= 40_000


@pytest.fixture(scope="module")
def rotated(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """A lockstep flight recorded into parts of 64 KiB (--record-rotate): the INIT in the
    first part, a DRIVE in a later one; returns the parts in order."""
    return _record_rotated(tmp_path_factory.mktemp("rotated") / "flight.rec", 3)


def _record_rotated(path: Path, parts: int) -> list[Path]:
    """A lockstep flight recorded into parts of 64 KiB (--record-rotate) until the recording
    goes on in part ``parts``, then a DRIVE sent (queued after that part was opened) and the
    client gone; the parts in order, the recorder closed."""
    with running_sim() as server, Recorder(path, {"world": "pad"}, max_bytes=64 * 1024,
                                           rotate=True) as recorder:
        recorder.attach(server, server.runner)
        client = LineClient(server.port)
        client.expect("NFO")
        assert client.answer("INIT {ClassName hummingbird} {Location 0,0,-2}", "INIT").type == "RES"
        for _ in range(40 * parts):  # 64 KiB is about 1.2 s of sim time of one robot
            client.step(100)
            recorder.sync(timeout_s=60.0)  # the writer thread lags behind on a busy machine
            if len(recorder.parts) >= parts:
                break
        assert len(recorder.parts) == parts, f"the recording did not go on in part {parts}"
        client.send("DRIVE {AltitudeVelocity 0.5}")
        client.step(300)
        client.close()
        assert wait_for(lambda: server.client_count == 0)
    return list(recorder.parts)


def test_a_rotated_recording_replays_and_plots_as_one_flight_from_its_first_part(
        rotated: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`skeye replay flight.rec` and `skeye plot flight.rec` of a recording made with
    --record-rotate played and drew flight.rec alone: the rest of the flight, in flight.rec.2,
    flight.rec.3, ..., was left out, and the plot counted none of the commands sent there.
    Naming the first part now reads the parts that continue it, in order, as one flight."""
    per_part = [list(RecordingReader(p).records()) for p in rotated]
    engine = [r.line.encode() for records in per_part for r in records
              if r.direction == SENT and r.line.startswith(("SEN ", "STA "))]
    truth = sum(1 for records in per_part for r in records if r.direction == TRUTH)
    with ReplayServer(rotated[0], port=0, speed=1000.0) as replay:
        assert replay.robot == "R1"
        player = LineClient(replay.port)
        player.expect("NFO")
        player.read_until(lambda _m: engine[-1] + b"\r\n" in player.raw, timeout_s=10)
        got = [line for line in player.raw.split(b"\r\n") if line.startswith((b"SEN ", b"STA "))]
        player.close()
    assert got == engine  # every part's stream, in order, once
    tracks, summary = load_tracks(rotated[0])
    assert summary.parts == [str(p) for p in rotated] and summary.broken is None
    assert summary.connections == 1  # the one connection, opened in part 1, runs on
    assert len(tracks["R1"].time_s) == truth
    assert tracks["R1"].commands["INIT"] == 1 and tracks["R1"].commands["DRIVE"] == 1
    out = tmp_path / "flight.png"
    assert main(["plot", str(rotated[0]), "--out", str(out)]) == 0
    names = ", ".join(p.name for p in rotated)
    assert f"{rotated[0]} ({len(rotated)} parts: {names}): " in capsys.readouterr().out
    # A later part named on its own is read alone, as before.
    assert RecordingReader(rotated[1], follow_parts=True).parts == [rotated[1]]


def test_a_missing_or_foreign_part_ends_the_flight_there_and_is_named(
        rotated: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A flight whose second part is missing, or is not the part that continues the first
    (another part, another recording's), is read up to the part before it, and the file is
    named with what is wrong."""
    first = tmp_path / "flight.rec"
    first.write_bytes(rotated[0].read_bytes())
    part1 = list(RecordingReader(rotated[0]).records())
    second = tmp_path / "flight.rec.2"
    header, body = rotated[1].read_bytes().split(b"\n", 1)
    meta = parse_header(header.decode())
    cases = [
        (None, f"{first} ends saying the recording continues in {second}, which is missing"),
        (rotated[2].read_bytes(), f"{first} ends saying the recording continues in {second}, "
         "but that file is not part 2 continuing flight.rec: its header says part 3, "
         "continuing 'flight.rec.2'"),
        (format_header({**meta, "world": "yard"}) + body,
         f"{first} ends saying the recording continues in {second}, but that file is another "
         f"recording's part: its world differ from {first}'s"),
    ]
    for data, said in cases:
        second.unlink(missing_ok=True)
        if data is not None:
            second.write_bytes(data)
        _tracks, summary = load_tracks(first)
        assert summary.broken == said and summary.parts == [str(first)]
        assert summary.records == len(part1)
        assert main(["plot", str(first), "--out", str(tmp_path / "p.png")]) == 0
        assert f"warning: {said}: the flight is read up to there" in capsys.readouterr().out
        with ReplayServer(first, port=0) as replay:
            assert replay.reader.parts == [first] and replay.reader.broken == said


def _fd_of(path: Path) -> int:
    """The descriptor this process holds open on ``path`` (Linux /proc)."""
    for fd in os.listdir("/proc/self/fd"):
        try:
            if os.readlink(f"/proc/self/fd/{fd}") == str(path):
                return int(fd)
        except OSError:
            continue
    raise AssertionError(f"{path} is not open")


@pytest.mark.parametrize("how", ["size limit", "failed write"])
def test_a_stopped_recording_counts_what_it_does_not_write_and_says_so_at_close(
        tmp_path: Path, caplog: pytest.LogCaptureFixture, how: str) -> None:
    """docs/recording.md: a recording stopped at its size limit counts what it no longer
    writes, and a failed write stops it the same way. Yet after a failed write nothing more
    was counted (nor the records of the write that failed, nor those left queued), a record
    dropped after a stop counted once however many lines it held, and no count reached the
    user either way. Now every record the server offers is written or counted in ``dropped``,
    and closing says how many were not written. The failed write is a real one: the file's
    descriptor is made /dev/full's, as a disk that fills."""
    path = tmp_path / "flight.rec"
    offered = [0]
    lock = threading.Lock()  # observers run on the engine's thread and each client's reader

    def count(_conn: int, direction: str, data: bytes) -> None:  # what the recorder is given
        with lock:
            offered[0] += len(split_lines(data)) if direction in (SENT, TRUTH) else 1

    with running_sim() as server:
        with caplog.at_level(logging.WARNING, logger="skeye.recording.records"), \
                Recorder(path, {"world": "pad"}, max_bytes=64 * 1024) as recorder:
            recorder.attach(server, server.runner, truth_rate_hz=0)  # all through the server
            server.observers.append(count)
            client = LineClient(server.port)
            client.expect("NFO")
            assert client.answer("INIT {ClassName hummingbird} {Location 0,0,-2}",
                                 "INIT").type == "RES"
            if how == "failed write":
                client.step(100)
                assert wait_for(lambda: recorder.written > 0)
                full = os.open("/dev/full", os.O_WRONLY)
                os.dup2(full, _fd_of(path))
                os.close(full)
            for _ in range(80):  # 64 KiB is about 1.2 s of sim time of one robot
                client.step(100)
                if recorder.stopped is not None:
                    break
            assert wait_for(lambda: recorder.stopped is not None, 30.0), "the recording ran on"
            client.step(300)  # after the stop: none of it is written
            client.close()
            assert wait_for(lambda: server.client_count == 0)
            server.observers.remove(count)
            assert recorder.dropped > 0
        stopped = [r.getMessage() for r in caplog.records if "stopped early" in r.getMessage()]
    assert recorder.written + recorder.dropped == offered[0]
    reason = "reached its size limit" if how == "size limit" else "No space left on device"
    assert len(stopped) == 1 and reason in stopped[0], stopped
    assert stopped[0].endswith(f": {recorder.dropped} records were not written"), stopped


def test_sync_returns_once_every_record_observed_before_it_is_on_disk(tmp_path: Path) -> None:
    """``Recorder.sync()``: the writer thread batches records and flushes at most once per
    ``flush_interval_s``; a caller that must see the file as it stands (a test stepping a
    flight until the recording rotates) waits on the writer, not on a guess."""
    path = tmp_path / "r.rec"
    with Recorder(path, flush_interval_s=1.0) as recorder:
        for k in range(2000):
            recorder.observe(1, SENT, b"SEN {Time %d.0}\r\n" % k)
        recorder.sync(timeout_s=60.0)
        text = path.read_bytes()
        assert text.count(b" SEN {Time ") == 2000 and b"SEN {Time 1999.0}" in text
        assert recorder.written == 2000
    recorder.sync(timeout_s=1.0)  # closed: nothing to wait for, no error


def test_replay_of_a_robot_plays_every_connection_that_flew_it(tmp_path: Path) -> None:
    """A robot spawned again under its name on a new connection (a pilot restarted, or one
    re-attaching after the simulator removed its robot) is the same robot to ``--robot``: the
    replay plays both lives in order, as the plot sums them. It played the first connection's
    alone, and the listing named the robot twice."""
    path = tmp_path / "fleet.rec"
    streams: list[bytes] = []
    with running_sim() as server, Recorder(path, {"world": "pad"}) as recorder:
        recorder.attach(server, server.runner)
        other = LineClient(server.port)
        other.expect("NFO")
        assert other.answer("INIT {ClassName hummingbird} {Name R2} {Location 3,0,-1}",
                            "INIT").type == "RES"
        for _ in range(2):
            client = LineClient(server.port)
            client.expect("NFO")
            assert client.answer("INIT {ClassName hummingbird} {Name R1} {Location 0,0,-1}",
                                 "INIT").type == "RES"
            client.step(200)
            client.sock.shutdown(socket.SHUT_WR)  # the robot's removal is queued by the end
            with pytest.raises(ConnectionError):
                client.read_until(lambda m: False)
            streams.append(bytes(client.raw))
            client.close()
        other.close()
        assert wait_for(lambda: server.client_count == 0)
    expected = [line for raw in streams for line in raw.split(b"\r\n")
                if line.startswith((b"SEN ", b"STA "))]
    with ReplayServer(path, port=0, speed=1000.0, robot="R1") as replay:
        assert replay.names == ["R2", "R1"]  # each name once
        client = LineClient(replay.port)
        played = iter(range(1, len(expected) + 1))
        client.read_until(lambda m: m.type in ("SEN", "STA") and next(played) == len(expected),
                          timeout_s=10)
        got = [line for line in client.raw.split(b"\r\n") if line.startswith((b"SEN ", b"STA "))]
        client.close()
    assert got == expected


def _short_flight(path: Path, meta: dict | None = None, seconds: float = 1.0) -> Path:
    """A recording written by hand: robot R1 spawned on connection 1, then a STA line every
    0.1 s of sim time for ``seconds``."""
    records = [Record(100.0, 0.0, 1, SENT, "RES {Command INIT} {Name R1} {Status OK}")]
    records += [Record(100.0 + k / 10, k / 10, 1, SENT, f"STA {{Name R1}} {{Time {k / 10:.1f}}}")
                for k in range(1, round(seconds * 10) + 1)]
    path.write_bytes(format_header({"world": "pad"} if meta is None else meta)
                     + b"".join(format_record(r) for r in records))
    return path


def test_a_full_replay_goes_on_accepting_after_a_refused_client_reset_its_connection(
        tmp_path: Path) -> None:
    """The answer to a client over ``max_clients`` was a blocking sendall that raised
    ConnectionResetError when that client had already reset its connection, and the accept
    thread died of it: the replay took no client again, its listener left open (connections
    hung without an NFO). The refusal is now one non-blocking send whose failure is ignored,
    as the simulator's."""
    path = _short_flight(tmp_path / "flight.rec")
    with ReplayServer(path, port=0, speed=1000.0, max_clients=1) as replay:
        first = LineClient(replay.port)
        first.expect("NFO")
        # The accept thread is held before it answers, so the refused clients' resets are in
        # before its answer is sent (it takes each connection, then waits for the lock).
        with replay._lock:
            for _ in range(3):
                gone = socket.create_connection(("127.0.0.1", replay.port), timeout=10)
                gone.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                gone.close()  # SO_LINGER 0: a reset, not a FIN
        # Taken in order: once this one is refused, so are those before it (one left over
        # would take the place the later client is given below).
        refused = LineClient(replay.port)
        err = refused.read_until(lambda m: m.type == "ERR", timeout_s=30)[1]
        assert err.get("Command") == "CONNECT" and err.get("Reason") == "too many clients"
        refused.close()
        first.close()
        assert wait_for(lambda: replay.client_count == 0, timeout_s=30)
        later = LineClient(replay.port)
        assert later.expect("NFO", timeout_s=10).get("Replay") == "true"
        later.close()


@pytest.mark.parametrize("gone", ["first part", "later part"])
def test_a_recording_gone_while_replayed_is_said_to_the_client_and_logged(
        tmp_path: Path, caplog: pytest.LogCaptureFixture, gone: str) -> None:
    """The replay reads the recording anew for each client: a file moved or deleted after the
    replay started (a rotated recording's later part among them) closed the client's
    connection without a word, and the replay logged nothing (the OSError was taken for the
    client's socket failing). The client now gets ``ERR {Command REPLAY}`` naming the file and
    why, and the replay logs it."""
    first = _short_flight(tmp_path / "flight.rec")
    if gone == "later part":
        later = tmp_path / "flight.rec.2"
        later.write_bytes(format_header({"world": "pad", "part": 2, "continues": first.name})
                          + format_record(Record(102.0, 2.0, 1, SENT, "STA {Name R1} {Time 2}")))
        with first.open("ab") as f:
            f.write(format_record(Record(101.5, 1.5, 0, NOTE, "recording continues in "
                                         "flight.rec.2 (size limit 1 MiB)")))
        missing = later
    else:
        missing = first
    with ReplayServer(first, port=0, speed=1000.0) as replay:
        assert len(replay.reader.parts) == (2 if gone == "later part" else 1)
        missing.unlink()
        with caplog.at_level(logging.ERROR, logger="skeye.recording.replay"):
            client = LineClient(replay.port)
            err = client.read_until(lambda m: m.type == "ERR", timeout_s=30)[1]
            assert err.get("Command") == "REPLAY", err
            assert str(missing) in (err.get("Reason") or "")
            assert "No such file or directory" in (err.get("Reason") or "")
            with pytest.raises(ConnectionError):
                client.read_until(lambda m: False, timeout_s=30)
            client.close()
            assert wait_for(lambda: replay.client_count == 0, timeout_s=30)
    assert any(str(missing) in r.getMessage() and r.levelno == logging.ERROR
               for r in caplog.records), caplog.records


@pytest.mark.parametrize("world", ["pad}{Mode lockstep", "pad{"])
def test_a_header_world_no_nfo_line_can_hold_is_refused_when_the_replay_starts(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], world: str) -> None:
    """A header's world goes into each client's NFO line, ``{Level <world>}``; one holding a
    brace cannot. The replay started and every client that connected was closed without a
    word (a LocalProtocolError traceback logged per client); it is now refused at the start,
    naming the file and the setting."""
    path = _short_flight(tmp_path / "odd.rec", {"world": world})
    with pytest.raises(RemoteProtocolError, match="world"):
        ReplayServer(path, port=0)
    assert main(["replay", str(path), "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "world" in err and "Traceback" not in err, err


def test_an_empty_robot_name_is_refused_not_taken_for_the_first_robot(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``skeye replay FILE --robot ""`` (a shell variable left empty) played the first robot as
    if no --robot were given; it is a name no robot has, refused listing those there are."""
    path = _short_flight(tmp_path / "flight.rec")
    with pytest.raises(ConfigError, match="no robot '' in the recording; it holds R1"):
        ReplayServer(path, port=0, robot="")
    assert main(["replay", str(path), "--port", "0", "--robot", ""]) == 2
    assert "no robot '' in the recording" in capsys.readouterr().err


def test_a_replay_says_the_lines_it_skips_and_a_last_line_cut_short(tmp_path: Path) -> None:
    """Lines of a recording that do not parse, and a last line a crash cut short, are skipped
    by every reader; ``skeye plot`` counted them in its summary, but ``skeye replay`` played
    on without a word, so a damaged file looked whole to its user. It says both at the start
    (stderr), and serves the rest."""
    path = _short_flight(tmp_path / "damaged.rec")
    lines = path.read_bytes().splitlines(keepends=True)
    path.write_bytes(b"".join(lines[:3]) + b"not a record\n" + b"".join(lines[3:])
                     + b"{not one either\n" + lines[-1][:20])
    with ReplayServer(path, port=0) as replay:
        assert (replay.skipped_lines, replay.cut_short) == (2, True)
    status, out, err = stopped_at_its_first_line(["replay", str(path), "--port", "0"])
    assert status == 0 and "control protocol on" in out, (out, err)
    assert err == (f"skeye replay: warning: {path}: 2 lines that did not parse, skipped\n"
                   f"skeye replay: warning: {path}: its last line is cut short (the recording "
                   "ended in a crash?), not played\n"), err


def _write_to_fifo_reader(path: Path, content: bytes, timeout_s: float = 60.0) -> None:
    """Write ``content`` to the FIFO at ``path`` once a reader has opened it (within
    ``timeout_s``: a plain open for writing waits for a reader without end)."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            writer = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
            break
        except OSError as exc:  # ENXIO: no reader yet
            if exc.errno != errno.ENXIO or time.monotonic() > deadline:
                raise
            time.sleep(0.01)
    try:
        os.set_blocking(writer, True)
        os.write(writer, content)  # a blocking write, read as it goes
    finally:
        os.close(writer)


@contextmanager
def _replayed_from_a_fifo(path: Path, content: bytes, *, speed: float, held_s: float = 0.0
                          ) -> Iterator[LineClient]:
    """A replay of R2 in ``content``, whose playback (which reads the file anew) finds a FIFO
    at ``path`` that gives the recording only once the client has its NFO and ``held_s`` more
    have passed (the test's own delay, not a guess at speed); yields the client."""
    path.write_bytes(content)
    with ReplayServer(path, port=0, speed=speed, robot="R2") as replay:
        path.unlink()
        os.mkfifo(path)
        client = LineClient(replay.port, timeout_s=60)
        try:
            try:
                client.expect("NFO")
                time.sleep(held_s)
            finally:  # the playback waits to open the FIFO (either code): give it the file
                _write_to_fifo_reader(path, content)
            yield client
        finally:
            client.close()


def test_a_client_is_greeted_before_its_playback_reads_the_recording(tmp_path: Path) -> None:
    """Each client's playback read the recording up to its robot's first line before it sent
    the NFO, answering nothing meanwhile: a robot spawned late in a long recording kept every
    client from its NFO for as long as a whole read of the file (half a minute for 1 GB, past
    a pilot's 10 s wait for the greeting). The NFO is now sent on connecting and the file read
    in slices. Here the playback's read cannot even begin (the recording, which each playback
    reads anew, has become a FIFO no one writes to yet): the greeting must come all the same,
    and the robot's stream once the FIFO gives the recording."""
    path = tmp_path / "late.rec"
    truth = (b"1.0 0.5 0 = TRUTH {Name R1} {Time 0.5} {Location 0,0,-1} {Orientation 0,0,0} "
             b"{Velocity 0,0,0} {Battery 100} {Voltage 12} {Armed false} {Landed true}\n")
    content = (format_header({"world": "pad"})
               + format_record(Record(1.0, 0.0, 1, SENT, "RES {Command INIT} {Name R1}"))
               + format_record(Record(1.0, 0.0, 1, SENT, "STA {Name R1} {Time 0}"))
               + truth * 1000
               + format_record(Record(2.0, 9.0, 2, SENT, "RES {Command INIT} {Name R2}"))
               + format_record(Record(2.0, 9.0, 2, SENT, "STA {Name R2} {Time 9}")))
    with _replayed_from_a_fifo(path, content, speed=1000.0) as client:
        _, sta = client.read_until(lambda m: m.type == "STA")
        assert sta.get("Name") == "R2", sta
        client.send("PING {Id after}")
        assert client.read_until(lambda m: m.type == "RES")[1].get("Id") == "after"


def test_a_late_robots_playback_is_paced_from_its_first_line_once_read(tmp_path: Path) -> None:
    """The playback's clock started on connecting, so the sim time a long read of the file
    took was all due when its robot's first line came: those lines went out in one burst. It
    starts with the first line now. The read is held here for ``held_s`` (the recording a
    FIFO given only then); a PING sent when the first STA (sim 9.0) arrives is answered with
    the playback's time, about 9.0 plus the PING's round trip, where the old clock said 9.0
    plus the ``held_s`` of the read."""
    held_s = 6.0
    path = tmp_path / "late.rec"
    content = (format_header({"world": "pad"})
               + format_record(Record(1.0, 0.0, 1, SENT, "RES {Command INIT} {Name R1}"))
               + format_record(Record(1.0, 0.0, 1, SENT, "STA {Name R1} {Time 0}"))
               + format_record(Record(2.0, 9.0, 2, SENT, "RES {Command INIT} {Name R2}"))
               + b"".join(format_record(Record(2.0, 9.0 + k / 10, 2, SENT,
                                               f"STA {{Name R2}} {{Time {9 + k / 10:.1f}}}"))
                          for k in range(100)))
    with _replayed_from_a_fifo(path, content, speed=1.0, held_s=held_s) as client:
        client.read_until(lambda m: m.type == "STA")
        client.send("PING {Id paced}")
        answer = client.read_until(lambda m: m.type == "RES")[1]
    assert answer.get("Id") == "paced"
    # the round trip of one PING on loopback: far below half of held_s, loaded or not
    assert float(answer.get("Time")) < 9.0 + held_s / 2, answer
