"""``skeye plot``: draw a flight recording and summarise it.

How this works: :func:`load_tracks` reads a recording once and builds, per robot, the time series
of its ground truth: the recorder's ``TRUTH`` samples when there are any, otherwise the
``SEN {Type GroundTruth}`` and ``STA`` lines its connection was sent. The first part of a
rotated recording is read with the parts that continue it, as one flight (a later part named
alone is read alone). :func:`summarize` turns
the tracks into figures; :func:`plot_recording` draws three panels with matplotlib's Agg backend
(no display needed): the trajectory seen from above (north up, east right), altitude above the
world origin over sim time, and battery time left over sim time while flying (on the ground the
estimate, charge over the idle current, reaches hours: those samples are left out).

A line whose numbers are not numbers, or whose ``Location`` lies beyond the simulator's limit
(:data:`skeye.geo.MAX_POSITION_M`, 100 km from the origin: the simulator stops a robot there,
so no recording of it holds one), is counted with the bad lines and skipped; the summary says
how many were too far. Every figure and axis is then finite.
"""

from __future__ import annotations

import argparse
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from skeye import cliargs
from skeye.errors import RemoteProtocolError
from skeye.geo import MAX_POSITION_M
from skeye.outputs import figure_file, write_whole
from skeye.recording.records import (
    CONNECTED,
    NOTE,
    RECEIVED,
    SENT,
    TRUTH,
    RecordingReader,
    recording_file,
)
from skeye.wire.sim_lines import parse_line


@dataclass
class RobotTrack:
    """One robot's ground truth over sim time (NED metres, seconds)."""

    name: str
    time_s: list[float] = field(default_factory=list)
    pos_ned_m: list[tuple[float, float, float]] = field(default_factory=list)
    battery_time_s: list[float] = field(default_factory=list)
    battery_s: list[float] = field(default_factory=list)
    battery_landed: list[bool] = field(default_factory=list)  # on the ground at that sample
    commands: Counter[str] = field(default_factory=Counter)

    def distance_m(self) -> float:
        if len(self.pos_ned_m) < 2:
            return 0.0
        p = np.asarray(self.pos_ned_m)
        return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


@dataclass
class RecordingSummary:
    """What :func:`summarize` reports about a recording."""

    path: str
    sim_duration_s: float
    wall_duration_s: float
    records: int
    connections: int
    lines_sent: int
    lines_received: int
    notes: list[str]
    bad_lines: int
    truncated: bool
    robots: dict[str, dict[str, float | int | str]]
    far_positions: int = 0  # of the bad lines: a Location beyond MAX_POSITION_M
    parts: list[str] = field(default_factory=list)  # the files read (a rotated flight's parts)
    broken: str | None = None  # why the parts end before the recording did

    def text(self) -> str:
        of = f" ({len(self.parts)} parts: {', '.join(Path(p).name for p in self.parts)})" \
            if len(self.parts) > 1 else ""
        lines = [
            f"{self.path}{of}: {self.records} records, {self.connections} connection(s), "
            f"sim {self.sim_duration_s:.2f} s over wall {self.wall_duration_s:.2f} s",
            f"  lines sent {self.lines_sent}, received {self.lines_received}, "
            f"bad {self.bad_lines}{self._far_text()}"
            f"{', last line cut off' if self.truncated else ''}",
        ]
        for name, r in self.robots.items():
            lines.append(
                f"  {name}: {r['samples']} samples, {r['distance_m']:.2f} m flown, altitude "
                f"{r['min_altitude_m']:.2f}..{r['max_altitude_m']:.2f} m, battery left "
                f"{r['battery_end_s']:.0f} s, commands {r['commands']}"
            )
        lines.extend(f"  note: {n}" for n in self.notes)
        if self.broken is not None:
            lines.append(f"  warning: {self.broken}: the flight is read up to there")
        return "\n".join(lines)

    def _far_text(self) -> str:
        if not self.far_positions:
            return ""
        return (f" ({self.far_positions} with a Location beyond {MAX_POSITION_M:g} m of the "
                "origin, the simulator's limit: skipped)")


def _vector(msg: Any, key: str) -> tuple[float, float, float] | None:
    try:
        x, y, z = msg.get_vector(key, 3)
    except RemoteProtocolError:
        return None
    return (x, y, z)


def load_tracks(path: str | Path) -> tuple[dict[str, RobotTrack], RecordingSummary]:
    """Read a recording: each robot's track and a summary (see :func:`summarize`)."""
    reader = RecordingReader(path, follow_parts=True)
    conn_robot: dict[int, str] = {}
    truth: dict[str, RobotTrack] = {}
    sensed: dict[str, RobotTrack] = {}
    commands: dict[int, Counter[str]] = {}
    counts: Counter[str] = Counter()
    first_sim = last_sim = first_wall = last_wall = math.nan
    notes: list[str] = []
    records = 0
    bad_values = 0
    far_positions = 0
    for rec in reader.records():
        records += 1
        if records == 1:
            first_sim, first_wall = rec.sim_s, rec.wall_s
        last_sim, last_wall = rec.sim_s, rec.wall_s
        counts[rec.direction] += 1
        if rec.direction == NOTE:
            notes.append(rec.line)
            continue
        if rec.direction not in (TRUTH, SENT, RECEIVED):
            continue
        if rec.direction == RECEIVED:
            word = rec.line.split(" ", 1)[0].upper()
            commands.setdefault(rec.conn, Counter())[word] += 1
            continue
        line = rec.line
        if rec.direction == SENT and not (
            line.startswith(("RES {Command INIT}", "STA "))
            or (line.startswith("SEN ") and "{Type GroundTruth}" in line)
        ):
            continue
        try:
            msg = parse_line(rec.line)
            _values(msg)
        except RemoteProtocolError:
            bad_values += 1  # a line whose values are not numbers: counted with the bad lines
            continue
        if _beyond_limit(msg):  # never recorded by the simulator: a bad line, said as such
            far_positions += 1
            continue
        if rec.direction == TRUTH:
            truth_name = msg.get("Name") or "?"
            track = truth.setdefault(truth_name, RobotTrack(truth_name))
            pos = _vector(msg, "Location")
            if pos is not None:
                track.time_s.append(rec.sim_s)
                track.pos_ned_m.append(pos)
            if msg.has("Battery"):
                track.battery_time_s.append(rec.sim_s)
                track.battery_s.append(msg.get_float("Battery"))
                track.battery_landed.append(_landed(msg))
            continue
        if msg.type == "RES":
            if msg.get("Name"):
                conn_robot[rec.conn] = msg.require("Name")
            continue
        name = conn_robot.get(rec.conn)
        if name is None and msg.type == "STA" and msg.get("Name"):
            # No INIT answer in this file (a later part of a rotated recording): the robot's
            # status lines name it.
            name = conn_robot[rec.conn] = msg.require("Name")
        if name is None:
            continue
        track = sensed.setdefault(name, RobotTrack(name))
        if msg.type == "STA" and msg.has("Battery"):
            track.battery_time_s.append(rec.sim_s)
            track.battery_s.append(msg.get_float("Battery"))
            track.battery_landed.append(_landed(msg))
        elif msg.type == "SEN":
            pos = _vector(msg, "Location")
            if pos is not None:
                track.time_s.append(msg.get_float("Time") if msg.get("Time") else rec.sim_s)
                track.pos_ned_m.append(pos)
    tracks: dict[str, RobotTrack] = {}
    for name in dict.fromkeys([*truth, *sensed, *conn_robot.values()]):
        t = truth.get(name) if truth.get(name) and truth[name].time_s else sensed.get(name)
        tracks[name] = t or RobotTrack(name)
    for conn, name in conn_robot.items():
        tracks[name].commands.update(commands.get(conn, Counter()))
    summary = summarize(
        tracks,
        path=str(path),
        sim_duration_s=0.0 if records == 0 else last_sim - first_sim,
        wall_duration_s=0.0 if records == 0 else last_wall - first_wall,
        records=records,
        connections=counts[CONNECTED],
        lines_sent=counts[SENT],
        lines_received=counts[RECEIVED],
        notes=notes,
        bad_lines=reader.bad_lines + bad_values + far_positions,
        truncated=reader.truncated,
        far_positions=far_positions,
        parts=[str(p) for p in reader.parts],
        broken=reader.broken,
    )
    return tracks, summary


def _values(msg: Any) -> None:
    """The numbers a track takes from ``msg`` are numbers (RemoteProtocolError names one that
    is not; a Location must be three), so a bad line is counted and skipped instead of ending
    the plot."""
    for key in ("Battery", "Time"):
        if msg.get(key):
            msg.get_float(key)
    if msg.get("Location"):
        msg.get_vector("Location", 3)


def _beyond_limit(msg: Any) -> bool:
    """Whether ``msg``'s Location (checked by :func:`_values`) lies beyond the simulator's
    limit: near 1e308 m its distances summed to inf and matplotlib's ticks raised OverflowError."""
    location = msg.get("Location")
    return bool(location) and max(map(abs, msg.get_vector("Location", 3))) > MAX_POSITION_M


def _landed(msg: Any) -> bool:
    return msg.has("Landed") and str(msg.get("Landed")).lower() in ("true", "1")


def flight_time_left_min(track: RobotTrack) -> np.ndarray:
    """The battery's flight time left (minutes) while flying; NaN (a gap in the plot) where the
    robot is on the ground (recordings made before STA's Battery had a hover-current floor
    read hours there, which would flatten the flight)."""
    left = np.asarray(track.battery_s, dtype=float) / 60.0
    landed = np.asarray(track.battery_landed + [False] * (len(left) - len(track.battery_landed)))
    return np.where(landed, np.nan, left)


def summarize(tracks: dict[str, RobotTrack], **totals: Any) -> RecordingSummary:
    """Per-robot figures (samples, distance, altitude range, battery left, commands)."""
    robots: dict[str, dict[str, float | int | str]] = {}
    for name, t in tracks.items():
        alt = [-p[2] for p in t.pos_ned_m]
        robots[name] = {
            "samples": len(t.time_s),
            "distance_m": t.distance_m(),
            "min_altitude_m": min(alt) if alt else math.nan,
            "max_altitude_m": max(alt) if alt else math.nan,
            "battery_end_s": t.battery_s[-1] if t.battery_s else math.nan,
            "commands": ", ".join(f"{k} {v}" for k, v in sorted(t.commands.items())) or "none",
        }
    return RecordingSummary(robots=robots, **totals)


def plot_recording(path: str | Path, out: str | Path, *,
                   option: str = "--out") -> RecordingSummary:
    """Draw ``path`` into the image ``out`` (its extension picks the format; none: ``.png``);
    returns the summary. ``out`` is written whole or not at all
    (:func:`skeye.outputs.write_whole`): a write that fails (a full disk, ``ulimit -f``) is a
    ConfigError naming ``option`` and ``out``, and leaves the file that was there.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    if not out.suffix:  # as matplotlib names it; the partial file beside it needs the name
        out = out.with_name(out.name + ".png")
    tracks, summary = load_tracks(path)
    fig, (top, alt, bat) = plt.subplots(1, 3, figsize=(15, 4.8))
    try:
        for name, t in tracks.items():
            if t.pos_ned_m:
                p = np.asarray(t.pos_ned_m)
                top.plot(p[:, 1], p[:, 0], label=name)
                top.plot(p[0, 1], p[0, 0], "o", color=top.lines[-1].get_color())
                alt.plot(t.time_s, -p[:, 2], label=name)
            if t.battery_s:
                bat.plot(t.battery_time_s, flight_time_left_min(t), label=name)
        top.set(title="trajectory (top view)", xlabel="east (m)", ylabel="north (m)")
        top.set_aspect("equal", adjustable="datalim")
        alt.set(title="altitude", xlabel="sim time (s)", ylabel="altitude above origin (m)")
        bat.set(title="battery (shown while flying only)", xlabel="sim time (s)",
                ylabel="flight time left (min)")
        for ax in (top, alt, bat):
            ax.grid(True, alpha=0.3)
            if ax.lines:
                ax.legend(loc="best", fontsize="small")
        fig.suptitle(Path(path).name + (f" and its {len(summary.parts) - 1} later part(s)"
                                         if len(summary.parts) > 1 else ""))
        fig.tight_layout()
        write_whole([(option, out, lambda partial: fig.savefig(partial, dpi=100))])
    finally:
        plt.close(fig)
    return summary


def cmd_plot(args: argparse.Namespace) -> int:
    if args.file.exists():  # a folder named as one, not as a folder --out is inside; a
        recording_file(args.file)  # missing file is said after --out, as every input's is
    out = figure_file(args.out, "--out", args.file, "recording")  # before it is read
    summary = plot_recording(args.file, out)
    print(summary.text())
    print(f"skeye plot: wrote {out}")
    return 0


def register(sub: Any) -> None:
    """Add ``skeye plot`` to the command line."""
    p = sub.add_parser("plot", help="draw a flight recording (trajectory, altitude, battery)")
    p.add_argument("file", type=cliargs.file_path, help="a recording made with skeye sim --record")
    p.add_argument("--out", type=cliargs.file_path, default=Path("plot.png"),
                   help="image to write (its extension picks the format; none: .png)")
    p.set_defaults(func=cmd_plot)
