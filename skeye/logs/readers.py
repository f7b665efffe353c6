"""Readers of real flight logs: EuRoC-style CSV folders, PX4 ULog files, ROS bags.

How this works: each reader returns an :class:`ImuLog`: the IMU's samples (time, gyro rad/s,
specific force m/s^2, in the IMU's own axes, as logged) and, where the log has one, a ground
truth track (time, position, attitude quaternion w x y z of the IMU or body in the world) with
the direction of the world's vertical axis ("up" for EuRoC's and ROS's z-up worlds, "down"
for PX4's NED). Nothing is resampled or filtered. PX4 ULog needs ``pyulog`` and ROS bags
``rosbags`` (the ``logs`` extra); EuRoC CSV needs nothing but numpy. :func:`read_log` picks the
reader from the path (a folder: EuRoC; ``.ulg``: ULog; ``.bag`` or a rosbag2 folder: ROS).

Invariants: times are seconds from the log's first IMU sample; arrays are float64, one row per
sample; a log without IMU samples, or with times that go backwards or repeat, is refused
(ConfigError naming the file and the first such sample), and so is a ground truth that is not
numbers, has a zero-length quaternion or times that go backwards (the replay would judge
against NaN or the wrong instant).
"""

from __future__ import annotations

import contextlib
import csv
import io
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from skeye.errors import ConfigError

LOG_FORMATS = ("auto", "euroc", "ulog", "rosbag")

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TruthTrack:
    """A log's ground truth: times (s), positions (m), quaternions w x y z (body -> world)."""

    t_s: np.ndarray
    pos_m: np.ndarray
    quat_wxyz: np.ndarray
    world_z: str  # "up" (EuRoC, ROS) or "down" (PX4's NED)


@dataclass(frozen=True)
class ImuLog:
    """A log's IMU samples in the IMU's own axes, and its ground truth if it has one."""

    name: str
    t_s: np.ndarray
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray
    truth: TruthTrack | None = None

    @property
    def rate_hz(self) -> float:
        """The median sample rate."""
        return float(1.0 / np.median(np.diff(self.t_s)))

    def span(self, start_s: float | None, end_s: float | None) -> ImuLog:
        """The samples from ``start_s`` to ``end_s`` (seconds from the first; None: the end)."""
        lo = self.t_s[0] if start_s is None else start_s
        hi = self.t_s[-1] if end_s is None else end_s
        keep = (self.t_s >= lo) & (self.t_s <= hi)
        if int(keep.sum()) < 2:
            raise ConfigError(f"{self.name}: no IMU samples between {lo:g} and {hi:g} s")
        return ImuLog(self.name, self.t_s[keep], self.gyro_rad_s[keep], self.accel_m_s2[keep],
                      self.truth)


def _checked(name: str, t_ns_or_s: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
             scale: float, truth: TruthTrack | None) -> ImuLog:
    if len(t_ns_or_s) < 2:
        raise ConfigError(f"{name}: fewer than two IMU samples")
    lost = np.flatnonzero(~np.isfinite(t_ns_or_s))  # a EuRoC stamp of "nan": no comparison
    if len(lost):  # catches it, so the order check let it through
        k = int(lost[0])
        raise ConfigError(f"{name}: IMU times that are not numbers: sample {k} is stamped "
                          f"{t_ns_or_s[k]} ({len(lost)} such samples)")
    t = (t_ns_or_s - t_ns_or_s[0]) * scale
    back = np.flatnonzero(np.diff(t) <= 0.0)
    if len(back):  # named by the first sample (from 0) whose time is not after the one before
        k = int(back[0]) + 1
        raise ConfigError(f"{name}: IMU times do not increase: sample {k} at {t[k]:.6g} s "
                          f"follows one at {t[k - 1]:.6g} s (seconds from the first sample)")
    bad = np.flatnonzero(~(np.isfinite(gyro).all(axis=1) & np.isfinite(accel).all(axis=1)))
    if len(bad):  # named by the first, as a time that goes backwards is
        k = int(bad[0])
        row = np.concatenate((gyro[k], accel[k])).astype(float)
        i = int(np.flatnonzero(~np.isfinite(row))[0])
        raise ConfigError(f"{name}: IMU samples that are not numbers: sample {k} at {t[k]:.6g} s "
                          f"reads {row[i]} in the {('gyro', 'accelerometer')[i // 3]}'s "
                          f"{'xyz'[i % 3]} ({len(bad)} such samples)")
    if truth is not None:
        _check_truth(name, truth)
        t0 = t_ns_or_s[0]
        truth = TruthTrack((truth.t_s - t0) * scale, truth.pos_m, truth.quat_wxyz, truth.world_z)
    return ImuLog(name, t, gyro.astype(float), accel.astype(float), truth)


def _check_truth(name: str, truth: TruthTrack) -> None:
    """A ground truth the replay can judge against: numbers, rotations, times in order."""
    if not (np.all(np.isfinite(truth.t_s)) and np.all(np.isfinite(truth.pos_m))
            and np.all(np.isfinite(truth.quat_wxyz))):
        raise ConfigError(f"{name}: ground truth that is not numbers")
    if np.any(np.linalg.norm(truth.quat_wxyz, axis=1) < 1e-6):
        raise ConfigError(f"{name}: ground-truth quaternions of zero length (no attitude)")
    if np.any(np.diff(truth.t_s) < 0.0):
        raise ConfigError(f"{name}: ground-truth times go backwards")


def _csv_rows(path: Path) -> tuple[np.ndarray, list[int] | None]:
    """The data rows of a EuRoC CSV file, as numbers, and their first field (the timestamp, ns)
    as exact integers where every one is an integer (else None): a float64 holds EuRoC's
    19-digit stamps to 256 ns only, and a 200 Hz log read 200.0026 Hz. A row with another number
    of fields than the first (a file cut short mid-line), or a field that is not a number, is
    named by its line number."""
    try:
        # utf-8-sig: a file saved by a spreadsheet or Notepad starts with a byte-order mark,
        # which hid the header's "#" ("line 1 is not numbers: '\ufeff#timestamp [ns]'")
        with open(path, newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            numbered = [(reader.line_num, r) for r in reader
                        if r and not r[0].lstrip().startswith("#")]
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: not a readable EuRoC CSV file: {exc}") from None
    for line, row in numbered:
        if len(row) != len(numbered[0][1]):
            raise ConfigError(f"{path}: line {line} has {len(row)} fields where line "
                              f"{numbered[0][0]} has {len(numbered[0][1])} (a file cut short?)")
    values: list[list[float]] = []
    for line, row in numbered:
        try:
            values.append([float(v) for v in row])
        except ValueError as exc:  # named by its line: a log is tens of thousands of them
            raise ConfigError(f"{path}: line {line} is not numbers: {exc}") from None
    try:
        stamps: list[int] | None = [int(row[0]) for _, row in numbered]
    except ValueError:  # "1.4e18", "nan": read as the numbers they are
        stamps = None
    return np.array(values, dtype=float), stamps


def read_euroc(folder: Path) -> ImuLog:
    """An EuRoC MAV dataset folder (``mav0/`` or the folder holding it): ``imu0/data.csv``
    (timestamp ns, w_RS_S x y z rad/s, a_RS_S x y z m/s^2) and, if present,
    ``state_groundtruth_estimate0/data.csv`` (timestamp ns, p_RS_R x y z m, q_RS w x y z)."""
    root = folder / "mav0" if (folder / "mav0").is_dir() else folder
    imu_csv = root / "imu0" / "data.csv"
    if not imu_csv.is_file():
        raise ConfigError(f"{folder}: no imu0/data.csv (an EuRoC-style folder has mav0/imu0/)")
    imu, imu_ns = _csv_rows(imu_csv)
    if not imu.size:
        raise ConfigError(f"{imu_csv}: no IMU samples (no line but comments)")
    if imu.ndim != 2 or imu.shape[1] < 7:
        raise ConfigError(f"{imu_csv}: expected 7 columns (timestamp, w xyz, a xyz)")
    truth = None
    gt_ns: list[int] | None = None
    gt_csv = root / "state_groundtruth_estimate0" / "data.csv"
    if gt_csv.is_file():
        gt, gt_ns = _csv_rows(gt_csv)
        if not gt.size:  # a file cut short or left empty: not a log without ground truth
            raise ConfigError(f"{gt_csv}: no ground-truth poses (no line but comments); a log "
                              "without ground truth has no state_groundtruth_estimate0/")
        if gt.ndim != 2 or gt.shape[1] < 8:
            raise ConfigError(f"{gt_csv}: expected 8 columns (timestamp, p xyz, q wxyz)")
        gt_t = gt[:, 0]
        if imu_ns is not None and gt_ns is not None:  # from the IMU's first stamp, exactly
            gt_t = np.array([k - imu_ns[0] for k in gt_ns], dtype=float)
        truth = TruthTrack(gt_t, gt[:, 1:4], gt[:, 4:8], "up")
    imu_t = imu[:, 0]
    if imu_ns is not None and (truth is None or gt_ns is not None):
        imu_t = np.array([k - imu_ns[0] for k in imu_ns], dtype=float)
    return _checked(str(folder), imu_t, imu[:, 1:4], imu[:, 4:7], 1e-9, truth)


def read_ulog(path: Path) -> ImuLog:
    """A PX4 ULog: ``sensor_combined`` (gyro_rad, accelerometer_m_s2, FRD body) and, in a
    simulation's log, ``vehicle_local_position_groundtruth`` + ``vehicle_attitude_groundtruth``
    (NED); a topic logged in several instances is read from instance 0."""
    try:
        from pyulog import ULog
    except ImportError:
        raise ConfigError("reading ULog files needs pyulog: pip install 'skeye[logs]'") from None
    said = io.StringIO()  # pyulog prints what it finds damaged: on stdout, into the table
    try:
        # The file is opened here, not by pyulog: given a name, it leaves the file open when
        # the parse fails.
        with open(path, "rb") as f, contextlib.redirect_stdout(said):
            ulog = ULog(f, ["sensor_combined", "vehicle_local_position_groundtruth",
                            "vehicle_attitude_groundtruth"])
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except Exception as exc:  # pyulog raises bare exceptions on a damaged file
        raise ConfigError(f"{path}: not a readable ULog file: {exc}") from None
    words = "; ".join(line.strip() for line in said.getvalue().splitlines() if line.strip())
    # Damage is what pyulog flags as such; it also prints notes on a whole file ("unknown file
    # version", a longer flag bits message: a newer PX4's), which are passed on, not damage.
    damage = (words or "damaged messages skipped") if ulog.file_corruption else ""
    # A topic logged in several instances is read from its lowest (0, the primary), as pyulog's
    # get_dataset takes it by default.
    topics: dict[str, dict[str, Any]] = {}
    for d in sorted(ulog.data_list, key=lambda d: d.multi_id):
        topics.setdefault(d.name, d.data)
    imu = topics.get("sensor_combined")
    if imu is None:
        if damage:  # cut short or damaged before the IMU's first sample: say so
            raise ConfigError(f"{path}: not a readable ULog file: damaged or cut short before "
                              f"any sensor_combined sample (pyulog: {damage})")
        if "sensor_combined" in ulog.message_formats:
            raise ConfigError(f"{path}: the sensor_combined topic (the IMU) has no samples "
                              "(a log cut short?)")
        raise ConfigError(f"{path}: no sensor_combined topic (the IMU)")
    if damage:  # what pyulog read around the damage is used; a hole in it is a gap, refused
        log.warning("%s: the ULog file is damaged, pyulog skipped what it could not read (%s)",
                    path, damage)
    elif words:
        log.warning("%s: pyulog: %s", path, words)
    _ulog_fields(path, "sensor_combined", imu, ["timestamp"]
                 + [f"{v}[{i}]" for v in ("gyro_rad", "accelerometer_m_s2") for i in range(3)])
    t = np.asarray(imu["timestamp"], dtype=float)
    gyro = np.column_stack([imu[f"gyro_rad[{i}]"] for i in range(3)])
    accel = np.column_stack([imu[f"accelerometer_m_s2[{i}]"] for i in range(3)])
    truth = None
    pos, att = topics.get("vehicle_local_position_groundtruth"), topics.get(
        "vehicle_attitude_groundtruth")
    if pos is not None and att is not None:
        _ulog_fields(path, "vehicle_local_position_groundtruth", pos, ["timestamp", "x", "y", "z"])
        _ulog_fields(path, "vehicle_attitude_groundtruth", att,
                     ["timestamp"] + [f"q[{i}]" for i in range(4)])
        tp = np.asarray(pos["timestamp"], dtype=float)
        if np.any(np.diff(np.asarray(att["timestamp"], dtype=float)) < 0.0):
            raise ConfigError(f"{path}: ground-truth times go backwards "
                              "(vehicle_attitude_groundtruth)")
        q = np.column_stack([att[f"q[{i}]"] for i in range(4)]).astype(float)
        # q and -q are one rotation, and a log may give either (one that keeps w >= 0 flips
        # sign when w crosses 0): each is put in the hemisphere of the one before, since
        # interpolating from q towards -q passes through 0 (refused as "quaternions of zero
        # length") or a rotation neither is
        turn = np.where(np.sum(q[1:] * q[:-1], axis=1) < 0.0, -1.0, 1.0)
        q[1:] *= np.cumprod(turn)[:, None]
        quat = np.column_stack([np.interp(tp, att["timestamp"], q[:, i]) for i in range(4)])
        truth = TruthTrack(tp, np.column_stack([pos["x"], pos["y"], pos["z"]]), quat, "down")
    return _checked(str(path), t, gyro, accel, 1e-6, truth)


def _ulog_fields(path: Path, topic: str, data: dict[str, Any], names: list[str]) -> None:
    """A topic's fields that the reader uses; ConfigError names the ones it lacks."""
    missing = [n for n in names if n not in data]
    if missing:
        raise ConfigError(f"{path}: the {topic} topic has no field {', '.join(missing)} "
                          "(a PX4 log's has)")


def read_rosbag(path: Path, imu_topic: str | None = None,
                truth_topic: str | None = None) -> ImuLog:
    """A ROS 1 bag or a ROS 2 bag folder: ``sensor_msgs/msg/Imu`` (the first such topic unless
    ``imu_topic``) and ground truth from a ``geometry_msgs/msg/TransformStamped``,
    ``PoseStamped`` or ``nav_msgs/msg/Odometry`` topic (``truth_topic``, else the first), in a
    z-up world as ROS's REP 103 has it."""
    try:
        from rosbags.highlevel import AnyReader
    except ImportError:
        raise ConfigError("reading ROS bags needs rosbags: pip install 'skeye[logs]'") from None
    imu_rows: list[list[Any]] = []  # stamp (int ns), then floats
    truth_rows: list[list[Any]] = []
    truth_types = ("geometry_msgs/msg/TransformStamped", "geometry_msgs/msg/PoseStamped",
                   "nav_msgs/msg/Odometry")
    try:
        with AnyReader([path]) as reader:
            conns = reader.connections
            imu_conn = [c for c in conns if (c.topic == imu_topic if imu_topic is not None
                                             else c.msgtype == "sensor_msgs/msg/Imu")][:1]
            if not imu_conn:
                raise ConfigError(f"{path}: no IMU topic" + (
                    f" {imu_topic!r}" if imu_topic is not None else " (sensor_msgs/Imu)"))
            gt_conn = [c for c in conns if (c.topic == truth_topic if truth_topic is not None
                                            else c.msgtype in truth_types)][:1]
            # named ("" too: no topic is called so), so wanted: refused as --imu-topic is
            if truth_topic is not None and not gt_conn:
                raise ConfigError(f"{path}: no ground-truth topic {truth_topic!r} "
                                  "(--truth-topic)")
            if imu_conn[0].msgtype != "sensor_msgs/msg/Imu":
                raise ConfigError(f"{path}: --imu-topic {imu_topic!r} holds "
                                  f"{imu_conn[0].msgtype}, not sensor_msgs/msg/Imu")
            if gt_conn and gt_conn[0].msgtype not in truth_types:
                raise ConfigError(f"{path}: --truth-topic {truth_topic!r} holds "
                                  f"{gt_conn[0].msgtype}, not {', '.join(truth_types)}")
            for conn, _t, raw in reader.messages(connections=imu_conn + gt_conn):
                msg: Any = reader.deserialize(raw, conn.msgtype)
                # in integer ns: as float64 seconds a stamp of today's clock (1.7e9 s) holds
                # to 238 ns, and a 200 Hz IMU read 199.9954 Hz
                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                if conn in imu_conn:
                    w, a = msg.angular_velocity, msg.linear_acceleration
                    imu_rows.append([stamp, w.x, w.y, w.z, a.x, a.y, a.z])
                    continue
                if conn.msgtype == "geometry_msgs/msg/TransformStamped":
                    p, q = msg.transform.translation, msg.transform.rotation
                elif conn.msgtype == "nav_msgs/msg/Odometry":
                    p, q = msg.pose.pose.position, msg.pose.pose.orientation
                else:
                    p, q = msg.pose.position, msg.pose.orientation
                truth_rows.append([stamp, p.x, p.y, p.z, q.w, q.x, q.y, q.z])
    except ConfigError:
        raise
    except Exception as exc:  # rosbags raises its own errors on a damaged bag
        raise ConfigError(f"{path}: not a readable ROS bag: {exc}") from None
    if not imu_rows:
        raise ConfigError(f"{path}: the IMU topic has no messages")
    imu_rows.sort(key=lambda row: row[0])  # stamp order (a bag holds arrival order)
    t0_ns = imu_rows[0][0]
    imu = np.array([[row[0] - t0_ns, *row[1:]] for row in imu_rows], dtype=float)
    truth = None
    if truth_rows:
        truth_rows.sort(key=lambda row: row[0])
        gt = np.array([[row[0] - t0_ns, *row[1:]] for row in truth_rows], dtype=float)
        truth = TruthTrack(gt[:, 0], gt[:, 1:4], gt[:, 4:8], "up")
    return _checked(str(path), imu[:, 0], imu[:, 1:4], imu[:, 4:7], 1e-9, truth)


def read_log(path: Path, fmt: str = "auto", *, imu_topic: str | None = None,
             truth_topic: str | None = None) -> ImuLog:
    """Read a log, its format named or told by the path (see the module doc)."""
    if fmt not in LOG_FORMATS:
        raise ConfigError(f"unknown log format {fmt!r}: {', '.join(LOG_FORMATS)}")
    if not path.exists():
        raise ConfigError(f"{path}: no such file or folder")
    if fmt == "auto":
        if path.suffix == ".ulg":
            fmt = "ulog"
        elif path.suffix == ".bag" or (path.is_dir() and (path / "metadata.yaml").is_file()):
            fmt = "rosbag"
        elif path.is_dir():
            fmt = "euroc"
        else:
            raise ConfigError(f"{path}: cannot tell the log format (.ulg, .bag, a rosbag2 or "
                              "EuRoC folder); name it with --format")
    topics = [option for option, topic in (("--imu-topic", imu_topic),
                                           ("--truth-topic", truth_topic)) if topic is not None]
    if topics and fmt != "rosbag":  # it would be ignored: only a bag has topics
        raise ConfigError(f"{', '.join(topics)} name(s) a ROS bag's topic; {path} is a {fmt} "
                          "log, which has none")
    if fmt == "euroc":
        return read_euroc(path)
    if fmt == "ulog":
        return read_ulog(path)
    return read_rosbag(path, imu_topic, truth_topic)
