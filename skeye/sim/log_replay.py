"""``skeye logs``: a real flight log's IMU against the simulated one, and the board estimator
replayed on the log's sensors.

How this works: the log is read by :mod:`skeye.logs.readers` and measured by
:mod:`skeye.logs.analysis` (vibration above 10 Hz, Allan deviation at 1 s). The simulated IMU
is the robot file's own accelerometer and gyro (the Hummingbird's by default), sampled at the
log's rate in a level hover with the rotors at the vibration's reference speed, for as long as
the log (at most 120 s), and measured the same way. The replay feeds the log's gyro and
accelerometer samples, turned into a body frame whose z axis is the log's first second's
gravity, to :class:`skeye.sim.estimator.BoardEstimator` (power-up calibration on that first
second, as the simulated board does), and compares the estimate's tilt with the log's ground
truth: the angle between the estimated and the true "down" in the body frame (roll and pitch
together; heading needs a compass the IMU logs lack). The simulated IMU goes through the same
replay against its known level attitude, so the two tilt errors stand side by side.

Limits: the log is assumed to start at rest for one second (EuRoC's and PX4's logs start on the
ground); only the IMU is replayed (position needs the log's aiding sensors, which EuRoC lacks).
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from skeye import cliargs
from skeye.errors import ConfigError
from skeye.logs.analysis import imu_figures, lowest_rate_hz, samples_above, spectrum
from skeye.logs.readers import LOG_FORMATS, ImuLog, TruthTrack, read_log
from skeye.outputs import different_files, figure_file, output_file, write_whole
from skeye.robots.config import load_robot_config
from skeye.robots.params import GRAVITY_M_S2, EstimatorParams
from skeye.sim.estimator import BoardEstimator
from skeye.sim.sensors import Accelerometer, AccelReading, Gyro, GyroReading, Mount
from skeye.sim.sensors.inertial import HOVER_SPEED_RAD_S
from skeye.sim.state import BodyState

EUROC_HOVER: dict[str, tuple[float, float]] = {
    "accel_band_rms": (0.9, 1.3),
    "gyro_band_rms": (0.06, 0.07),
}
"""Published in-flight figures: the EuRoC MAV dataset's ADIS16448 (200 Hz) on an AscTec
multirotor in hover, content above 10 Hz, per axis (m/s^2, rad/s): the range measured over its
hover segments (docs/physics.md, "In-flight vibration")."""

REST_S = 1.0  # the log's first second: at rest, for the power-up calibration
MIN_HOVER_S = REST_S + 1.0  # skeye logs --seconds: the rest, then a second of hover to measure
TRUTH_GAP_S = 0.1  # ground truth further than this from an instant is not used for it
REST_TURN_DEG = 1.0  # a truth turning more than this in the first second: not at rest
GAP_INTERVALS = 5.0  # an IMU interval this many median ones long (and over 0.1 s) is a gap
VIBRATION_FROM_HZ = 10.0  # the vibration figure: the content above this (imu_figures' low_hz)
MAX_SIM_S = 120.0  # the simulated hover's longest: a log's length beyond it, --seconds' limit
MAX_RATE_HZ = 10000.0  # the simulated IMU's fastest rate: --rate's limit, and a log's


def _quat_rows(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _align(f_sensor: np.ndarray) -> np.ndarray:
    """The rotation (sensor -> body) that takes the mean specific force at rest to body -z."""
    a = f_sensor / np.linalg.norm(f_sensor)
    b = np.array([0.0, 0.0, -1.0])
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    if np.linalg.norm(v) < 1e-9:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def _refuse_turning_rest(t0_s: float, truth: TruthTrack) -> None:
    """Refuse a first second in which the ground truth turns more than ``REST_TURN_DEG`` from
    its first pose in it: the board calibrates its gyro on that second, as a board does at
    power-up on a vehicle standing still, so a turning one would be judged on a gyro bias made
    up of its turn rate (``--start`` mid-flight read 5.5 deg RMS where the log reads 0.5)."""
    inside = (truth.t_s >= t0_s) & (truth.t_s < t0_s + REST_S)
    if int(inside.sum()) < 2 or np.ptp(truth.t_s[inside]) == 0.0:
        # no truth over that second (poses all stamped at one instant tell no turn): the
        # accelerometer's check is all there is
        return
    q = truth.quat_wxyz[inside] / np.linalg.norm(truth.quat_wxyz[inside], axis=1)[:, None]
    # the angle between two unit quaternions: 2 acos |q1 . q2|
    turn = np.degrees(2.0 * np.arccos(np.clip(np.abs(q @ q[0]), 0.0, 1.0))).max()
    if turn > REST_TURN_DEG:
        raise ConfigError(f"the first second ({t0_s:g}..{t0_s + REST_S:g} s) is not at rest: its "
                          f"ground truth turns {turn:.3g} deg in it (more than "
                          f"{REST_TURN_DEG:g}), and the board calibrates its gyro on that "
                          "second; start the window (--start) where the vehicle stands still")


def replay_tilt(t_s: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
                truth: TruthTrack | None, every_s: float = 0.05) -> dict[str, float]:
    """The board estimator on these IMU samples; its tilt error against ``truth`` (a level
    vehicle when None), RMS and maximum in degrees."""
    rest = t_s < t_s[0] + REST_S
    if int(rest.sum()) < 2:
        raise ConfigError("the log's first second has too few IMU samples to calibrate on")
    at_rest = accel[rest].mean(axis=0)
    if not float(np.linalg.norm(at_rest)) >= 0.5 * GRAVITY_M_S2:
        raise ConfigError(f"the log's first second reads a specific force of "
                          f"{float(np.linalg.norm(at_rest)):.3g} m/s^2, not gravity's "
                          f"{GRAVITY_M_S2:g}: the log must start at rest, its accelerometer in "
                          "m/s^2")
    if truth is not None:
        _refuse_turning_rest(t_s[0], truth)
    rot = _align(at_rest)
    gyro_b = gyro @ rot.T
    accel_b = accel @ rot.T
    est = BoardEstimator(EstimatorParams(), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 163.0)
    est.align_at_rest([(w[0], w[1], w[2]) for w in gyro_b[rest].tolist()],
                      [(f[0], f[1], f[2]) for f in accel_b[rest].tolist()])
    errors: list[float] = []
    next_s = t_s[0] + REST_S
    j = 0
    for k in range(len(t_s)):
        t = float(t_s[k])
        wx, wy, wz = gyro_b[k].tolist()
        fx, fy, fz = accel_b[k].tolist()
        est.observe(GyroReading(t, (wx, wy, wz)))
        est.observe(AccelReading(t, (fx, fy, fz)))
        if t < next_s:
            continue
        next_s = t + every_s
        r = est.rot()
        down_est = np.array([r[6], r[7], r[8]])  # NED down in the body frame
        if truth is None:
            down_true = np.array([0.0, 0.0, 1.0])
        else:
            while j + 1 < len(truth.t_s) and truth.t_s[j + 1] <= t:
                j += 1
            if abs(truth.t_s[j] - t) > TRUTH_GAP_S:
                continue  # no truth near this instant
            world_down = np.array([0.0, 0.0, 1.0 if truth.world_z == "down" else -1.0])
            down_true = rot @ (_quat_rows(truth.quat_wxyz[j]).T @ world_down)
        cos = float(np.clip(np.dot(down_est, down_true), -1.0, 1.0))
        errors.append(math.degrees(math.acos(cos)))
    if not errors:
        return {}
    e = np.array(errors)
    return {"tilt_rms_deg": float(np.sqrt(np.mean(e * e))), "tilt_max_deg": float(e.max()),
            "tilt_samples": float(len(e))}


def simulated_imu(rate_hz: float, seconds: float, robot: str = "hummingbird", seed: int = 1
                  ) -> ImuLog:
    """The robot file's accelerometer and gyro in a level hover (rotors at the vibration's
    reference speed, at rest on the ground for the first second), sampled at ``rate_hz``."""
    config = load_robot_config(robot)
    params: dict[str, dict[str, object]] = {}
    for mount in config.sensors:
        key = mount.type_name.lower()
        if key in ("accelerometer", "gyro") and key not in params:
            params[key] = {k: v for k, v in mount.params if k not in ("rate_hz", "rate")}
    rng = np.random.default_rng(seed)
    acc = Accelerometer("IMU", Mount(), params.get("accelerometer", {}), rng)
    gyr = Gyro("IMU", Mount(), params.get("gyro", {}), rng)
    gyr.share_board(acc)
    speed = float(acc.params["VibrationSpeed"]) or HOVER_SPEED_RAD_S
    n = int(seconds * rate_hz)
    t = np.arange(n) / rate_hz
    g_rows, a_rows = [], []
    world: Any = _NoWorld()
    for k in range(n):
        w = speed if t[k] >= REST_S else 0.0
        rotors = (w, w, w, w)
        state = BodyState(float(t[k]), specific_force_frd_m_s2=(0.0, 0.0, -GRAVITY_M_S2),
                          rotor_speed_rad_s=rotors)
        a_rows.append(acc.read(state, world).proper_acceleration_m_s2)
        g_rows.append(gyr.read(state, world).angular_velocity_rad_s)
    return ImuLog(f"simulated {robot}", t, np.array(g_rows), np.array(a_rows))


class _NoWorld:
    """The inertial sensors ask nothing of the world."""

    geo_origin = None
    magnetic_field_ned_ut = np.zeros(3)
    sea_level_pressure_pa = 101325.0


def in_flight(log: ImuLog) -> ImuLog:
    """The log after its first ``REST_S`` seconds at rest (from its first sample, which is
    ``--start``'s when given): what the table's figures and the plotted spectra measure."""
    return log.span(log.t_s[0] + REST_S, None)


def axis_mean_spectrum(log: ImuLog, attr: str) -> tuple[np.ndarray, np.ndarray]:
    """The power spectral density of ``attr`` (``accel_m_s2`` or ``gyro_rad_s``) in flight,
    the mean over the three axes: (frequencies Hz, units^2/Hz)."""
    data = getattr(in_flight(log), attr)
    freqs = spectrum(data[:, 0], log.rate_hz)[0]
    power = np.mean([spectrum(data[:, i], log.rate_hz)[1] ** 2 for i in range(3)], axis=0)
    return freqs, power


def reference_imu(log: ImuLog, robot: str = "hummingbird") -> ImuLog:
    """The simulated IMU a log is compared with: at the log's rate, as long (``MAX_SIM_S`` at
    most). A log whose rate (its median interval's) is over ``MAX_RATE_HZ`` is refused: IMU
    stamps that come in bursts (a FIFO's samples stamped as they are read, microseconds apart)
    read a rate of a MHz or more, and its simulated IMU (a Python loop, 12 us a sample) then
    ran for hours or ran out of memory, with no word."""
    seconds = float(log.t_s[-1] - log.t_s[0])
    rate = log.rate_hz
    if rate > MAX_RATE_HZ:
        raise ConfigError(
            f"{log.name}: the IMU samples every {1.0 / rate:.3g} s (its median interval: "
            f"{rate:.3g} Hz), over the {MAX_RATE_HZ:g} Hz the simulated IMU is sampled at most; "
            f"its {len(log.t_s)} samples over {seconds:.3g} s are "
            f"{(len(log.t_s) - 1) / seconds:.3g} Hz on average (stamps that come in bursts, "
            "several samples read at once, are no rate)")
    return simulated_imu(rate, min(MAX_SIM_S, seconds), robot)


def refuse_gaps(log: ImuLog) -> None:
    """Refuse IMU samples with a gap: an interval longer than ``TRUTH_GAP_S`` and than
    ``GAP_INTERVALS`` median intervals (a logger's dropout). The spectra and the Allan deviation
    take the samples as evenly spaced at the median rate, and the replay would integrate the
    gyro across the gap in one step, so a gap would corrupt every figure; the ConfigError names
    the first gap, in seconds from the log's first sample (``--start``'s clock)."""
    dt = np.diff(log.t_s)
    limit = max(TRUTH_GAP_S, GAP_INTERVALS * float(np.median(dt)))
    gaps = np.flatnonzero(dt > limit)
    if len(gaps):
        k = int(gaps[0])
        more = f" (and {len(gaps) - 1} more gaps)" if len(gaps) > 1 else ""
        raise ConfigError(f"{log.name}: no IMU sample for {float(dt[k]):.3g} s after "
                          f"{float(log.t_s[k]):.6g} s{more}, where the log samples every "
                          f"{float(np.median(dt)):.3g} s: the figures need unbroken samples; "
                          "measure a window without the gap with --start/--end")


def compare(log: ImuLog, robot: str = "hummingbird", sim: ImuLog | None = None
            ) -> dict[str, Any]:
    """The log's figures, the simulated IMU's at the log's rate (``sim``, else
    :func:`reference_imu`), and both replays."""
    refuse_gaps(log)
    rate = log.rate_hz
    flight = in_flight(log)
    sim = reference_imu(log, robot) if sim is None else sim
    sim_flight = in_flight(sim)
    # A log without ground truth gets no tilt error: replay_tilt would judge it against a level
    # vehicle, which only the simulated hover is.
    try:
        real_tilt = ({} if log.truth is None
                     else replay_tilt(log.t_s, log.gyro_rad_s, log.accel_m_s2, log.truth))
    except ConfigError as exc:  # the replay's refusal, named by the log it is about
        raise ConfigError(f"{log.name}: {exc}") from None
    result = {
        "log": log.name, "rate_hz": rate, "seconds": float(log.t_s[-1] - log.t_s[0]),
        "real": {**imu_figures(flight.gyro_rad_s, flight.accel_m_s2, rate), **real_tilt},
        "simulated": {**imu_figures(sim_flight.gyro_rad_s, sim_flight.accel_m_s2, rate),
                      **replay_tilt(sim.t_s, sim.gyro_rad_s, sim.accel_m_s2, None)},
        "has_truth": log.truth is not None,
    }
    if not samples_above(rate, VIBRATION_FROM_HZ):  # its cells read "-": the table says why
        result["vibration_unsampled"] = (
            f"The log samples at {rate:.3g} Hz: nothing above {VIBRATION_FROM_HZ:g} Hz is "
            f"sampled (its Nyquist frequency is {rate / 2.0:.3g} Hz), so no vibration figure.")
    if log.truth is not None and not real_tilt:  # its cells read "-": the table says why
        gt = log.truth.t_s
        result["truth_unused"] = (
            f"The log's ground truth ({len(gt)} poses, {gt[0]:.3f}..{gt[-1]:.3f} s from the "
            f"first IMU sample) is within {TRUTH_GAP_S:g} s of none of the instants the replay "
            f"judges ({float(log.t_s[0]) + REST_S:.3f}..{float(log.t_s[-1]):.3f} s): no tilt "
            "error for it.")
    return result


ROWS = (
    ("accel_band_rms", "accelerometer vibration above 10 Hz", "m/s^2", 1.0),
    ("gyro_band_rms", "gyro vibration above 10 Hz", "rad/s", 1.0),
    ("accel_adev_1s", "accelerometer Allan deviation at 1 s", "m/s^2", 1.0),
    ("gyro_adev_1s", "gyro Allan deviation at 1 s", "rad/s", 1.0),
    ("tilt_rms_deg", "board estimator tilt error, RMS", "deg", 1.0),
    ("tilt_max_deg", "board estimator tilt error, max", "deg", 1.0),
)


def report_table(result: dict[str, Any]) -> str:
    """The side-by-side table (Markdown)."""
    lines = [f"Log: {result['log']} ({result['seconds']:.1f} s at {result['rate_hz']:.1f} Hz)",
             "",
             "| figure | real (log) | simulated | EuRoC hover (published) |",
             "| --- | --- | --- | --- |"]
    for key, label, unit, _ in ROWS:
        real = result["real"].get(key)
        sim = result["simulated"].get(key)
        ref = EUROC_HOVER.get(key)
        lines.append(
            f"| {label} ({unit}) | {'-' if real is None else f'{real:.4g}'} | "
            f"{'-' if sim is None else f'{sim:.4g}'} | "
            f"{'-' if ref is None else f'{ref[0]:g}-{ref[1]:g}'} |")
    if result["real"] and not result["has_truth"]:  # simulated only: there is no log
        lines += ["", "The log has no ground truth: no tilt error for it."]
    for note in ("vibration_unsampled", "truth_unused"):
        if result.get(note):
            lines += ["", result[note]]
    return "\n".join(lines)


def plot(result_logs: list[ImuLog], path: Path) -> None:
    """Top: amplitude spectra of the logs' (and the simulated) accelerometer and gyro, mean over
    the axes. Bottom: the RMS of the content above each frequency, with EuRoC's published hover
    level above 10 Hz marked (the comparison the figures make)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 7.5))
    for col, (attr, unit, key) in enumerate((("accel_m_s2", "m/s^2", "accel_band_rms"),
                                             ("gyro_rad_s", "rad/s", "gyro_band_rms"))):
        top = fig.add_subplot(2, 2, col + 1)
        bottom = fig.add_subplot(2, 2, col + 3)
        for log in result_logs:
            freqs, power = axis_mean_spectrum(log, attr)  # the window the table measures
            top.semilogy(freqs, np.sqrt(power), linewidth=1, label=log.name)
            df = freqs[1] - freqs[0]
            above = np.sqrt(np.cumsum((power * df)[::-1])[::-1])
            bottom.plot(freqs, above, linewidth=1.2, label=log.name)
        lo, hi = EUROC_HOVER[key]
        bottom.errorbar([10.0], [(lo + hi) / 2], yerr=[[(hi - lo) / 2], [(hi - lo) / 2]],
                        fmt="o", color="black", capsize=4,
                        label="EuRoC ADIS16448 in hover, above 10 Hz (published)")
        name = "accelerometer" if col == 0 else "gyro"
        top.set_title(f"{name}: amplitude spectral density")
        top.set_ylabel(f"{unit}/sqrt(Hz)")
        bottom.set_title(f"{name}: RMS of the content above f, per axis")
        bottom.set_ylabel(unit)
        for ax in (top, bottom):
            ax.axvline(10.0, color="grey", linestyle=":", linewidth=0.8)
            ax.set_xlabel("frequency f (Hz)")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
        bottom.set_ylim(bottom=0.0)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


DEFAULT_RATE_HZ = 200.0  # skeye logs without a log: EuRoC's IMU rate
DEFAULT_SECONDS = 60.0  # skeye logs without a log: the simulated hover's length


def unused_options(args: argparse.Namespace) -> None:
    """Refuse the options that would do nothing: ``--start``, ``--end``, the topics and
    ``--format`` read a log, ``--rate`` and ``--seconds`` shape the simulated hover without
    one (with a log the simulated IMU takes the log's rate and length)."""
    if args.log is None:
        given = [option for option, value in (
            ("--start", args.start), ("--end", args.end), ("--imu-topic", args.imu_topic),
            ("--truth-topic", args.truth_topic),
            ("--format", None if args.format == "auto" else args.format)) if value is not None]
        if given:
            verb = "read" if len(given) > 1 else "reads"
            raise ConfigError(f"{', '.join(given)} {verb} a log, and none was given (without "
                              "one skeye logs measures the simulated IMU alone: --rate, "
                              "--seconds)")
        return
    given = [option for option, value in (("--rate", args.rate), ("--seconds", args.seconds))
             if value is not None]
    if given:
        verb = "shape" if len(given) > 1 else "shapes"
        raise ConfigError(f"{', '.join(given)} {verb} the simulated hover without a log; with "
                          "one the simulated IMU takes the log's rate and length")


def cmd_logs(args: argparse.Namespace) -> int:
    logs: list[ImuLog] = []
    source = None if args.log is None else Path(args.log)
    # Checked before the log is read: a name that cannot be written costs no work, and the log
    # itself is never written over.
    json_out = None if args.json is None else output_file(Path(args.json), "--json", source,
                                                          "log")
    plot_out = None if args.plot is None else figure_file(Path(args.plot), "--plot", source,
                                                          "log")
    different_files(("--json", json_out), ("--plot", plot_out))
    unused_options(args)
    if args.log is not None:
        log = read_log(Path(args.log), args.format, imu_topic=args.imu_topic,
                       truth_topic=args.truth_topic)
        if args.start is not None and args.end is not None and args.start >= args.end:
            raise ConfigError(f"--start {args.start:g} s is after --end {args.end:g} s: the "
                              "window runs from --start to a later --end")
        log = log.span(args.start, args.end)
        length = float(log.t_s[-1] - log.t_s[0])
        if length < MIN_HOVER_S:  # the rest second, then a second of flight to measure
            window = "" if args.start is None and args.end is None else " from --start to --end"
            raise ConfigError(f"{log.name}: {length:g} s of IMU samples{window}; skeye logs "
                              f"needs at least {MIN_HOVER_S:g} s (the first {REST_S:g} s at "
                              "rest, then the flight)")
        sim = reference_imu(log, args.robot)
        result = compare(log, args.robot, sim)
        logs.append(log)
    else:
        rate = DEFAULT_RATE_HZ if args.rate is None else args.rate
        seconds = DEFAULT_SECONDS if args.seconds is None else args.seconds
        if not (math.isfinite(rate) and samples_above(rate, VIBRATION_FROM_HZ)
                and rate <= MAX_RATE_HZ):
            raise ConfigError(f"--rate must be over {lowest_rate_hz(VIBRATION_FROM_HZ):g} Hz (the "
                              f"vibration figure measures above {VIBRATION_FROM_HZ:g} Hz, and a "
                              "rate samples nothing above half itself) and at most "
                              f"{MAX_RATE_HZ:g}, got {rate:g}")
        if not MIN_HOVER_S <= seconds <= MAX_SIM_S:  # 1e9 s asked numpy for 1.5 TiB
            raise ConfigError(f"--seconds must be {MIN_HOVER_S:g}..{MAX_SIM_S:g} s (the first "
                              f"{REST_S:g} s at rest, then the hover; a log's simulated IMU is "
                              f"{MAX_SIM_S:g} s at most too), got {seconds:g}")
        sim = simulated_imu(rate, seconds, args.robot)
        sim_flight = in_flight(sim)
        result = {"log": "none (simulated only)", "rate_hz": rate, "seconds": seconds,
                  "real": {}, "has_truth": False,
                  "simulated": {**imu_figures(sim_flight.gyro_rad_s, sim_flight.accel_m_s2,
                                              rate),
                                **replay_tilt(sim.t_s, sim.gyro_rad_s, sim.accel_m_s2, None)}}
    logs.append(sim)  # the simulated IMU the table measured (it is simulated once)
    print(report_table(result))
    writes: list[tuple[str, Path, Callable[[Path], object]]] = []
    if json_out is not None:
        text = json.dumps(result, indent=2)
        writes.append(("--json", json_out, lambda path: path.write_text(text)))
    if plot_out is not None:
        writes.append(("--plot", plot_out, lambda path: plot(logs, path)))
    write_whole(writes)
    if plot_out is not None:
        print(f"\nspectra: {plot_out}")
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser(
        "logs", help="a real flight log's IMU against the simulated one (docs/logs.md)",
        description="Read a real flight log (EuRoC-style CSV folder, PX4 ULog, ROS bag), "
        "measure its IMU (vibration above 10 Hz, Allan deviation), replay it through the "
        "board estimator against the log's ground truth, and print the simulated IMU's "
        "figures beside it. Without a log: the simulated figures alone.")
    p.add_argument("log", nargs="?", default=None, type=cliargs.path,
                   help="the log: an EuRoC folder (mav0/), a .ulg file, a .bag or rosbag2 folder")
    p.add_argument("--format", choices=LOG_FORMATS, default="auto")
    p.add_argument("--imu-topic", default=None, help="ROS bags: the IMU topic")
    p.add_argument("--truth-topic", default=None, help="ROS bags: the ground-truth topic")
    p.add_argument("--start", type=cliargs.non_negative_float, default=None,
                   help="first second used (from the log's first IMU sample; the default: all)")
    p.add_argument("--end", type=cliargs.non_negative_float, default=None,
                   help="last second used (after --start)")
    p.add_argument("--robot", default="hummingbird", help="the robot whose IMU is simulated")
    p.add_argument("--rate", type=float, default=None,
                   help=f"without a log: the simulated IMU's rate (Hz; default "
                   f"{DEFAULT_RATE_HZ:g}, EuRoC's)")
    p.add_argument("--seconds", type=cliargs.positive_float, default=None,
                   help=f"without a log: how long the simulated hover is ({MIN_HOVER_S:g}.."
                   f"{MAX_SIM_S:g} s; default {DEFAULT_SECONDS:g})")
    p.add_argument("--plot", type=cliargs.path, default=None, metavar="PNG",
                   help="write the spectra here")
    p.add_argument("--json", type=cliargs.path, default=None, metavar="FILE",
                   help="write the figures here")
    p.set_defaults(func=cmd_logs)
