"""``skeye validate [E1|E2|all] --seeds N --out DIR [--quick] [--camera ideal|webcam]
[--calibration FILE] [--estimator onboard|truth] [--world pad|indoor]``: the paper's
experiments."""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

from skeye import cliargs
from skeye.cliargs import not_installed
from skeye.errors import ConfigError, LocalProtocolError, SkeyeError
from skeye.outputs import folder_lock, output_folder
from skeye.processes import scaled_s
from skeye.robots.config import camera_model
from skeye.sweep.backends import LocalBackend
from skeye.sweep.cli import run_trials, stop_cleanly_on_signals
from skeye.sweep.spec import MAX_TRIALS, SweepSpec, Trial
from skeye.validate.calibration import calibrate_simulated_camera
from skeye.validate.experiments import (
    CAMERAS,
    E2_RUNS,
    E2_WINDS,
    ESTIMATORS,
    PAD_SOURCES,
    SETTING_CHOICES,
    WORLDS,
    E1Series,
    E2Series,
    RunSettings,
    check_setting,
    e2_key,
)
from skeye.validate.report import PAPER, median_summary, write_e1, write_e2, write_report
from skeye.vision.calibration import CalibrationResult


def _choice(name: str, value: str, what: str) -> None:
    """A setting that names one of a list (:func:`check_setting`), refused in the CLI's words."""
    try:
        check_setting(name, value)
    except ConfigError:
        raise LocalProtocolError(f"unknown {what} {value!r}: "
                                 f"{', '.join(SETTING_CHOICES[name])}") from None


VALIDATE_NEEDS = ("mujoco", "rich", "matplotlib")
"""The modules of the sim extra a validation imports: the simulator its trials fly, the
progress, the figures (drawn once every trial has flown)."""


def validate(which: str, seeds: int, out: Path, quick: bool, first_seed: int = 1,
             workers: int | None = None, keep_recordings: bool = False, *,
             camera: str = "ideal", estimator: str = "onboard", world: str = "pad",
             calibration: Path | None = None, wind: str = "dryden",
             vision_latency: str = "measured", pad_source: str = "vision") -> dict[str, Any]:
    """Run the experiments for ``seeds`` seeds on the sweep's local pool; write the report.

    Each (experiment, seed) is one trial of :mod:`skeye.sweep` (its own processes, in parallel
    up to ``workers``); the series come back from the trials and the report is built here.
    A trial that failed (its error in its row, as in a sweep) leaves the others' series in the
    report, which lists it with its error (``failed`` in the summary, as ``skeye sweep``'s report
    lists its failed trials); when every trial failed there is nothing to report and a
    :class:`SkeyeError` names each one, and no report, series or figure is written (a
    calibration made first stays in ``out/calibration/``).
    ``camera`` is the camera profile every run renders through, ``estimator`` the boards'
    state estimator and ``world`` the built-in world flown in. A camera other than the ideal
    pinhole is calibrated first, as a user would (the checkerboard world, ``skeye
    calibrate``'s maths; ``out/calibration/``), unless a ``calibration`` file is given; the
    pilot's detector uses it, and E1 is flown again without it.
    """
    which = which.upper()
    if which not in ("E1", "E2", "ALL"):
        raise LocalProtocolError(f"unknown experiment {which!r}: E1, E2 or all")
    experiments = ("E1", "E2") if which == "ALL" else (which,)
    if not 1 <= seeds <= MAX_TRIALS // len(experiments):  # one sweep trial per run
        raise LocalProtocolError(f"--seeds must be 1..{MAX_TRIALS // len(experiments)} (a sweep "
                                 f"makes at most {MAX_TRIALS} trials), got {seeds}")
    for name, value, what in (("camera", camera, "camera profile"),
                              ("estimator", estimator, "estimator"), ("world", world, "world")):
        _choice(name, value, what)
    if wind not in E2_WINDS:
        raise LocalProtocolError(f"unknown E2 disturbance {wind!r}: {', '.join(E2_WINDS)}")
    try:  # refused here, not in every trial; in the CLI's words (it was "vision_latency")
        check_setting("vision_latency", vision_latency)
    except ConfigError:
        raise LocalProtocolError(f"--vision-latency-ms must be 'measured' or a number of ms "
                                 f"0..10000, got {vision_latency!r}") from None
    _choice("pad_source", pad_source, "pad source")
    if calibration is not None:  # a bad file is named here, not in every trial
        check_setting("calibration", str(calibration))
        calibration_fits(calibration, camera)
    missing = not_installed(VALIDATE_NEEDS)  # before the folder, not after the trials
    if missing:
        raise ConfigError(missing)
    output_folder(out)
    with folder_lock(out, "skeye validate"):  # two runs there would mix their files
        if keep_recordings:  # each trial would refuse to write over one, or fail to make its
            # folder where something else is in the way, after the calibration
            kept = [out / f"recordings_seed{s}" for s in range(first_seed, first_seed + seeds)]
            blocked = [str(d) for d in kept if os.path.lexists(d) and not d.is_dir()]
            if blocked:  # a file, or a link to none: no trial of that seed could record there
                raise ConfigError(f"--keep-recordings: {', '.join(blocked)} is not a folder "
                                  "(each seed's recordings go in a folder of that name): remove "
                                  "it, or give another --out")
            full = [str(d) for d in kept if d.is_dir() and any(d.iterdir())]
            if full:
                raise ConfigError(f"--keep-recordings: {', '.join(full)} already hold(s) "
                                  "recordings of an earlier run: give another --out, or remove "
                                  "them")
        calibrating = calibration is None and camera != "ideal"
        blocked = [str(out / name) for name in written_names(experiments, calibrating
                                                             or calibration is not None)
                   if (out / name).is_dir()]
        if calibrating and os.path.lexists(out / "calibration") and not (
                out / "calibration").is_dir():
            blocked.append(str(out / "calibration"))
        if blocked:  # found before anything is calibrated or flown, not when it is written
            raise ConfigError(f"--out {out}: {', '.join(blocked)} is in the way of what this "
                              "run writes there (the report, summary, series and figures are "
                              "files, the calibration a folder): remove it, or give another "
                              "--out")
        summary: dict[str, Any] = {"paper": PAPER}
        if calibrating:
            calibration, found = calibrate_simulated_camera(out / "calibration", camera, first_seed)
            summary["calibration"] = calibration_figures(found, camera)
        cal_path = str(calibration.resolve()) if calibration is not None else ""
        params = {"camera": camera, "estimator": estimator, "world": world, "calibration": cal_path,
                  "wind": wind, "vision_latency": vision_latency, "pad_source": pad_source}
        summary["setup"] = dict(params)
        seed_list = list(range(first_seed, first_seed + seeds))
        settings = {s: RunSettings(seed=s, quick=quick, camera=camera, estimator=estimator,
                                   world=world, calibration=cal_path, wind=wind,
                                   vision_latency=vision_latency, pad_source=pad_source)
                    for s in seed_list}
        limit_s = scaled_s(900.0 if quick else 7200.0)  # a guard; the runs wait on sim time
        trials = [Trial(e, dict(params), s, quick, timeout_s=limit_s)
                  for s in seed_list for e in experiments]
        summary["trials"] = len(trials)  # the count every line that says "k of N" gives
        spec = SweepSpec(which, trials, [])
        with tempfile.TemporaryDirectory(prefix="skeye-validate-") as tmp:

            def keep(trial: dict[str, Any]) -> dict[str, str]:
                t = Trial.from_json(trial)
                extra = {"series_file": str(Path(tmp) / f"{t.key}.series.json")}
                if keep_recordings:
                    extra["workdir"] = str(out / f"recordings_seed{t.seed}")
                return extra

            backend = LocalBackend(workers or max(1, min(len(trials), (os.cpu_count() or 2) // 2)),
                                   keep)
            result = run_trials(spec, Path(tmp), backend,
                                f"validate {'/'.join(experiments)} x {seeds} seed(s)")
            failed = [{"experiment": r["experiment"], "seed": r["seed"], "error": r["error"]}
                      for r in result.rows if r.get("error")]
            if len(failed) == len(trials):  # nothing flown: nothing to report
                raise SkeyeError("every trial failed, no report written: " + "; ".join(
                    f"{f['experiment']} seed {f['seed']}: {f['error']}" for f in failed))
            gone = {(f["experiment"], f["seed"]) for f in failed}
            series = {(t.experiment, t.seed): json.loads(
                (Path(tmp) / f"{t.key}.series.json").read_text())
                for t in trials if (t.experiment, t.seed) not in gone}
        flown = {e: [s for s in seed_list if (e, s) in series] for e in experiments}
        if flown.get("E1"):
            e1 = {s: E1Series(**series["E1", s]["E1"]) for s in flown["E1"]}
            raw = ({s: E1Series(**series["E1", s]["E1_uncalibrated"]) for s in flown["E1"]}
                   if cal_path else None)
            summary["E1"] = median_summary(write_e1(out, e1, raw))
        if flown.get("E2"):
            e2 = {s: {run: E2Series(**series["E2", s][e2_key(run)]) for run in E2_RUNS}
                  for s in flown["E2"]}
            summary["E2"] = median_summary(write_e2(out, e2, settings))
        if failed:
            summary["failed"] = failed
        write_report(out, summary, quick, seed_list, flown)
        return summary


def calibration_fits(path: Path, camera: str) -> None:
    """A ``--calibration`` for the image size of the camera every run flies (the
    Hummingbird's, under ``camera``), refused here as each trial's ``skeye pilot`` would refuse
    it: once, before anything runs, not again in every trial."""
    from skeye.vision.calibration import load_calibration

    cal = load_calibration(path)
    model = camera_model("hummingbird", profile=camera)
    if (cal.width_px, cal.height_px) != (model.width, model.height):
        raise ConfigError(f"--calibration {path} is for {cal.width_px}x{cal.height_px} images, "
                          f"the {camera} camera every run flies gives {model.width}x"
                          f"{model.height}: calibrate it at that resolution")


def written_names(experiments: tuple[str, ...], calibrated: bool) -> list[str]:
    """The files a run of ``experiments`` writes in its ``--out`` folder (E1's uncalibrated
    series when it flies with a calibration)."""
    names = ["report.md", "summary.json"]
    if "E1" in experiments:
        names += ["e1_series.csv", "e1_height.png"]
        names += ["e1_uncalibrated_series.csv"] if calibrated else []
    if "E2" in experiments:
        names += ["e2_series.csv", "e2_distance.png"]
    return names


def calibration_figures(result: CalibrationResult, camera: str) -> dict[str, Any]:
    """The calibration found beside the camera model the simulator rendered through."""
    model = camera_model("hummingbird", profile=camera)
    cal = result.calibration
    names = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
    found = (cal.fx, cal.fy, cal.cx, cal.cy, *cal.dist)
    truth = (model.fx_px, model.fy_px, model.cx_px, model.cy_px, *model.dist_coeffs)
    return {"views_used": len(result.used), "rms_px": cal.rms_px,
            "found": dict(zip(names, found, strict=True)),
            "model": dict(zip(names, truth, strict=True))}


def cmd_validate(args: argparse.Namespace) -> int:
    try:  # Ctrl-C, SIGTERM, SIGHUP: the running trials are killed, as skeye sweep's are
        with stop_cleanly_on_signals():
            summary = validate(
                args.experiment, args.seeds, Path(args.out), args.quick, args.first_seed,
                args.workers, args.keep_recordings, camera=args.camera,
                estimator=args.estimator, world=args.world,
                calibration=Path(args.calibration) if args.calibration is not None else None,
                wind=args.wind, vision_latency=args.vision_latency_ms,
                pad_source=args.pad_source)
    except KeyboardInterrupt as exc:
        print(f"skeye validate: {str(exc) or 'interrupted'}; no report written",
              file=sys.stderr)
        return 130
    print((Path(args.out) / "report.md").read_text())
    failed = summary.get("failed", [])
    if failed:  # as skeye sweep: 1 when a trial failed, the report written for the others
        named = ", ".join(f"{f['experiment']} seed {f['seed']}" for f in failed)
        print(f"skeye validate: {len(failed)} of {summary['trials']} trials failed ({named}); "
              f"the report covers the others, the errors are in {Path(args.out) / 'report.md'}",
              file=sys.stderr)
        return 1
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("validate", help="reproduce the paper's experiments and report them")
    p.add_argument("experiment", nargs="?", default="all", help="E1, E2 or all")
    p.add_argument("--seeds", type=cliargs.positive_int, default=1,
                   help="number of seeds (run in parallel)")
    p.add_argument("--first-seed", type=cliargs.seed, default=1,
                   help="the first seed (a whole number >= 0; default 1)")
    p.add_argument("--out", type=cliargs.path, default="validation", help="output folder")
    p.add_argument("--quick", action="store_true", help="shortened runs (CI)")
    p.add_argument("--workers", type=cliargs.positive_int, default=None,
                   help="worker processes (>= 1)")
    p.add_argument("--keep-recordings", action="store_true",
                   help="keep the simulator recordings in the output folder")
    p.add_argument("--camera", choices=CAMERAS, default="ideal",
                   help="camera profile of every run (skeye sim --camera-profile); webcam is "
                   "calibrated first unless --calibration is given")
    p.add_argument("--calibration", type=cliargs.path, default=None,
                   help="a `skeye calibrate` file for the pilot's pad detector")
    p.add_argument("--estimator", choices=ESTIMATORS, default="onboard",
                   help="the boards' state estimator (skeye sim --estimator): onboard flies on "
                   "the simulated sensors, truth on the oracle")
    p.add_argument("--wind", choices=E2_WINDS, default="dryden",
                   help="E2's disturbance: dryden (MIL-F-8785C low-altitude gusts with a mean "
                   "wind, the default), random_force (the paper's own: a force on the centre "
                   "of mass, F_max 0.3 N redrawn every 1/30 s) or none")
    p.add_argument("--vision-latency-ms", default="measured", metavar="MS|measured",
                   help="when the pilot uses a pad detection: 'measured' (default), the "
                   "detector's own processing time as on a real computer; N fixes it at N ms "
                   "after the frame (skeye pilot --vision-latency-ms)")
    p.add_argument("--pad-source", choices=PAD_SOURCES, default="vision",
                   help="the vision runs' pad observations: vision (the detector, default) or "
                   "truth (ground truth in place of each detection, same frames and timing: "
                   "what a perfect detector would give, for comparison)")
    p.add_argument("--world", choices=WORLDS, default="pad",
                   help="the world flown in: pad (outdoors, GPS) or indoor (no GPS: the "
                   "velocity hold is optical flow only, as on the paper's extension board)")
    p.set_defaults(func=cmd_validate)
