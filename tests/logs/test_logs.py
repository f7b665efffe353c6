"""``skeye logs``: reading real-log formats, IMU figures, and the board estimator's replay.

The logs are built by :mod:`tests.logs.make_logs` from published figures (no licensed real log
ships with skeye): what goes in is known, so each figure has an expected value.
"""

from __future__ import annotations

import dataclasses
import gc
import json
import math
import os
import shutil
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest

from skeye.cli import main
from skeye.errors import ConfigError
from skeye.logs.analysis import adev_at, band_rms, imu_figures
from skeye.logs.readers import ImuLog, read_log
from skeye.sim.log_replay import REST_S, axis_mean_spectrum, replay_tilt
from tests.logs import make_logs
from tests.logs.make_logs import RATE_HZ, synthetic


@pytest.fixture(scope="module")
def flight() -> make_logs.Synthetic:
    return synthetic(30.0)


def test_allan_deviation_reads_the_noise_density() -> None:
    rng = np.random.default_rng(3)
    density = 2.0e-3
    x = density * math.sqrt(RATE_HZ / 2.0) * rng.standard_normal(int(600 * RATE_HZ))
    # white noise of density N (one-sided, per sqrt(Hz)): ADEV(tau) = N / sqrt(2 tau)
    assert adev_at(x, RATE_HZ, 1.0) == pytest.approx(density / math.sqrt(2.0), rel=0.1)
    assert adev_at(x, RATE_HZ, 4.0) == pytest.approx(density / math.sqrt(8.0), rel=0.15)


def test_the_synthetic_log_has_the_white_noise_of_euroc_s_sensor_file() -> None:
    # EuRoC's sensor.yaml gives Kalibr's continuous-time noise densities (two-sided): a sample
    # at rate f carries sigma_d = density * sqrt(f) (Kalibr wiki, "IMU Noise Model"), and the
    # Allan deviation at 1 s reads the density itself. At rest (the first 2 s) the log is that
    # noise alone around the true gyro (0) and specific force (0, 0, -g): 400 samples per axis,
    # 3 axes pooled, so the sample sigma's relative standard error is 1 / sqrt(2 x 1200).
    s = make_logs.synthetic(10.0, seed=5)
    rest = s.t_s < make_logs.REST_S
    tol = 4.0 / math.sqrt(2.0 * 3 * int(rest.sum()))
    for data, density in ((s.gyro, make_logs.GYRO_DENSITY), (s.accel, make_logs.ACCEL_DENSITY)):
        noise = data[rest] - data[rest].mean(axis=0)
        sigma = float(np.sqrt(np.mean(noise ** 2)))
        assert sigma == pytest.approx(density * math.sqrt(RATE_HZ), rel=tol)


def test_band_rms_counts_what_lies_above_the_cut() -> None:
    t = np.arange(int(20 * RATE_HZ)) / RATE_HZ
    low = 2.0 * np.sin(2 * np.pi * 3.0 * t)  # below 10 Hz: not counted
    high = 0.5 * np.sin(2 * np.pi * 60.0 * t)  # RMS 0.354
    assert band_rms(low + high, RATE_HZ, 10.0) == pytest.approx(0.5 / math.sqrt(2), rel=0.05)


@pytest.mark.parametrize("fmt", ["euroc", "ulog", "rosbag"])
def test_each_format_reads_back_what_was_logged(fmt: str, flight: make_logs.Synthetic,
                                               tmp_path: Path) -> None:
    writer = {"euroc": lambda: make_logs.write_euroc(tmp_path / "MH_xx", flight),
              "ulog": lambda: make_logs.write_ulog(tmp_path / "flight.ulg", flight),
              "rosbag": lambda: make_logs.write_rosbag(tmp_path / "flight.bag", flight)}[fmt]
    log = read_log(writer())
    assert log.rate_hz == pytest.approx(RATE_HZ, rel=1e-3)
    assert log.t_s[0] == 0.0 and len(log.t_s) == len(flight.t_s)
    assert np.allclose(log.gyro_rad_s, flight.gyro, atol=1e-5)
    assert np.allclose(log.accel_m_s2, flight.accel, atol=1e-4)
    assert log.truth is not None and log.truth.world_z == ("down" if fmt == "ulog" else "up")
    # the figures of what was put in: the vibration's level above 10 Hz (issue 33's hover
    # figures), within the broadband's 5 % below 10 Hz and the estimate's spread
    hover = log.span(make_logs.REST_S, None)
    figures = imu_figures(hover.gyro_rad_s, hover.accel_m_s2, log.rate_hz)
    assert figures["accel_band_rms"] == pytest.approx(make_logs.VIB_ACCEL, rel=0.08)
    assert figures["gyro_band_rms"] == pytest.approx(make_logs.VIB_GYRO, rel=0.08)
    # the board estimator on the log, against its truth: a MEMS AHRS's accuracy class
    replay = replay_tilt(log.t_s, log.gyro_rad_s, log.accel_m_s2, log.truth)
    assert replay["tilt_samples"] > 400
    assert replay["tilt_rms_deg"] < 1.0, replay


def test_the_replay_is_judged_against_the_log_truth(flight: make_logs.Synthetic,
                                                   tmp_path: Path) -> None:
    log = read_log(make_logs.write_euroc(tmp_path / "MH_xx", flight))
    assert log.truth is not None
    # the truth tilted 10 degrees about x: the replay's error says so
    c, s = math.cos(math.radians(5.0)), math.sin(math.radians(5.0))
    tilt = np.array([c, s, 0.0, 0.0])  # w x y z, 10 deg about x
    w1, x1, y1, z1 = log.truth.quat_wxyz.T
    w2, x2, _, _ = tilt
    quat = np.column_stack([w1 * w2 - x1 * x2, w1 * x2 + x1 * w2, y1 * w2 + z1 * x2,
                            z1 * w2 - y1 * x2])
    wrong = dataclasses.replace(log.truth, quat_wxyz=quat)
    replay = replay_tilt(log.t_s, log.gyro_rad_s, log.accel_m_s2, wrong)
    assert replay["tilt_rms_deg"] == pytest.approx(10.0, abs=1.5)


def test_a_damaged_ulog_leaves_no_file_open(tmp_path: Path) -> None:
    """pyulog, given a file name, does not close the file when its parse fails (Python closes
    it later, warning "unclosed file"); the reader opens and closes the file itself."""
    (tmp_path / "junk.ulg").write_bytes(b"not a ulog at all")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ResourceWarning)
        with pytest.raises(ConfigError, match=r"junk\.ulg"):
            read_log(tmp_path / "junk.ulg")
        gc.collect()
    assert not [w for w in caught if issubclass(w.category, ResourceWarning)], caught


def test_the_plotted_spectra_leave_out_the_windows_rest_second_as_the_table_does() -> None:
    """With --start the table measures from a second after the window's start; the plot used to
    leave out the first second of the log's own clock instead (so nothing, after a --start)."""
    rate = 200.0
    t = np.arange(0.0, 12.0, 1.0 / rate)
    accel = np.tile([0.0, 0.0, -9.81], (len(t), 1))
    start_s = 5.0
    rest = (t >= start_s) & (t < start_s + REST_S)  # the window's rest second: a 40 Hz buzz
    accel[rest, 0] += 3.0 * np.sin(2 * np.pi * 40.0 * t[rest])
    log = ImuLog("buzz", t, np.zeros((len(t), 3)), accel).span(start_s, None)
    freqs, power = axis_mean_spectrum(log, "accel_m_s2")
    assert float(power[np.argmin(abs(freqs - 40.0))]) < 1e-12


def test_bad_logs_are_named(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no such file"):
        read_log(tmp_path / "missing.ulg")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ConfigError, match=r"imu0/data\.csv"):
        read_log(tmp_path / "empty")
    (tmp_path / "junk.ulg").write_bytes(b"not a ulog at all")
    with pytest.raises(ConfigError, match=r"junk\.ulg"):
        read_log(tmp_path / "junk.ulg")
    with pytest.raises(ConfigError, match="log format"):
        read_log(tmp_path / "junk.ulg", "parquet")


def test_the_command_prints_real_and_simulated_side_by_side(
        flight: make_logs.Synthetic, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = make_logs.write_euroc(tmp_path / "MH_xx", flight)
    assert main(["logs", str(folder), "--json", str(tmp_path / "f.json"),
                 "--plot", str(tmp_path / "f.png")]) == 0
    out = capsys.readouterr().out
    assert "| accelerometer vibration above 10 Hz (m/s^2) |" in out
    assert (tmp_path / "f.png").stat().st_size > 10_000

    result = json.loads((tmp_path / "f.json").read_text())
    sim = result["simulated"]
    # the simulated Hummingbird's IMU at the log's rate carries its stated vibration
    assert 0.8 < sim["accel_band_rms"] < 1.3 and 0.05 < sim["gyro_band_rms"] < 0.08
    assert main(["logs", str(tmp_path / "nothing")]) == 2


def test_a_log_without_ground_truth_gets_no_tilt_error(
        flight: make_logs.Synthetic, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A real vehicle's log has no truth: its replay has nothing to be judged against (a level
    # vehicle is the simulated hover's truth, not a flying one's), so its column shows none.
    folder = make_logs.write_euroc(tmp_path / "MH_nt", flight)
    shutil.rmtree(folder / "mav0" / "state_groundtruth_estimate0")
    assert main(["logs", str(folder), "--json", str(tmp_path / "f.json")]) == 0
    out = capsys.readouterr().out
    assert "| board estimator tilt error, RMS (deg) | - |" in out
    assert "The log has no ground truth: no tilt error for it." in out
    result = json.loads((tmp_path / "f.json").read_text())
    assert "tilt_rms_deg" not in result["real"] and "tilt_rms_deg" in result["simulated"]


@pytest.mark.parametrize("how", ["later", "one instant"])
def test_a_ground_truth_that_meets_none_of_the_replays_instants_is_said_so(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], how: str) -> None:
    # A truth stamped on another clock (1000 s later) or whose stamps all repeat one instant
    # left the tilt-error cells "-" without a word: the table read as if the replay had run.
    folder = make_logs.write_euroc(tmp_path / "MH_off", synthetic(4.0))
    gt = folder / "mav0" / "state_groundtruth_estimate0" / "data.csv"
    head, *rows = gt.read_text().splitlines()
    first = int(rows[0].split(",")[0])
    stamp = (lambda t: t + 1000 * 10**9) if how == "later" else (lambda t: first)
    gt.write_text("\n".join([head] + [f"{stamp(int(r.split(',')[0]))},{r.split(',', 1)[1]}"
                                      for r in rows]) + "\n")
    assert main(["logs", str(folder), "--json", str(tmp_path / "f.json")]) == 0
    out = capsys.readouterr().out
    assert "| board estimator tilt error, RMS (deg) | - |" in out
    span = "1000.000..1003.990" if how == "later" else "0.000..0.000"
    note = (f"The log's ground truth (400 poses, {span} s from the first IMU sample) is within "
            "0.1 s of none of the instants the replay judges (1.000..3.995 s): no tilt error "
            "for it.")
    assert note in out, out
    assert json.loads((tmp_path / "f.json").read_text())["truth_unused"] == note


def test_a_euroc_file_cut_mid_line_is_refused_naming_the_line(tmp_path: Path) -> None:
    # A copy cut short: numpy's "setting an array element with a sequence. The requested array
    # has an inhomogeneous shape after 1 dimensions..." named neither line nor cause; a file
    # of comments only was "expected 7 columns".
    folder = make_logs.write_euroc(tmp_path / "MH_cut", synthetic(4.0))
    imu = folder / "mav0" / "imu0" / "data.csv"
    text = imu.read_text()
    imu.write_text(text[:-30])
    with pytest.raises(ConfigError, match=r"imu0/data\.csv: line 801 has [1-6] fields where "
                                          r"line 2 has 7 \(a file cut short\?\)"):
        read_log(folder)
    imu.write_text(text.splitlines()[0] + "\n")
    with pytest.raises(ConfigError, match=r"imu0/data\.csv: no IMU samples"):
        read_log(folder)


def test_the_simulated_only_table_speaks_of_no_log(capsys: pytest.CaptureFixture[str]) -> None:
    # docs/logs.md's `skeye logs --rate 200 --seconds 60`: without a log there is no log to
    # lack ground truth, so the note about one must not be printed.
    assert main(["logs", "--rate", "200", "--seconds", "3"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("Log: none (simulated only)")
    assert "| board estimator tilt error, RMS (deg) | - |" in out
    assert "ground truth" not in out


def test_a_named_truth_topic_missing_from_the_bag_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # As --imu-topic is: a topic the user named is wanted, so its absence is a bad option,
    # not "the log has no ground truth".
    bag = make_logs.write_rosbag(tmp_path / "flight.bag", synthetic(5.0))
    assert main(["logs", str(bag), "--truth-topic", "/nosuch"]) == 2
    err = capsys.readouterr().err
    assert "--truth-topic" in err and "'/nosuch'" in err and "Traceback" not in err


def test_a_ulog_imu_topic_without_its_fields_is_refused_naming_them(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # sensor_combined with other field names (gyro, not gyro_rad) raised KeyError 'gyro_rad[0]'
    path = make_logs.write_ulog(tmp_path / "renamed.ulg", synthetic(3.0),
                                "uint64_t timestamp;float[3] gyro;float[3] accelerometer_m_s2")
    with pytest.raises(ConfigError, match=r"renamed\.ulg: the sensor_combined topic has no "
                       r"field gyro_rad\[0\], gyro_rad\[1\], gyro_rad\[2\]"):
        read_log(path)
    assert main(["logs", str(path)]) == 2
    assert "Traceback" not in capsys.readouterr().err


@pytest.mark.parametrize(("option", "topic", "holds"), [
    ("--imu-topic", "/vicon", "geometry_msgs/msg/TransformStamped"),
    ("--truth-topic", "/imu0", "sensor_msgs/msg/Imu"),
])
def test_a_named_topic_of_the_wrong_message_type_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], option: str, topic: str,
        holds: str) -> None:
    # --imu-topic /vicon read as "not a readable ROS bag: ... no attribute 'angular_velocity'";
    # --truth-topic /imu0 read every IMU message twice: "IMU times do not increase"
    bag = make_logs.write_rosbag(tmp_path / "flight.bag", synthetic(3.0))
    assert main(["logs", str(bag), option, topic]) == 2
    err = capsys.readouterr().err
    assert f"{option} {topic!r} holds {holds}, not " in err and "Traceback" not in err


def _bad_truth(rows: list[str], how: str) -> list[str]:
    head, body = rows[:1], rows[1:]
    if how == "zero quaternion":
        cells = body[100].split(",")
        body[100] = ",".join([*cells[:4], "0", "0", "0", "0"])
    elif how == "not a number":
        body[100] = body[100].replace(body[100].split(",")[2], "nan", 1)
    elif how == "backwards":
        body[100], body[300] = body[300], body[100]
    else:  # a column short
        body = [",".join(r.split(",")[:7]) for r in body]
    return head + body


@pytest.mark.parametrize(("how", "message"), [
    ("zero quaternion", "ground-truth quaternions of zero length"),
    ("not a number", "ground truth that is not numbers"),
    ("backwards", "ground-truth times go backwards"),
    ("a column short", r"data\.csv: expected 8 columns"),
])
def test_ground_truth_the_replay_cannot_judge_by_is_refused(
        tmp_path: Path, how: str, message: str) -> None:
    # A zero quaternion or a NaN printed a tilt error of "nan"; times out of order matched the
    # wrong instants; a truth file a column short was dropped: "the log has no ground truth".
    folder = make_logs.write_euroc(tmp_path / "MH_bt", synthetic(4.0))
    gt = folder / "mav0" / "state_groundtruth_estimate0" / "data.csv"
    gt.write_text("\n".join(_bad_truth(gt.read_text().splitlines(), how)) + "\n")
    with pytest.raises(ConfigError, match=message):
        read_log(folder)


@pytest.mark.parametrize("end", ["1.0", "1.02", "1.9"])
def test_a_log_window_shorter_than_the_rest_and_a_second_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], end: str) -> None:
    # 1.0 s read "no IMU samples between 1 and 1 s"; 1.02 s gave "figures" from four samples
    folder = make_logs.write_euroc(tmp_path / "MH_sh", synthetic(4.0))
    assert main(["logs", str(folder), "--start", "0", "--end", end]) == 2
    err = capsys.readouterr().err
    assert "s of IMU samples from --start to --end; skeye logs needs at least 2 s" in err


def test_a_log_whose_first_second_reads_no_gravity_is_refused(
        flight: make_logs.Synthetic) -> None:
    # an accelerometer reading zero at rest turned into a tilt error of "nan"
    accel = flight.accel.copy()
    accel[:] = 0.0
    with pytest.raises(ConfigError, match="reads a specific force of 0 m/s\\^2, not gravity"):
        replay_tilt(flight.t_s, flight.gyro, accel, None)


def test_the_files_written_are_checked_before_the_log_is_read(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # --plot spectra.txt ended in matplotlib's ValueError traceback once the work was done (the
    # --json file already written); --plot spectra wrote spectra.png and said "spectra:
    # spectra"; --json flight.ulg wrote the figures over the log. skeye plot's --out is checked
    # the same way.
    log = make_logs.write_ulog(tmp_path / "flight.ulg", synthetic(3.0))
    data = log.read_bytes()
    figures = tmp_path / "f.json"
    for option, value, message in (
            ("--plot", tmp_path / "spectra.txt", "cannot write .txt files; the formats are"),
            ("--plot", tmp_path, "is a directory"),
            ("--json", log, f"is the log {log} itself")):
        assert main(["logs", str(log), "--json", str(figures), option, str(value)]) == 2
        err = capsys.readouterr().err
        assert f"skeye logs: error: {option} {value}" in err and message in err
        assert "Traceback" not in err and not figures.exists()
    assert log.read_bytes() == data
    # A file inside a log that is a folder (EuRoC, ROS 2), a folder that does not exist, and
    # --json and --plot naming one file: each refused before the work.
    euroc = make_logs.write_euroc(tmp_path / "MH_out", synthetic(3.0))
    imu_csv = euroc / "mav0" / "imu0" / "data.csv"
    kept = imu_csv.read_bytes()
    nowhere = tmp_path / "no-such-folder" / "f.json"
    for args, message in (
            ([str(euroc), "--json", str(imu_csv)], f"is inside the log {euroc}"),
            (["--seconds", "3", "--json", str(nowhere)],
             f"--json {nowhere}: no folder {nowhere.parent} to write it in"),
            (["--seconds", "3", "--json", str(tmp_path / "x.png"), "--plot",
              str(tmp_path / "x.png")], "--json and --plot both name")):
        assert main(["logs", *args]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, err
    assert imu_csv.read_bytes() == kept
    assert main(["logs", "--seconds", "3", "--plot", str(tmp_path / "spectra")]) == 0
    assert capsys.readouterr().out.endswith(f"spectra: {tmp_path / 'spectra.png'}\n")
    assert (tmp_path / "spectra.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("with_log", [True, False])
def test_the_simulated_imu_is_simulated_once(
        with_log: bool, flight: make_logs.Synthetic, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """The table and the plotted spectra measure one simulated IMU (it was simulated again for
    the plot, and also when no plot was asked for)."""
    from skeye.sim import log_replay

    made: list[ImuLog] = []
    simulate = log_replay.simulated_imu

    def counted(*args: object, **kwargs: object) -> ImuLog:
        made.append(simulate(*args, **kwargs))  # type: ignore[arg-type]
        return made[-1]

    monkeypatch.setattr(log_replay, "simulated_imu", counted)
    source = ([str(make_logs.write_euroc(tmp_path / "MH_once", flight))] if with_log
              else ["--rate", "200", "--seconds", "3"])
    assert main(["logs", *source]) == 0
    assert main(["logs", *source, "--plot", str(tmp_path / "s.png")]) == 0
    assert len(made) == 2  # one per command
    capsys.readouterr()


def test_options_that_would_do_nothing_are_refused(
        flight: make_logs.Synthetic, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--start``, ``--end``, the topics and ``--format`` read a log, ``--rate`` and
    ``--seconds`` shape the simulated hover without one: given where they do nothing, they
    were accepted and ignored (``skeye logs --start 60 --end 180`` measured the whole simulated
    hover, as if windowed); each is now refused before the work, naming itself."""
    euroc = str(make_logs.write_euroc(tmp_path / "MH_opts", flight))
    for args, named in (
            (["--start", "10"], "--start reads"),
            (["--end", "5", "--imu-topic", "/imu0"], "--end, --imu-topic read"),
            (["--truth-topic", "/pose", "--format", "euroc"], "--truth-topic, --format read"),
            ([euroc, "--rate", "100"], "--rate shapes"),
            ([euroc, "--seconds", "30", "--rate", "200"], "--rate, --seconds shape"),
            ([euroc, "--imu-topic", "/imu0"], "--imu-topic")):
        assert main(["logs", *args]) == 2, args
        err = capsys.readouterr().err
        assert err.startswith(f"skeye logs: error: {named} "), err
        assert err.count("\n") == 1, err


def _cut(s: make_logs.Synthetic, keep: np.ndarray) -> make_logs.Synthetic:
    return make_logs.Synthetic(s.t_s[keep], s.gyro[keep], s.accel[keep], s.quat_ned[keep],
                               s.pos_ned[keep])


def test_a_gap_in_the_imu_samples_is_refused_naming_it(
        flight: make_logs.Synthetic, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # 3 s without IMU samples (a logger's dropout) was measured as if the samples ran on: the
    # replay integrated the gyro over the 3 s at once and read 6.6 deg RMS (22 deg at most)
    # where the unbroken log reads under 1 deg, with exit status 0
    gap = (flight.t_s > 10.0) & (flight.t_s < 13.0)
    folder = make_logs.write_euroc(tmp_path / "MH_gap", _cut(flight, ~gap))
    assert main(["logs", str(folder)]) == 2
    err = capsys.readouterr().err.strip()
    assert "no IMU sample for 3 s after 10 s" in err and "--start/--end" in err, err
    assert len(err.splitlines()) == 1, err
    # a window without the gap is measured
    assert main(["logs", str(folder), "--end", "10"]) == 0
    # a single dropped sample is no gap
    folder = make_logs.write_euroc(tmp_path / "MH_drop", _cut(flight, np.arange(len(
        flight.t_s)) != 1500))
    assert main(["logs", str(folder)]) == 0


def test_a_ulog_topic_logged_twice_is_read_from_its_first_instance(
        flight: make_logs.Synthetic, tmp_path: Path) -> None:
    """A ULog topic with two instances (multi_id 0 and 1) was read from the last one parsed;
    pyulog's get_dataset takes instance 0, the primary, by default."""
    def msg(kind: bytes, payload: bytes) -> bytes:
        return struct.pack("<HB", len(payload), kind[0]) + payload

    fields = "uint64_t timestamp;float[3] gyro_rad;float[3] accelerometer_m_s2"
    out = bytearray(b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0)) + msg(b"B", bytes(40))
    out += msg(b"F", f"sensor_combined:{fields};".encode())
    for msg_id in (0, 1):  # msg_id k subscribes instance k
        out += msg(b"A", struct.pack("<BH", msg_id, msg_id) + b"sensor_combined")
    level = np.tile([0.0, 0.0, -9.81], (len(flight.t_s), 1))
    for k in range(len(flight.t_s)):
        stamp = round(float(flight.t_s[k]) * 1e6) + 1_000_000
        out += msg(b"D", struct.pack("<HQ6f", 0, stamp, *flight.gyro[k], *flight.accel[k]))
        out += msg(b"D", struct.pack("<HQ6f", 1, stamp, 0.0, 0.0, 0.0, *level[k]))
    (tmp_path / "two.ulg").write_bytes(bytes(out))
    log = read_log(tmp_path / "two.ulg")
    assert np.allclose(log.gyro_rad_s, flight.gyro, atol=1e-5)
    assert np.allclose(log.accel_m_s2, flight.accel, atol=1e-4)


def test_a_reversed_or_not_numeric_window_is_refused_naming_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # these read "no IMU samples between 20 and 10 s" and "between nan and 3.995 s"
    folder = make_logs.write_euroc(tmp_path / "MH_w", synthetic(4.0))
    assert main(["logs", str(folder), "--start", "3", "--end", "1"]) == 2
    assert "--start 3 s is after --end 1 s" in capsys.readouterr().err
    for option, value, message in (("--start", "nan", "must be a finite number, got 'nan'"),
                                   ("--end", "-1", "must be a number >= 0, got '-1'")):
        with pytest.raises(SystemExit) as refused:  # argparse's refusal
            main(["logs", str(folder), option, value])
        assert refused.value.code == 2
        assert f"argument {option}: {message}" in capsys.readouterr().err


def test_imu_times_that_do_not_increase_are_refused_naming_where(
        flight: make_logs.Synthetic, tmp_path: Path) -> None:
    # "IMU times do not increase" said nothing of where, in a log of tens of thousands of lines
    t = flight.t_s.copy()
    t[1000:1010] -= 0.2  # sample 1000 (5 s) is stamped 4.8 s
    s = dataclasses.replace(flight, t_s=t)
    with pytest.raises(ConfigError, match=r"IMU times do not increase: sample 1000 at 4\.8 s "
                       r"follows one at 4\.995 s"):
        read_log(make_logs.write_euroc(tmp_path / "MH_back", s))


def test_the_simulated_hover_figures_quoted_in_physics_md_come_out(
        tmp_path: Path) -> None:
    """docs/physics.md quotes `skeye logs --rate 200 --seconds 60` (seed 1, so the same every
    run): the vibration above 10 Hz and the replay's tilt error, each to the digits quoted."""
    import re

    text = " ".join((Path(__file__).parents[2] / "docs" / "physics.md").read_text().split())
    vib = re.search(r"Simulated, this part \(seed 1\) carries ([0-9.]+) m/s\^2 and ([0-9.]+) "
                    r"rad/s above 10 Hz", text)
    tilt = re.search(r"its tilt error, level truth, is ([0-9.]+) deg RMS and ([0-9.]+) deg at "
                     r"most", text)
    assert vib and tilt
    assert main(["logs", "--rate", "200", "--seconds", "60",
                 "--json", str(tmp_path / "f.json")]) == 0
    sim = json.loads((tmp_path / "f.json").read_text())["simulated"]
    for quoted, key in ((vib[1], "accel_band_rms"), (vib[2], "gyro_band_rms"),
                        (tilt[1], "tilt_rms_deg"), (tilt[2], "tilt_max_deg")):
        digits = len(quoted.split(".")[1])
        assert f"{sim[key]:.{digits}f}" == quoted, (key, sim[key], quoted)


def test_a_window_that_does_not_start_at_rest_is_refused_when_replayed(
        flight: make_logs.Synthetic, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # --start 10 (mid-flight, swaying 8 deg at 0.2 Hz) calibrated the board's gyro on a second
    # of turning and read 5.5 deg RMS against the truth where the log reads 0.5, exit status 0
    folder = make_logs.write_euroc(tmp_path / "MH_mid", flight)
    assert main(["logs", str(folder), "--start", "10"]) == 2
    err = capsys.readouterr().err
    assert "is not at rest: its ground truth turns" in err and "--start" in err, err
    assert main(["logs", str(folder), "--start", "0.5"]) == 0  # still on the ground: measured
    # without a truth there is no replay to spoil: the IMU figures are measured
    shutil.rmtree(folder / "mav0" / "state_groundtruth_estimate0")
    assert main(["logs", str(folder), "--start", "10"]) == 0


@pytest.mark.parametrize("seconds", ["1e9", "121"])
def test_a_simulated_hover_longer_than_a_logs_is_refused(
        capsys: pytest.CaptureFixture[str], seconds: str) -> None:
    # --seconds 1e9 ended in numpy's MemoryError traceback ("Unable to allocate 1.46 TiB"), and
    # a day's worth ran for days: the simulated hover is at most the 120 s a log's is
    assert main(["logs", "--seconds", seconds]) == 2
    err = capsys.readouterr().err
    assert err == ("skeye logs: error: --seconds must be 2..120 s (the first 1 s at rest, then "
                   "the hover; a log's simulated IMU is 120 s at most too), got "
                   f"{float(seconds):g}\n")


def test_a_ulog_cut_short_or_damaged_is_said_so_on_stderr_not_in_the_table(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        caplog: pytest.LogCaptureFixture) -> None:
    # pyulog prints what it finds damaged on stdout: "File corruption detected while reading
    # file definitions!" went into the table's output (skeye logs x.ulg > table.md), and the
    # error under it read "no sensor_combined topic", as if the log had never held one
    data = make_logs.write_ulog(tmp_path / "whole.ulg", synthetic(6.0)).read_bytes()
    (tmp_path / "cut.ulg").write_bytes(data[:30])  # inside the flag bits, before the formats
    assert main(["logs", str(tmp_path / "cut.ulg")]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.startswith(f"skeye logs: error: {tmp_path / 'cut.ulg'}: not a readable ULog "
                          "file: damaged or cut short before any sensor_combined sample "
                          "(pyulog: "), err
    assert err.count("\n") == 1, err
    (tmp_path / "nodata.ulg").write_bytes(data[:400])  # formats and subscriptions, no data
    assert main(["logs", str(tmp_path / "nodata.ulg")]) == 2
    assert capsys.readouterr().err.endswith(
        "the sensor_combined topic (the IMU) has no samples (a log cut short?)\n")
    # one IMU message three quarters through names a topic the log never subscribed: pyulog
    # skips it (one sample lost, no gap) and printed "no subscription found" into the table
    imu_header = struct.pack("<HBH", 34, ord("D"), 0)  # sensor_combined's data messages
    at = data.index(imu_header, len(data) * 3 // 4)
    damaged = data[:at + 3] + struct.pack("<H", 0x7777) + data[at + 5:]
    (tmp_path / "damaged.ulg").write_bytes(damaged)
    assert main(["logs", str(tmp_path / "damaged.ulg")]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"Log: {tmp_path / 'damaged.ulg'} ("), out
    assert "corrupt" not in out, out
    assert any("the ULog file is damaged" in r.getMessage() for r in caplog.records)



def test_a_whole_ulog_pyulog_only_remarks_on_is_not_called_damaged(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        caplog: pytest.LogCaptureFixture) -> None:
    # pyulog prints notes on a whole file too: a newer format version ("Warning: unknown file
    # version. Will attempt to read it anyway") was warned of as a damaged file, pyulog having
    # "skipped what it could not read", where it skipped nothing
    data = bytearray(make_logs.write_ulog(tmp_path / "whole.ulg", synthetic(6.0)).read_bytes())
    data[7] = 2  # the file format's version
    (tmp_path / "v2.ulg").write_bytes(bytes(data))
    assert main(["logs", str(tmp_path / "v2.ulg")]) == 0
    assert capsys.readouterr().out.startswith(f"Log: {tmp_path / 'v2.ulg'} (")
    said = [r.getMessage() for r in caplog.records if r.name == "skeye.logs.readers"]
    assert said == [f"{tmp_path / 'v2.ulg'}: pyulog: Warning: unknown file version. Will "
                    "attempt to read it anyway"], said

def test_a_log_sampled_too_slowly_for_the_vibration_figure_gets_none(
        flight: make_logs.Synthetic, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # a 20 Hz log (a PX4 logger's slow profile) samples nothing above 10 Hz: the table read a
    # vibration of 0.027 m/s^2 "above 10 Hz" from the one spectral bin at Nyquist (8 Hz: 0),
    # and --rate 10 read 0 for the simulated IMU
    slow = _cut(flight, np.arange(0, len(flight.t_s), 10))
    folder = make_logs.write_euroc(tmp_path / "MH_20hz", slow)
    assert main(["logs", str(folder), "--json", str(tmp_path / "f.json")]) == 0
    out = capsys.readouterr().out
    assert "| accelerometer vibration above 10 Hz (m/s^2) | - | - | 0.9-1.3 |" in out, out
    assert "| gyro vibration above 10 Hz (rad/s) | - | - | 0.06-0.07 |" in out, out
    assert ("The log samples at 20 Hz: nothing above 10 Hz is sampled (its Nyquist frequency "
            "is 10 Hz), so no vibration figure.") in out, out
    result = json.loads((tmp_path / "f.json").read_text())
    assert "accel_band_rms" not in result["real"] and "gyro_band_rms" not in result["simulated"]
    assert result["real"]["tilt_rms_deg"] > 0.0  # the rest is measured
    for rate in ("10", "20.1"):
        assert main(["logs", "--rate", rate]) == 2
        assert capsys.readouterr().err.startswith(
            "skeye logs: error: --rate must be over 20.2 Hz (the vibration figure measures above "
            f"10 Hz, and a rate samples nothing above half itself) and at most 10000, got {rate}")


def test_an_empty_topic_name_is_refused_not_taken_as_none(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # --imu-topic "" (an unset shell variable: --imu-topic "$IMU") read the bag's first IMU
    # topic, and --truth-topic "" its first pose, as if neither had been given
    bag = make_logs.write_rosbag(tmp_path / "flight.bag", synthetic(3.0))
    for option, message in (("--imu-topic", "no IMU topic ''"),
                            ("--truth-topic", "no ground-truth topic '' (--truth-topic)")):
        assert main(["logs", str(bag), option, ""]) == 2
        assert capsys.readouterr().err.startswith(f"skeye logs: error: {bag}: {message}")


def test_a_euroc_field_that_is_no_number_is_refused_naming_its_line(tmp_path: Path) -> None:
    # "could not convert string to float: 'abc0.13'" named no line of the thousands; a header
    # written without its "#" (timestamp,w_RS_S_x,...) is line 1
    folder = make_logs.write_euroc(tmp_path / "MH_txt", synthetic(3.0))
    imu = folder / "mav0" / "imu0" / "data.csv"
    lines = imu.read_text().splitlines()
    lines[499] = lines[499].replace(",", ",abc", 1)
    imu.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError, match=r"imu0/data\.csv: line 500 is not numbers: could not "
                                          r"convert string to float: 'abc"):
        read_log(folder)
    imu.write_text("\n".join([lines[0].lstrip("#"), *lines[1:499]]) + "\n")
    with pytest.raises(ConfigError, match=r"imu0/data\.csv: line 1 is not numbers"):
        read_log(folder)


def test_imu_samples_that_are_not_numbers_are_refused_naming_the_first(
        flight: make_logs.Synthetic, tmp_path: Path) -> None:
    # "IMU samples that are not numbers" said nothing of where, in a log of thousands
    gyro = flight.gyro.copy()
    gyro[1200, 1] = np.nan
    gyro[1500, 0] = np.inf
    with pytest.raises(ConfigError, match=r"IMU samples that are not numbers: sample 1200 at 6 s "
                                          r"reads nan in the gyro's y \(2 such samples\)"):
        read_log(make_logs.write_ulog(tmp_path / "nan.ulg",
                                      dataclasses.replace(flight, gyro=gyro)))


@pytest.mark.parametrize("row", [499, -1])
def test_imu_times_that_are_not_numbers_are_refused_naming_the_first(
        tmp_path: Path, row: int) -> None:
    # a EuRoC stamp of "nan" passed the order check (no comparison with NaN holds): mid-log the
    # figures came out of a log with a NaN time in it; last, "no IMU samples between 0 and nan s"
    folder = make_logs.write_euroc(tmp_path / "MH_tnan", synthetic(3.0))
    imu = folder / "mav0" / "imu0" / "data.csv"
    lines = imu.read_text().splitlines()
    lines[row] = "nan" + lines[row][lines[row].index(","):]
    imu.write_text("\n".join(lines) + "\n")
    k = (len(lines) - 2) if row == -1 else row - 1  # sample numbers count from 0, after a header
    with pytest.raises(ConfigError, match=rf"IMU times that are not numbers: sample {k} is "
                                          r"stamped nan \(1 such samples\)"):
        read_log(folder)


def test_a_figure_that_cannot_be_written_leaves_no_output_behind(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    # the --json file was written, then the --plot failed (a full disk; a folder that takes no
    # new file), exit 2 with half the outputs there and an OSError naming no option. The disk
    # fills mid-plot here: /proc, which refused the file only to a root user (to any other its
    # folder is refused as not writable, before anything is written), made the test root's only
    from skeye.sim import log_replay

    def disk_full(logs: object, path: Path) -> None:
        path.write_bytes(b"\x89PNG half a figure")
        raise OSError(28, "No space left on device")

    folder = make_logs.write_euroc(tmp_path / "MH_out", synthetic(3.0))
    figures = tmp_path / "f.json"
    with monkeypatch.context() as patched:
        patched.setattr(log_replay, "plot", disk_full)
        assert main(["logs", str(folder), "--json", str(figures), "--plot",
                     str(tmp_path / "s.png")]) == 2
    err = capsys.readouterr().err
    assert err == (f"skeye logs: error: --plot {tmp_path / 's.png'}: cannot write it: No space "
                   "left on device\n"), err
    assert not figures.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["MH_out"]  # no partial file either
    assert main(["logs", str(folder), "--json", str(figures), "--plot",
                 str(tmp_path / "s.png")]) == 0
    assert json.loads(figures.read_text())["log"] == str(folder)
    assert (tmp_path / "s.png").stat().st_size > 10_000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["MH_out", "f.json", "s.png"]


def test_a_figure_written_to_a_symbolic_link_is_written_through_it(tmp_path: Path) -> None:
    # the partial file was renamed over the link itself: the link became a plain file and the
    # file it named (results/latest.json -> a run's own) kept the old figures
    folder = make_logs.write_euroc(tmp_path / "MH_link", synthetic(3.0))
    (tmp_path / "runs").mkdir()
    run = tmp_path / "runs" / "run1.json"
    run.write_text("{}")
    latest = tmp_path / "latest.json"
    latest.symlink_to(run)
    assert main(["logs", str(folder), "--json", str(latest)]) == 0
    assert latest.is_symlink() and latest.resolve() == run.resolve()
    assert json.loads(run.read_text())["log"] == str(folder)
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == ["run1.json"]


def test_a_figure_whose_rename_fails_leaves_the_other_not_written(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    # both written, the --json renamed into place, then the --plot's rename refused (a file in a
    # sticky folder that another user owns): the --json was left, where the docs say neither
    folder = make_logs.write_euroc(tmp_path / "MH_rename", synthetic(3.0))
    replace = os.replace

    def refuse_png(src: str | Path, dst: str | Path) -> None:
        if str(dst).endswith(".png"):
            raise PermissionError(1, "Operation not permitted")
        replace(src, dst)

    monkeypatch.setattr(os, "replace", refuse_png)
    figures = tmp_path / "f.json"
    assert main(["logs", str(folder), "--json", str(figures), "--plot",
                 str(tmp_path / "s.png")]) == 2
    assert capsys.readouterr().err == (f"skeye logs: error: --plot {tmp_path / 's.png'}: cannot "
                                       "write it: Operation not permitted\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["MH_rename"]


def test_imu_stamps_in_bursts_are_refused_not_simulated_at_their_median_rate(
        flight: make_logs.Synthetic, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A FIFO's samples stamped as they are read: three at a time, 10 us apart, every 15 ms. The
    # median interval read a rate of 100 kHz, and the simulated IMU beside the log was sampled
    # at it (exit 0, after 30 s for these 3 s; 1 us apart, a minute a second of log; 1 ns apart,
    # out of memory), with no word.
    k = np.arange(int(3.0 * RATE_HZ))
    burst = dataclasses.replace(_cut(flight, k), t_s=(k // 3) * 0.015 + (k % 3) * 1e-5)
    folder = make_logs.write_euroc(tmp_path / "MH_burst", burst)
    assert main(["logs", str(folder)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"skeye logs: error: {folder}: the IMU samples every ") and (
        "over the 10000 Hz the simulated IMU is sampled at most; its 600 samples over 2.99 s "
        "are 201 Hz on average") in err, err
    assert len(err.splitlines()) == 1, err


@pytest.mark.parametrize("text", ["", "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], "
                                      "q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []\n"],
                         ids=["empty", "header only"])
def test_a_euroc_ground_truth_file_with_no_pose_is_refused_naming_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str) -> None:
    # An empty state_groundtruth_estimate0/data.csv (a download cut short) was read as a log
    # without ground truth: exit 0, the tilt error "-", "The log has no ground truth"; the IMU's
    # file with no line but comments was refused (docs/logs.md: "a EuRoC file with no line but
    # comments" is)
    folder = make_logs.write_euroc(tmp_path / "MH_gt", synthetic(3.0))
    gt = folder / "mav0" / "state_groundtruth_estimate0" / "data.csv"
    gt.write_text(text)
    assert main(["logs", str(folder)]) == 2
    assert capsys.readouterr().err == (
        f"skeye logs: error: {gt}: no ground-truth poses (no line but comments); a log without "
        "ground truth has no state_groundtruth_estimate0/\n")
    shutil.rmtree(gt.parent)  # a log without ground truth is still measured
    assert main(["logs", str(folder)]) == 0
    assert "The log has no ground truth: no tilt error for it." in capsys.readouterr().out


def test_a_dead_gyro_axis_reads_zero_without_numpy_s_warning(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A gyro logged as zeros (a dead sensor) has an Allan deviation of 0, and its logarithm
    # printed numpy's "RuntimeWarning: divide by zero encountered in log", with the source
    # line, on stderr under the table
    s = synthetic(12.0)
    folder = make_logs.write_euroc(tmp_path / "MH_dead", dataclasses.replace(
        s, gyro=np.zeros_like(s.gyro)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main(["logs", str(folder)]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    assert "| gyro Allan deviation at 1 s (rad/s) | 0 |" in captured.out, captured.out


def test_a_euroc_file_that_starts_with_a_byte_order_mark_is_read(tmp_path: Path) -> None:
    # A CSV saved by a spreadsheet or Notepad starts with UTF-8's byte-order mark; it hid the
    # header's "#", and the log was refused: "line 1 is not numbers: could not convert string
    # to float: '\ufeff#timestamp [ns]'"
    s = synthetic(3.0)
    plain = read_log(make_logs.write_euroc(tmp_path / "MH_plain", s))
    folder = make_logs.write_euroc(tmp_path / "MH_bom", s)
    for name in ("imu0", "state_groundtruth_estimate0"):
        csv_file = folder / "mav0" / name / "data.csv"
        csv_file.write_bytes(b"\xef\xbb\xbf" + csv_file.read_bytes())
    marked = read_log(folder)
    assert np.array_equal(marked.t_s, plain.t_s)
    assert np.array_equal(marked.gyro_rad_s, plain.gyro_rad_s)
    assert marked.truth is not None and plain.truth is not None
    assert np.array_equal(marked.truth.quat_wxyz, plain.truth.quat_wxyz)


@pytest.mark.parametrize("fmt", ["euroc", "rosbag"])
def test_nanosecond_stamps_are_read_exactly(tmp_path: Path, fmt: str) -> None:
    # EuRoC's 19-digit stamps (1403636579758555392 ns) were read as float64, which holds them
    # to 256 ns: every interval of the 200 Hz log was off by up to 256 ns, its rate read
    # 200.0026 Hz and its length 2.995000064 s. A bag's header stamp (sec, nanosec) was read
    # as float64 seconds, which hold a stamp of today's clock (1.7e9 s) to 238 ns: its rate
    # read 199.9954 Hz.
    s = synthetic(3.0)
    if fmt == "euroc":
        log, truth_every = read_log(make_logs.write_euroc(tmp_path / "MH_ns", s)), 2
    else:
        log = read_log(make_logs.write_rosbag(tmp_path / "today.bag", s, t0_sec=1_764_000_000))
        truth_every = 4
    stamps_ns = np.round(s.t_s * 1e9)  # as make_logs writes them, from the first
    assert np.array_equal(log.t_s, stamps_ns * 1e-9)
    assert log.rate_hz == pytest.approx(RATE_HZ, rel=1e-12)
    assert log.truth is not None
    assert np.array_equal(log.truth.t_s, stamps_ns[::truth_every] * 1e-9)


def test_a_ulog_attitude_truth_that_changes_sign_is_one_rotation(tmp_path: Path) -> None:
    # q and -q are one rotation; the attitude truth was interpolated to the position's stamps
    # component by component, through 0 between a q and a -q: with the attitude stamped 10 ms
    # after the position, a log whose quaternions alternate in sign was refused, "ground-truth
    # quaternions of zero length (no attitude)"
    s = synthetic(12.0)
    k = np.arange(len(s.t_s))
    flipped = dataclasses.replace(s, quat_ned=s.quat_ned * np.where((k // 4) % 2, -1.0, 1.0)[
        :, None])
    figures = []
    for name, log in (("same", s), ("flipped", flipped)):
        path = make_logs.write_ulog(tmp_path / f"{name}.ulg", log, attitude_delay_us=10_000)
        assert main(["logs", str(path), "--json", str(tmp_path / f"{name}.json")]) == 0
        figures.append(json.loads((tmp_path / f"{name}.json").read_text())["real"])
    assert figures[1] == figures[0] and figures[0]["tilt_rms_deg"] < 1.0, figures
