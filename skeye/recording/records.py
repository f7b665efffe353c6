"""Flight recording: every line the control server sends or receives, plus sampled ground truth.

How this works: the file format (docs/recording.md) is line-oriented text. The first line is a
header, ``#skeye-recording 1 {json}``; every other line is one record::

    <wall_s> <sim_s> <conn> <dir> <protocol line>

``dir`` is ``>`` (sent to client ``conn``), ``<`` (received from it), ``+``/``-`` (connection
opened/closed; the line is the peer address), ``=`` (a ``TRUTH`` sample of one robot, ``conn``
0) or ``!`` (a note from the recorder, e.g. records it had to drop). A record never holds a line
break, so a crash that cuts the last line off loses that line only: the reader skips an
unterminated last line and counts it. :func:`format_record` and :func:`parse_record` are the
pure codec; they round-trip.

:class:`Recorder` is the I/O side. Its :meth:`Recorder.observe` is a
:data:`~skeye.sim.server.LineObserver`: it only timestamps the data and puts it in a bounded
queue (never blocks the engine or a client thread; when the queue is full the record is counted
and dropped, and a ``!`` note says how many). One writer thread formats records, writes them and
flushes and fsyncs the file at least every ``flush_interval_s`` (0.5 s) and on close, so a
killed simulator loses at most the last second. The recorder writes the file it was given and
refuses to overwrite an existing one; it holds each file's ``flock`` while writing it, so
another recorder given that file says it is being written.

Size: a recording never grows past ``max_bytes`` (``skeye sim --record-max-mb``, default
:data:`DEFAULT_MAX_BYTES`), nor is it written while the disk holds less than
``min_free_bytes`` (:data:`DEFAULT_MIN_FREE_BYTES`). At either limit it stops: a ``!`` note
says why, the log says so once, and later records are counted in ``dropped`` (the simulator
runs on); a write that fails stops it the same way, and :meth:`Recorder.close` says how many
records a stopped recording did not write. With ``rotate`` it goes on in a new part instead,
``FILE.2``, ``FILE.3``, ... (each a whole recording with its own header, whose settings name
the part and the one before), up to ``max_parts`` parts; a part that exists already is never
overwritten (recording stops there). A full part ends with the note ``recording continues in
NAME``: :class:`RecordingReader` with ``follow_parts`` reads a first part and the parts that
continue it as one flight.
"""

from __future__ import annotations

import fcntl
import json
import logging
import math
import os
import queue
import shutil
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from skeye.errors import ConfigError, LocalProtocolError, RemoteProtocolError, SkeyeError
from skeye.values import is_finite_number
from skeye.wire.sim_lines import format_message
from skeye.workers import Worker

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
HEADER_PREFIX = "#skeye-recording"
SENT, RECEIVED, CONNECTED, DISCONNECTED, TRUTH, NOTE = ">", "<", "+", "-", "=", "!"
DIRECTIONS = frozenset((SENT, RECEIVED, CONNECTED, DISCONNECTED, TRUTH, NOTE))
DEFAULT_FLUSH_INTERVAL_S = 0.5
DEFAULT_TRUTH_RATE_HZ = 20.0
DEFAULT_QUEUE_RECORDS = 200_000
DEFAULT_MAX_BYTES = 1024 * 1024 * 1024
"""1 GiB: about five hours of one hovering vehicle with a camera (the probe measured 80 MB in
23 min, 3.5 MB/min)."""
DEFAULT_MIN_FREE_BYTES = 256 * 1024 * 1024
"""Recording stops when the disk has less than this left (256 MiB): the rest is the system's."""
DEFAULT_MAX_PARTS = 10
MAX_HEADER_BYTES = 64 * 1024
"""The longest header line, terminator excluded: readers read no more of a first line (a
file whose first line is longer is no recording), and the recorder writes none longer."""
MAX_RECORD_BYTES = 1024 * 1024
"""The longest record line readers take, terminator excluded (1 MiB: sixteen times the longest
line the control protocol's decoders take, 64 KiB). A longer line is no record: counted with the
bad lines and skipped without being held, so a damaged file's memory does not grow with it."""
_DISK_CHECK_S = 1.0  # how often the free space is looked at


@dataclass(frozen=True)
class Record:
    """One recorded event: times in seconds, ``line`` without its terminator."""

    wall_s: float
    sim_s: float
    conn: int
    direction: str
    line: str

    def __post_init__(self) -> None:
        if self.direction not in DIRECTIONS:
            raise LocalProtocolError(f"unknown record direction {self.direction!r}")
        if not (math.isfinite(self.wall_s) and math.isfinite(self.sim_s)):
            raise LocalProtocolError("record times must be finite")
        if self.conn < 0:
            raise LocalProtocolError(f"connection id must be >= 0, got {self.conn}")
        if "\n" in self.line or "\r" in self.line:
            raise LocalProtocolError("a recorded line may not hold a line break")


def format_record(record: Record) -> bytes:
    """The file line of one record, newline included."""
    return (
        f"{record.wall_s:.6f} {record.sim_s:.6f} {record.conn} {record.direction} {record.line}\n"
    ).encode()


def parse_record(text: str) -> Record:
    """One file line (terminator optional) back to a :class:`Record`.

    Raises:
        RemoteProtocolError: the line is not a record (names what is wrong).
    """
    parts = text.rstrip("\r\n").split(" ", 4)
    if len(parts) < 4:
        raise RemoteProtocolError(f"record has {len(parts)} fields, needs at least 4")
    wall, sim, conn, direction = parts[:4]
    try:
        line = parts[4] if len(parts) > 4 else ""
        record = Record(float(wall), float(sim), int(conn), direction, line)
    except ValueError as exc:
        raise RemoteProtocolError(f"bad record field: {exc}") from None
    except LocalProtocolError as exc:
        raise RemoteProtocolError(str(exc)) from None
    return record


def format_header(meta: dict[str, Any]) -> bytes:
    """The first line of a recording: format name, version and a JSON object of run settings.

    Raises:
        LocalProtocolError: the line would be longer than :data:`MAX_HEADER_BYTES`.
    """
    line = f"{HEADER_PREFIX} {FORMAT_VERSION} {json.dumps(meta, sort_keys=True)}\n".encode()
    if len(line) - 1 > MAX_HEADER_BYTES:
        raise LocalProtocolError(f"recording header of {len(line) - 1} bytes (the run's "
                                 f"settings, {', '.join(sorted(meta))}): the most is "
                                 f"{MAX_HEADER_BYTES // 1024} KiB")
    return line


def parse_header(text: str) -> dict[str, Any]:
    """The settings object of a header line; raises RemoteProtocolError if it is not one."""
    parts = text.rstrip("\r\n").split(" ", 2)
    if len(parts) != 3 or parts[0] != HEADER_PREFIX:
        raise RemoteProtocolError(f"not a skeye recording (header {text[:60]!r})")
    if parts[1] != str(FORMAT_VERSION):
        raise RemoteProtocolError(
            f"recording format version {parts[1]!r}; this program reads {FORMAT_VERSION}"
        )
    try:
        meta = json.loads(parts[2])
    except json.JSONDecodeError as exc:
        raise RemoteProtocolError(f"recording header is not JSON: {exc}") from None
    except (ValueError, RecursionError) as exc:  # a number of over 4300 digits, deep nesting
        raise RemoteProtocolError(f"recording header holds JSON this program cannot read: "
                                  f"{exc}") from None
    if not isinstance(meta, dict):
        raise RemoteProtocolError("recording header must hold a JSON object")
    for key, kind, check in _HEADER_FIELDS:
        if key in meta and not check(meta[key]):
            raise RemoteProtocolError(
                f"recording header: {key} must be {kind}, got {meta[key]!r}")
    return meta


_HEADER_FIELDS: tuple[tuple[str, str, Callable[[Any], bool]], ...] = (
    ("timestep_s", "a number of seconds > 0", lambda v: is_finite_number(v) and v > 0),
    ("world", "a string", lambda v: isinstance(v, str)),
    ("mode", "a string", lambda v: isinstance(v, str)),
    ("wind", "a string", lambda v: isinstance(v, str)),
    ("seed", "a whole number", lambda v: isinstance(v, int) and not isinstance(v, bool)),
    ("started_unix_s", "a number", is_finite_number),
)
"""The settings a header may hold that readers use, and what each must be (the rest are kept
as they are): a header that breaks one is refused when the file is opened, not when a reader
first uses it."""


def split_lines(data: bytes) -> list[bytes]:
    """The protocol lines in a chunk the server queued (terminators and stray breaks removed)."""
    return [line.rstrip(b"\r").replace(b"\r", b" ") for line in data.split(b"\n") if line.strip()]


def recording_file(path: Path) -> Path:
    """``path`` if it is a file a recording can be read from: ConfigError, naming it, for a
    folder, a pipe or a device (readers seek and read a file more than once), or none."""
    if path.is_dir():
        raise ConfigError(f"{path} is a directory, not a recording file")
    if path.exists() and not path.is_file():
        raise ConfigError(f"{path} is not a regular file (a pipe, a device or a socket): give "
                          "the recording file itself")
    if not path.is_file():
        raise ConfigError(f"recording not found: {path}")
    return path


def read_header(path: Path) -> dict[str, Any]:
    """The settings of ``path``'s header line (ConfigError or RemoteProtocolError, naming the
    file, when it is no recording); reads no more than :data:`MAX_HEADER_BYTES` of it."""
    with recording_file(path).open("rb") as f:
        first = f.readline(MAX_HEADER_BYTES + 1)
    if not first.endswith(b"\n"):
        if len(first) > MAX_HEADER_BYTES:  # not read on: it could run to the file's end
            raise RemoteProtocolError(
                f"{path}: not a skeye recording (a first line longer than "
                f"{MAX_HEADER_BYTES // 1024} KiB, the longest header)")
        raise RemoteProtocolError(f"{path}: no complete header line")
    try:
        return parse_header(first.decode("utf-8", "replace"))
    except RemoteProtocolError as exc:  # said of the file, as every other refusal is
        raise RemoteProtocolError(f"{path}: {exc}") from None


CONTINUES_NOTE = "recording continues in "
"""How the note that ends a full part of a rotated recording begins; the next part's name
follows, then `` (size limit ...)``."""
_TAIL_BYTES = 4096  # a part's continue note is its last line, far shorter than this
_PART_KEYS = frozenset(("part", "continues", "started_unix_s"))  # differ between parts


def continued_in(path: Path) -> str | None:
    """The name of the part that ``path`` ends saying the recording continues in, if its last
    line is that note (a part cut short by a crash, or the last part, ends otherwise). Reads
    only the file's tail."""
    with path.open("rb") as f:
        size = f.seek(0, os.SEEK_END)
        f.seek(max(0, size - _TAIL_BYTES))
        tail = f.read()
    if not tail.endswith(b"\n"):
        return None
    last = tail[:-1].rsplit(b"\n", 1)[-1].decode("utf-8", "replace")
    try:
        record = parse_record(last)
    except RemoteProtocolError:
        return None
    if record.direction != NOTE or not record.line.startswith(CONTINUES_NOTE):
        return None
    return record.line[len(CONTINUES_NOTE):].rsplit(" (size limit", 1)[0]


def flight_parts(path: Path, header: dict[str, Any]) -> tuple[list[Path], str | None]:
    """The parts of the flight whose first part is ``path`` (``header`` its settings), in
    order, and why the chain ends early (None when it does not).

    A full part ends with the note ``recording continues in NAME``; NAME, in the same folder,
    must be a recording whose header says it is the next part (``part``), continues the one
    before it (``continues``, by name) and holds the same settings. A part that is missing, or
    is another recording's, ends the chain there: the parts before it are the flight."""
    parts = [path]
    while (name := continued_in(parts[-1])) is not None:
        if Path(name).name != name or name in ("", ".", ".."):
            return parts, f"{parts[-1]} ends saying the recording continues in {name!r}, " \
                "which is no file name in its folder"
        nxt = path.with_name(name)
        said = f"{parts[-1]} ends saying the recording continues in {nxt}"
        if not nxt.is_file():
            return parts, f"{said}, which is missing"
        try:
            meta = read_header(nxt)
        except (ConfigError, RemoteProtocolError) as exc:
            return parts, f"{said}, which is no recording ({exc})"
        want = len(parts) + 1
        if meta.get("part") != want or meta.get("continues") != parts[-1].name:
            return parts, (f"{said}, but that file is not part {want} continuing "
                           f"{parts[-1].name}: its header says part {meta.get('part')!r}, "
                           f"continuing {meta.get('continues')!r}")
        differ = sorted(k for k in (set(meta) | set(header)) - _PART_KEYS
                        if meta.get(k) != header.get(k))
        if differ:
            return parts, (f"{said}, but that file is another recording's part: its "
                           f"{', '.join(differ)} differ from {path}'s")
        parts.append(nxt)
    return parts, None


class RecordingReader:
    """Reads a recording file; tolerates an unterminated last line (a crash) and bad lines
    (one longer than :data:`MAX_RECORD_BYTES` among them, not held in memory).

    With ``follow_parts``, a first part of a rotated recording (``skeye sim --record-rotate``)
    is read with the parts that continue it, as one flight (see :func:`flight_parts`); a later
    part named on its own is read alone. The parts are read one after the other, lazily.

    Attributes:
        header: the run settings from the header line (of the first part).
        parts: the files read, in order (one unless parts are followed).
        broken: why the parts end before the recording did (a part missing or another
            recording's, named), or None.
        bad_lines: records that did not parse (counted, skipped).
        truncated: the file ended inside a line (that line was skipped).
    """

    def __init__(self, path: str | Path, *, follow_parts: bool = False) -> None:
        self.path = Path(path)
        self.header = read_header(self.path)
        self.parts = [self.path]
        self.broken: str | None = None
        if follow_parts and "part" not in self.header:
            self.parts, self.broken = flight_parts(self.path, self.header)
        self.bad_lines = 0
        self.truncated = False

    def records(self) -> Iterator[Record]:
        """Every record in file order, part after part (reads lazily; safe to call again)."""
        self.bad_lines = 0
        self.truncated = False
        for part in self.parts:
            with part.open("rb") as f:
                f.readline(MAX_HEADER_BYTES + 1)
                while raw := f.readline(MAX_RECORD_BYTES + 1):
                    if len(raw) > MAX_RECORD_BYTES and not raw.endswith(b"\n"):
                        if _skip_line(f):  # too long for a record: not held, read past
                            self.bad_lines += 1
                            continue
                        raw = b""  # and it runs to the end of the file: cut off
                    if not raw.endswith(b"\n"):
                        self.truncated = True
                        break
                    try:
                        yield parse_record(raw.decode("utf-8", "replace"))
                    except RemoteProtocolError:
                        self.bad_lines += 1


def _skip_line(f: IO[bytes]) -> bool:
    """Read ``f`` past the end of the line it is in, a piece at a time; False when the file
    ends first (the line has no end)."""
    while piece := f.readline(MAX_RECORD_BYTES):
        if piece.endswith(b"\n"):
            return True
    return False


def robot_connections(records: Iterator[Record]) -> dict[int, str]:
    """Connection id -> robot name, from the ``RES {Command INIT} {Name ...}`` each was sent,
    or, for a connection whose INIT answer the file does not hold (a later part of a rotated
    recording), from the ``{Name ...}`` of the ``STA`` lines its robot's stream sent it."""
    found: dict[int, str] = {}
    for rec in records:
        if rec.direction != SENT:
            continue
        initialised = rec.line.startswith("RES {Command INIT}")
        if initialised or (rec.line.startswith("STA ") and rec.conn not in found):
            name = _block_value(rec.line, "Name")
            if name:
                found[rec.conn] = name
    return found


def _block_value(line: str, key: str) -> str | None:
    """The value of the first ``{key value}`` block of a protocol line, if it has one."""
    for block in line.split("{")[1:]:
        found, _, value = block.rstrip("} ").partition(" ")
        if found == key:
            return value
    return None


_Entry = tuple[float, float, int, str, bytes] | threading.Event | None
"""What the writer's queue holds (see ``Recorder._queue``)."""


class Recorder:
    """Writes a recording; a context manager. Attach it to a server with :meth:`attach`.

    Args:
        path: the file to create (an existing file is never overwritten).
        meta: run settings stored in the header (world, mode, step, seed...).
        flush_interval_s: longest time a record waits in memory before it is on disk.
        queue_records: records buffered between the observers and the writer thread.
        sim_time: where sim time comes from (set by :meth:`attach`).
        wall_clock: Unix time source.
    """

    def __init__(
        self,
        path: str | Path,
        meta: dict[str, Any] | None = None,
        *,
        flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S,
        queue_records: int = DEFAULT_QUEUE_RECORDS,
        wall_clock: Callable[[], float] = time.time,
        max_bytes: int = DEFAULT_MAX_BYTES,
        rotate: bool = False,
        max_parts: int = DEFAULT_MAX_PARTS,
        min_free_bytes: int = DEFAULT_MIN_FREE_BYTES,
    ) -> None:
        if not (0.0 < flush_interval_s <= 1.0):
            raise LocalProtocolError(f"flush interval must be in (0, 1] s, got {flush_interval_s}")
        if max_bytes < 64 * 1024 or max_parts < 1 or min_free_bytes < 0:
            raise ConfigError(f"recording size limit must be >= 64 KiB and parts >= 1, got "
                              f"{max_bytes} B, {max_parts} parts")
        self.path = Path(path)
        self.max_bytes = max_bytes
        self.rotate = rotate
        self.max_parts = max_parts
        self.min_free_bytes = min_free_bytes
        self.parts = [self.path]  # every file written, in order
        self.stopped: str | None = None  # why recording stopped early (size, disk), if it did
        self._meta = dict(meta or {})
        header = format_header({"started_unix_s": wall_clock(), **self._meta})  # before the file
        if rotate:  # a later part's header also names its part and the one it continues,
            # and its start time may print longer (the longest repr of a float: 24 characters)
            format_header({"started_unix_s": -2.2250738585072014e-308, **self._meta,
                           "part": max_parts, "continues": f"{self.path.name}.{max_parts}"})
        self._file: IO[bytes] = self._create(self.path)
        self._clock = wall_clock
        self._sim_time: Callable[[], float] = lambda: 0.0
        self._flush_interval_s = flush_interval_s
        # records, a sync()'s event (set once what was queued before it is on disk), or None
        # (close: the end)
        self._queue: queue.Queue[_Entry] = queue.Queue(queue_records)
        self.dropped = 0  # observed records not written (add with _drop: several threads do)
        self._drop_lock = threading.Lock()
        self._batch_dropped = 0  # of the writer's batch, what _room could not write
        self.written = 0  # records written, the recorder's own "!" notes among them
        self._closed = False
        self._lock = threading.Lock()
        self._detach: list[Callable[[], None]] = []
        self._bytes = self._file.write(header)
        self._file.flush()
        self._disk_checked_s = -math.inf
        self.failure: BaseException | None = None
        """Why the writer thread stopped early (a bug; a failed write is logged and noted)."""
        self._thread = Worker(self._write_loop, "skeye-recorder", on_error=self._writer_failed)
        self._thread.start()

    @staticmethod
    def _create(path: Path) -> IO[bytes]:
        """``path`` made and opened for writing, locked (``flock``) while it is written, so that
        another recorder given it knows it is being written (the kernel's lock ends with the
        process however it ends)."""
        try:
            f = path.open("xb")
        except FileExistsError:
            if path.is_dir():  # not to be deleted: `--record ""` is the folder "."
                raise ConfigError(f"recording {path} is a directory: give a file name for the "
                                  "recording") from None
            if path.is_file() and _being_written(path):  # not to be deleted either (a FIFO
                # is not opened: that would wait for its writer)
                raise ConfigError(f"recording {path} is being written by another process (a "
                                  "simulator recording now); choose another name") from None
            raise ConfigError(
                f"recording {path} already exists; choose another name or delete it"
            ) from None
        except OSError as exc:
            raise ConfigError(f"cannot create recording {path}: {exc.strerror}") from None
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # a file system without locks (some network ones): recorded unlocked
            pass
        return f

    def _room(self, data: list[bytes]) -> list[bytes]:
        """The records of ``data`` that may still be written to the current part (writer
        thread); at a limit the part is ended: the next one is opened (``rotate``) or
        recording stops. What cannot be written is counted in ``dropped``."""
        now = time.monotonic()
        if now - self._disk_checked_s >= _DISK_CHECK_S:
            self._disk_checked_s = now
            try:
                free = shutil.disk_usage(self.path.parent or ".").free
            except OSError:
                free = None
            if free is not None and free < self.min_free_bytes:
                self._stop(f"the disk holds {free / 2**20:.0f} MiB, less than the "
                           f"{self.min_free_bytes / 2**20:.0f} MiB recording leaves free")
        fits: list[bytes] = []
        for i, record in enumerate(data):
            if self.stopped is not None:
                self._drop(len(data) - i, batch=True)
                return fits
            if self._bytes + len(record) > self.max_bytes - 256:  # room for the last note
                self._write_all(fits)
                fits = []
                self._part_full()
                if self.stopped is not None:
                    self._drop(len(data) - i, batch=True)
                    return fits
            fits.append(record)
            self._bytes += len(record)
        return fits

    def _write_all(self, records: list[bytes]) -> None:
        if records:
            self._file.write(b"".join(records))
            self.written += len(records)

    def _note(self, text: str) -> None:
        record = format_record(Record(self._clock(), self._sim_time(), 0, NOTE, text))
        self._file.write(record)
        self._bytes += len(record)

    def _part_full(self) -> None:
        limit = f"{self.max_bytes / 2**20:g} MiB"
        if not self.rotate:
            self._stop(f"{self.path} reached its size limit of {limit} (--record-max-mb)")
            return
        if len(self.parts) >= self.max_parts:
            self._stop(f"{len(self.parts)} parts of {limit} written, the most "
                       "--record-parts allows")
            return
        nxt = self.path.with_name(f"{self.path.name}.{len(self.parts) + 1}")
        try:
            new = self._create(nxt)
        except ConfigError as exc:
            self._stop(str(exc))
            return
        try:
            self._note(f"{CONTINUES_NOTE}{nxt.name} (size limit {limit})")
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
        except OSError:  # the old part cannot be finished: no new one begun (the writer says)
            new.close()
            nxt.unlink(missing_ok=True)
            raise
        self._file = new
        self.parts.append(nxt)
        log.warning("recording: %s is full (%s); continuing in %s", self.parts[-2], limit, nxt)
        meta = {**self._meta, "part": len(self.parts), "continues": self.parts[-2].name}
        self._bytes = self._file.write(format_header({"started_unix_s": self._clock(), **meta}))

    def _stop(self, why: str) -> None:
        if self.stopped is not None:
            return
        self.stopped = why
        log.error("recording stops: %s; the simulator goes on", why)
        self._note(f"recording stopped: {why}")

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- inputs --------------------------------------------------------------------------
    def observe(self, conn_id: int, direction: str, data: bytes) -> None:
        """A :data:`~skeye.sim.server.LineObserver`: timestamp and queue; never blocks."""
        if self._closed:
            return
        if self.stopped is not None:
            self._drop(_records_in(direction, data))
            return
        try:
            self._queue.put_nowait((self._clock(), self._sim_time(), conn_id, direction, data))
        except queue.Full:
            self._drop(_records_in(direction, data))

    def _drop(self, records: int, *, batch: bool = False) -> None:
        """Count ``records`` not written: observers on several threads (the engine's, each
        client's reader) and the writer count at once, so under a lock. ``batch``: the
        writer's own batch, which :meth:`_write_loop` needs to know apart."""
        with self._drop_lock:
            self.dropped += records
        if batch:
            self._batch_dropped += records

    def attach(
        self, server: Any, runner: Any, truth_rate_hz: float = DEFAULT_TRUTH_RATE_HZ
    ) -> None:
        """Record ``server``'s traffic and sample every robot of ``runner``'s simulation.

        Args:
            server: a :class:`~skeye.sim.server.ControlServer`.
            runner: its :class:`~skeye.sim.runner.SimulationRunner`.
            truth_rate_hz: how often each robot's ground truth is sampled (0 = never).
        """
        sim = runner.sim
        self._sim_time = lambda: sim.time_s
        server.observers.append(self.observe)
        self._detach.append(lambda: server.observers.remove(self.observe))
        if truth_rate_hz > 0:
            period = max(1, round(1.0 / (truth_rate_hz * sim.dt)))
            sampler = _TruthSampler(self, period)
            runner.call(sampler.install)
            self._detach.append(lambda: runner.call(sampler.uninstall))

    # -- output --------------------------------------------------------------------------
    def _write_loop(self) -> None:
        f = self._file
        last_flush = time.monotonic()
        reported_drops = 0
        done = False
        while not done:
            wait = max(0.0, self._flush_interval_s - (time.monotonic() - last_flush))
            batch: list[_Entry] = []
            synced: list[threading.Event] = []
            try:
                batch.append(self._queue.get(timeout=wait))
                while len(batch) < 4096:
                    batch.append(self._queue.get_nowait())
            except queue.Empty:
                pass
            out: list[bytes] = []
            for entry in batch:
                if entry is None:
                    done = True
                    break
                if isinstance(entry, threading.Event):
                    synced.append(entry)
                    continue
                self._format(entry, out)
            records = len(out)  # observed records; the note below is the recorder's own
            if self.dropped != reported_drops and self.stopped is None:
                note = f"dropped {self.dropped - reported_drops} records (queue full)"
                reported_drops = self.dropped
                out.append(format_record(Record(self._clock(), self._sim_time(), 0, NOTE, note)))
            written, self._batch_dropped = self.written, 0
            try:
                if out:
                    self._write_all(self._room(out))
                f = self._file
                if done or synced or time.monotonic() - last_flush >= self._flush_interval_s:
                    f.flush()
                    os.fsync(f.fileno())
                    last_flush = time.monotonic()
            except OSError as exc:
                for event in synced:  # recording stopped: nothing more will be written
                    event.set()
                # The batch's observed records neither written nor counted are not written
                # (the recorder's own note, last in the batch, is written after them all).
                self._drop(max(0, records - min(records, self.written - written)
                               - self._batch_dropped))
                self._write_failed(exc)
                return
            for event in synced:
                event.set()

    def _write_failed(self, exc: OSError) -> None:
        """A write or flush failed (a full disk, EFBIG past ``ulimit -f``, a failing device):
        recording stops, said once; the simulator goes on. The file is closed without
        retrying what the failed write left in its buffer, which would fail again (and did,
        in ``close()``, ending ``skeye sim`` with an error after the recording had stopped)."""
        if self.stopped is None:  # a size-limit stop whose last note failed keeps its reason
            self.stopped = f"writing {self.path} failed: {exc.strerror or exc}"
        log.error("recording %s: write failed, recording stops: %s; the simulator goes on",
                  self.path, exc.strerror or exc)
        # From here on observe() counts what it is given in dropped, as at the size limit, and
        # close() counts what is left in the queue.
        try:
            self._file.close()  # flushes the buffer, fails again, and closes the file anyway
        except OSError:
            pass

    def _writer_failed(self, exc: BaseException) -> None:
        """The writer thread raised (Worker logged it): record nothing more, keep the reason."""
        self.failure = exc
        self._closed = True

    def _format(self, entry: tuple[float, float, int, str, bytes], out: list[bytes]) -> None:
        wall, sim_s, conn, direction, data = entry
        prefix = b"%.6f %.6f %d %s " % (wall, sim_s, conn, direction.encode())
        if direction in (SENT, TRUTH):
            out.extend(prefix + line + b"\n" for line in split_lines(data))
        else:
            out.append(prefix + data.replace(b"\r", b" ").replace(b"\n", b" ") + b"\n")

    def sync(self, timeout_s: float = 5.0) -> None:
        """Wait until every record observed before this call is written and flushed to disk,
        or has been counted in ``dropped`` (a recording that stopped early, or closed).

        Raises:
            TimeoutError: the writer did not get there within ``timeout_s``.
        """
        if self._closed or not self._thread.is_alive():
            return
        done = threading.Event()
        try:
            self._queue.put(done, timeout=timeout_s)
        except queue.Full:
            raise TimeoutError(f"recording {self.path}: the writer's queue stayed full for "
                               f"{timeout_s:g} s") from None
        deadline = time.monotonic() + timeout_s
        while not done.wait(0.1):
            if not self._thread.is_alive():  # stopped by a failed write after the put
                return
            if time.monotonic() > deadline:
                raise TimeoutError(f"recording {self.path}: what was queued was not written "
                                   f"within {timeout_s:g} s")

    def close(self, timeout_s: float = 5.0) -> None:
        """Detach, write everything queued, flush and close the file; idempotent. A recording
        that stopped early (a size or disk limit, a failed write) says, once, how many records
        it did not write: the ``dropped`` count."""
        with self._lock:
            if self._closed and not self._thread.is_alive():
                if not self._file.closed:
                    self._file.close()
                return
            self._closed = True
        for detach in reversed(self._detach):
            try:
                detach()
            except (SkeyeError, ValueError, TimeoutError):
                pass
        self._detach.clear()
        if self._thread.is_alive():  # a writer stopped by a failed write reads no more
            try:
                self._queue.put(None, timeout=timeout_s)
            except queue.Full:
                log.error("recording %s: writer did not drain its queue", self.path)
            if not self._thread.join(timeout_s):
                log.error("recording %s: writer did not finish within %g s", self.path,
                          timeout_s)
        if not self._thread.is_alive():  # what a stopped writer left queued: not written
            while True:
                try:
                    entry = self._queue.get_nowait()
                except queue.Empty:
                    break
                if isinstance(entry, threading.Event):
                    entry.set()
                elif entry is not None:
                    self._drop(_records_in(entry[3], entry[4]))
        if not self._file.closed:
            self._file.close()
        if self.stopped is not None:
            log.warning("recording %s stopped early (%s): %d records were not written",
                        self.path, self.stopped, self.dropped)


def _being_written(path: Path) -> bool:
    """Whether a recorder holds ``path``'s lock (see ``Recorder._create``)."""
    try:
        with path.open("rb") as f:
            fcntl.flock(f, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:  # cannot be opened or locked: nothing says a recorder holds it
        return False
    return False


def _records_in(direction: str, data: bytes) -> int:
    """How many records ``data``, observed with ``direction``, is written as (see
    :meth:`Recorder._format`): a line each for what was sent and for truth, else one."""
    return len(split_lines(data)) if direction in (SENT, TRUTH) else 1


class _TruthSampler:
    """A step hook that records ``TRUTH`` lines of every robot every ``period`` steps."""

    def __init__(self, recorder: Recorder, period_steps: int) -> None:
        self.recorder = recorder
        self.period = period_steps

    def install(self, sim: Any) -> None:
        sim.step_hooks.append(self.on_step)
        sim.event_sources.append(self.next_event)

    def uninstall(self, sim: Any) -> None:
        if self.on_step in sim.step_hooks:
            sim.step_hooks.remove(self.on_step)
        if self.next_event in sim.event_sources:
            sim.event_sources.remove(self.next_event)

    def next_event(self, sim: Any) -> int:
        # The step with index k leaves sim.steps == k + 1: sample when that is a multiple.
        return -(-(sim.steps + 1) // self.period) * self.period - 1

    def on_step(self, sim: Any) -> None:
        if sim.steps % self.period or not sim.robots:
            return
        lines = []
        for name, robot in sim.robots.items():
            s = sim.body_state(name)
            lines.append(
                format_message(
                    "TRUTH",
                    ("Name", name),
                    ("Time", sim.time_s),
                    ("Location", s.pos_ned_m),
                    ("Orientation", s.rpy_rad),
                    ("Velocity", s.vel_ned_m_s),
                    ("Battery", float(robot.battery.remaining_s)),
                    ("Voltage", float(robot.battery.voltage_v)),
                    ("Armed", bool(robot.flight.armed)),
                    ("Landed", bool(robot.flight.landed)),
                )
            )
        self.recorder.observe(0, TRUTH, b"".join(lines))
