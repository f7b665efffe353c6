"""Figures, CSV series, plots, summary.json and report.md for the validation experiments.

Every figure in the summary is computed here from the recorded series (``e1_figures``,
``e2_figures``); nothing is typed in. With several seeds each figure is the median over the
seeds and ``runs`` lists every seed's figures (docs/experiments.md).
"""

from __future__ import annotations

import csv
import json
import math
import statistics
from pathlib import Path
from typing import Any

from skeye.errors import SkeyeError
from skeye.validate.experiments import E1Series, E2Series, RunSettings

PAPER = {"E1_max_rel_error": 0.02, "E2_std_m": 0.0249, "E2_max_m": 0.1327}


def e1_figures(series: E1Series, seed: int) -> dict[str, Any]:
    pairs = [(e, t) for e, t in zip(series.estimated_m, series.true_m, strict=True)
             if e is not None]
    errors = [e - t for e, t in pairs]
    rel = [abs(e - t) / t for e, t in pairs if t > 0]
    return {
        "max_abs_error_m": max((abs(x) for x in errors), default=math.nan),
        "max_rel_error": max(rel, default=math.nan),
        "rms_error_m": math.sqrt(sum(x * x for x in errors) / len(errors)) if errors else math.nan,
        "frames": len(series.time_s),
        "missed_frames": sum(1 for e in series.estimated_m if e is None),
        "seed": seed,
    }


PAPER_E2_REAL = {"std_m": 0.038, "max_m": 0.23}  # the paper's real flight (3.8 / 23 cm)
E2_RUN_LABELS = {
    "vision": "position hold on the pad (vision)",
    "velocity": "velocity hold on the board's estimate (no vision)",
    "attitude": "attitude + height hold (no horizontal feedback)",
}


def _distance_figures(series: E2Series, prefix: str) -> dict[str, float]:
    d = series.distance_m
    return {f"{prefix}mean_m": statistics.fmean(d), f"{prefix}std_m": statistics.pstdev(d),
            f"{prefix}max_m": max(d), f"{prefix}final_m": d[-1]}


def e2_figures(series: E2Series, velocity: E2Series, attitude: E2Series,
               settings: RunSettings) -> dict[str, Any]:
    """The vision run's figures, and the two baselines' (``velocity_*``, ``attitude_*``)."""
    out: dict[str, Any] = _distance_figures(series, "")
    out.update(duration_s=series.time_s[-1] - series.time_s[0] if series.time_s else 0.0,
               samples=len(series.distance_m))
    out.update(_distance_figures(velocity, "velocity_"))
    out.update(_distance_figures(attitude, "attitude_"))
    out.update(f_max_n=settings.f_max_n, seed=settings.seed)
    out.update(disturbance=settings.describe_wind(), vision_latency=settings.vision_latency)
    return out


def _latency_words(latency: str) -> str:
    """When the vision run's detections were used, read as ``skeye pilot --vision-latency-ms``
    reads the setting: ``MEASURED`` was said as "MEASURED ms after their frame (fixed ...)"."""
    from skeye.pilot.cli import vision_latency_s

    try:
        seconds = vision_latency_s(latency)
    except SkeyeError:  # a summary of before the setting was kept: as it was given
        return f"{latency} ms after their frame (fixed on request)"
    if seconds is None:
        return "after the detector's measured processing time (as on a real computer)"
    return f"{seconds * 1e3:g} ms after their frame (fixed on request)"


def where_it_lands(std_m: float, max_m: float) -> str:
    """Where E2's figures lie against the paper's simulation and real flight, in words."""
    words = []
    for name, value, sim, real in (("standard deviation", std_m, PAPER["E2_std_m"],
                                    PAPER_E2_REAL["std_m"]),
                                   ("maximum", max_m, PAPER["E2_max_m"], PAPER_E2_REAL["max_m"])):
        if value < sim:
            place = "below the paper's simulation"
        elif value <= real:
            place = "between the paper's simulation and its real flight"
        else:
            place = "above the paper's real flight"
        words.append(f"the {name} ({value * 100:.2f} cm) lies {place} (paper: simulation "
                     f"{sim * 100:.2f} cm, real flight {real * 100:.1f} cm)")
    return "; ".join(words)


def median_summary(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Each numeric figure's median over the runs, plus the runs themselves. A run without a
    figure (NaN: E1's errors when no frame had a detection) is left out of its median and
    spread, which are NaN when no run has it: NaN has no place in an order, and the median
    and spread were whatever the seeds' order made of it."""
    if len(runs) == 1:
        return dict(runs[0])
    out: dict[str, Any] = {}
    for key, value in runs[0].items():
        if key == "seed":
            out["seeds"] = [r["seed"] for r in runs]
        elif isinstance(value, int | float):
            values = [r[key] for r in runs if not math.isnan(r[key])]
            out[key] = statistics.median(values) if values else math.nan
            out[f"{key}_spread"] = ([min(values), max(values)] if values
                                    else [math.nan, math.nan])
        elif isinstance(value, str):
            out[key] = value  # a setting, the same for every run
    out["runs"] = runs
    return out


def add_uncalibrated(figures: dict[str, Any], uncalibrated: dict[str, Any]) -> None:
    """Add the E1 flight without the calibration's figures to ``figures``, as
    ``uncalibrated_*``."""
    figures.update({f"uncalibrated_{k}": v for k, v in uncalibrated.items() if k != "seed"})


def _write_e1_csv(path: Path, series_by_seed: dict[int, E1Series]) -> list[dict[str, Any]]:
    runs = []
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["seed", "time_s", "estimated_height_m", "true_height_m"])
        for seed, s in sorted(series_by_seed.items()):
            for t, e, tr in zip(s.time_s, s.estimated_m, s.true_m, strict=True):
                w.writerow([seed, f"{t:.4f}", "" if e is None else f"{e:.4f}", f"{tr:.5f}"])
            runs.append(e1_figures(s, seed))
    return runs


def write_e1(out: Path, series_by_seed: dict[int, E1Series],
             uncalibrated: dict[int, E1Series] | None = None) -> list[dict[str, Any]]:
    """e1_series.csv (and e1_uncalibrated_series.csv), e1_height.png; each seed's figures,
    the uncalibrated run's as ``uncalibrated_*``."""
    runs = _write_e1_csv(out / "e1_series.csv", series_by_seed)
    if uncalibrated:
        raw = _write_e1_csv(out / "e1_uncalibrated_series.csv", uncalibrated)
        for run, other in zip(runs, raw, strict=True):
            add_uncalibrated(run, other)
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 4.5))
    ax = fig.add_subplot(1, 1, 1)
    seed, s = sorted(series_by_seed.items())[0]
    ax.plot(s.time_s, s.true_m, label="true camera height", color="black", linewidth=1.5)
    est = [(t, e) for t, e in zip(s.time_s, s.estimated_m, strict=True) if e is not None]
    ax.plot([t for t, _ in est], [e for _, e in est], ".", markersize=2.5, color="tab:red",
            label="height from the pad")
    if uncalibrated:
        u = uncalibrated[seed]
        est = [(t, e) for t, e in zip(u.time_s, u.estimated_m, strict=True) if e is not None]
        ax.plot([t for t, _ in est], [e for _, e in est], ".", markersize=2.5,
                color="tab:orange", label="height from the pad, no calibration")
    ax.set_xlabel("sim time (s)")
    ax.set_ylabel("height above the pad (m)")
    ax.set_title(f"E1: height from the pad vs ground truth (seed {seed})")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "e1_height.png", dpi=120)
    return runs


def write_e2(out: Path, series_by_seed: dict[int, dict[str, E2Series]],
             settings_by_seed: dict[int, RunSettings]) -> list[dict[str, Any]]:
    """e2_series.csv and e2_distance.png from each seed's three runs (``vision``,
    ``velocity``, ``attitude``); each seed's figures."""
    runs = []
    with open(out / "e2_series.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["seed", "run", "time_s", "distance_m"])
        for seed, by_run in sorted(series_by_seed.items()):
            for name in E2_RUN_LABELS:
                ser = by_run[name]
                for t, dist in zip(ser.time_s, ser.distance_m, strict=True):
                    w.writerow([seed, name, f"{t:.4f}", f"{dist:.5f}"])
            runs.append(e2_figures(by_run["vision"], by_run["velocity"], by_run["attitude"],
                                   settings_by_seed[seed]))
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 4.5))
    ax = fig.add_subplot(1, 1, 1)
    seed, by_run = sorted(series_by_seed.items())[0]
    for name, color in (("attitude", "tab:red"), ("velocity", "tab:gray"),
                        ("vision", "tab:blue")):
        ser = by_run[name]
        ax.plot(ser.time_s, [x * 100 for x in ser.distance_m], color=color, linewidth=1,
                label=E2_RUN_LABELS[name])
    ax.axhline(5.0, color="tab:green", linestyle="--", linewidth=0.8, label="deadband 5 cm")
    ax.set_yscale("symlog", linthresh=20.0)
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("time since hold started (s)")
    ax.set_ylabel("distance from the pad centre (cm)")
    ax.set_title(f"E2: hold under {settings_by_seed[seed].wind} (seed {seed})")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "e2_distance.png", dpi=120)
    return runs


def _hundredths(value: float, unit: str) -> str:
    """A figure in m (or a fraction) said in cm (or %); an error figure of a run with no
    detection at all is NaN (no error to take): said as none, not "nan cm"."""
    if not math.isfinite(value):
        return "none (no frame with a detection)"
    return f"{value * 100:.2f} {unit}"


def _json_figures(value: Any) -> Any:
    """``value`` with every NaN or infinite figure as None (JSON's null, as ``skeye sweep``'s
    rows have it): ``json.dumps`` wrote NaN, which JSON has not, and strict readers refuse."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _json_figures(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_figures(v) for v in value]
    return value


def _shown_path(path: str, out: Path, made: bool) -> str:
    """``path`` relative to the output folder when it lies inside it (the report travels),
    said made by this run when it was (``made``): a ``--calibration`` given from an earlier
    run's ``OUT/calibration/`` was said made by this one."""
    if not path:
        return "none"
    try:
        inside = Path(path).resolve().relative_to(out.resolve())
    except ValueError:
        return f"`{path}`"
    return f"`{inside}` ({'made by this run' if made else 'given'})"


def _truth_note(setup: dict[str, Any]) -> str:
    if setup.get("pad_source") == "truth":
        return " (ground truth in place of the detector: a comparison run)"
    return ""


def _seeds_words(seeds: list[int], flown: dict[str, list[int]] | None,
                 failed: list[dict[str, Any]], trials: int | None) -> str:
    """The seeds the figures come from; with failed trials, beside the seeds asked for and
    the number of trials that ran (``summary["trials"]``; a summary without it: each
    experiment's seeds)."""
    if not failed or flown is None:
        return f"{seeds}"
    reported = sorted({s for flew in flown.values() for s in flew})
    ran = trials if trials is not None else len(seeds) * len(flown)
    return (f"{reported} (seeds {', '.join(map(str, seeds))} asked for; {len(failed)} of "
            f"{ran} trials failed, listed under \"Failed trials\")")


def _failed_lines(failed: list[dict[str, Any]]) -> list[str]:
    lines = ["## Failed trials", "",
             "Their series are not in the figures above; each trial's error, as its run gave it:",
             "", "| experiment | seed | error |", "| --- | --- | --- |"]
    lines += [f"| {f['experiment']} | {f['seed']} | "  # one table row: no '|', no line break
              f"{' '.join(str(f['error']).replace('|', '/').split())} |" for f in failed]
    return [*lines, ""]


def _missing_note(name: str, flown: dict[str, list[int]] | None, seeds: list[int]) -> list[str]:
    """A line under an experiment's heading naming its seeds that failed, when some did."""
    if flown is None or len(flown.get(name, [])) == len(seeds):
        return []
    gone = [s for s in seeds if s not in flown.get(name, [])]
    return [f"Over seed(s) {flown[name]} only: seed(s) {gone} failed (\"Failed trials\").", ""]


def write_report(out: Path, summary: dict[str, Any], quick: bool, seeds: list[int],
                 flown: dict[str, list[int]] | None = None) -> None:
    """report.md and summary.json. ``seeds`` are the seeds asked for, ``flown`` each
    experiment's seeds whose trial came back (all of them when None); ``summary["failed"]``
    lists the others' errors, out of ``summary["trials"]`` run."""
    setup = summary.get("setup", {})
    failed = summary.get("failed", [])
    lines = [
        "# skeye validation report",
        "",
        f"Seeds: {_seeds_words(seeds, flown, failed, summary.get('trials'))}; "
        f"mode: {'quick (CI: shortened runs)' if quick else 'full'}; "
        f"camera profile: {setup.get('camera', 'ideal')}; board estimator: "
        f"{setup.get('estimator', 'truth')}; world: {setup.get('world', 'pad')}; calibration: "
        f"{_shown_path(setup.get('calibration', ''), out, 'calibration' in summary)}; "
        "E2 disturbance: "
        f"{setup.get('wind', 'random_force')}; vision latency: "
        f"{setup.get('vision_latency', '0')}; pad observations: "
        f"{setup.get('pad_source', 'vision')}{_truth_note(setup)}.",
        "Simulator in lockstep, pilot with landing-pad vision on frames from the image server,",
        "a scripted ground client over the vehicle packet protocol. Figures are medians over",
        "the seeds, computed from the series in the CSV files.",
        "",
    ]
    if "calibration" in summary:
        cal = summary["calibration"]
        lines += [
            "## Camera calibration",
            "",
            f"`skeye calibrate` on {cal['views_used']} views of the checkerboard world "
            f"(RMS reprojection {cal['rms_px']:.3f} px), against the camera model the "
            "simulator renders through:",
            "",
            "| | calibrated | camera model |",
            "| --- | --- | --- |",
        ]
        lines += [f"| {key} | {cal['found'][key]:.4f} | {cal['model'][key]:.4f} |"
                  for key in cal["found"]]
        lines.append("")
    if "E1" in summary:
        e1 = summary["E1"]
        ok = e1["max_rel_error"] <= 0.01 and e1["max_abs_error_m"] <= 0.01
        lines += [
            "## E1: height from the pad (paper Fig. 6)",
            "",
            *_missing_note("E1", flown, seeds),
            "| figure | skeye | paper | target |",
            "| --- | --- | --- | --- |",
            f"| max absolute error | {_hundredths(e1['max_abs_error_m'], 'cm')} | ~2 cm "
            "| <= 1 cm |",
            f"| max relative error | {_hundredths(e1['max_rel_error'], '%')} | 2 % (5 % with the "
            f"integer FOV) | <= 1 % (goal 0.5 %) |",
            f"| RMS error | {_hundredths(e1['rms_error_m'], 'cm')} | - | - |",
            f"| frames processed | {e1['frames']:g} | - | - |",
            f"| frames with no detection | {e1['missed_frames']:g} | - | 0 |",
            "",
            f"Error targets (<= 1 %, <= 1 cm): {'met' if ok else 'NOT met'}. "
            f"No missed frames: {'met' if e1['missed_frames'] == 0 else 'NOT met'} "
            f"({e1['missed_frames']:g} of {e1['frames']:g} frames without a detection). "
            "Plot: `e1_height.png`; series: `e1_series.csv`.",
            "",
        ]
        if "uncalibrated_max_rel_error" in e1:
            lines += [
                "The same flight with the detector on the ideal pinhole of the camera's field "
                "of view (no calibration): max relative error "
                f"{_hundredths(e1['uncalibrated_max_rel_error'], '%')}, max absolute "
                f"{_hundredths(e1['uncalibrated_max_abs_error_m'], 'cm')}, RMS "
                f"{_hundredths(e1['uncalibrated_rms_error_m'], 'cm')}, "
                f"{e1['uncalibrated_missed_frames']:g} of {e1['uncalibrated_frames']:g} frames "
                "without a detection: the bias a missing calibration causes "
                "(series: `e1_uncalibrated_series.csv`).",
                "",
            ]
    if "E2" in summary:
        e2 = summary["E2"]
        lines += [
            "## E2: position hold over the pad under wind (paper Fig. 7)",
            "",
            *_missing_note("E2", flown, seeds),
            f"Disturbance: {e2.get('disturbance', 'random force')}; "
            f"{e2['duration_s']:.0f} s of sim time per run, the same seed and disturbance for "
            "the three runs; the vision run's pad detections are used "
            f"{_latency_words(e2.get('vision_latency', '0'))}. Distance of the vehicle from "
            "the pad centre:",
            "",
            "| run | mean | std | max | final | paper (sim) std / max | paper (real) std / max |",
            "| --- | --- | --- | --- | --- | --- | --- |",
        ]
        for name, prefix in (("vision", ""), ("velocity", "velocity_"),
                             ("attitude", "attitude_")):
            paper = ("2.49 / 13.27 cm", "3.8 / 23 cm") if name == "vision" else ("drifts", "-")
            lines.append(
                f"| {E2_RUN_LABELS[name]} | {e2[prefix + 'mean_m'] * 100:.2f} cm | "
                f"{e2[prefix + 'std_m'] * 100:.2f} cm | {e2[prefix + 'max_m'] * 100:.2f} cm | "
                f"{e2[prefix + 'final_m'] * 100:.2f} cm | {paper[0]} | {paper[1]} |")
        lines += [
            "",
            "PAD_MODE 1 with deadband 0.05 m and 0.3 m/s for the vision run; the velocity hold "
            "is HOLD on the board's own estimate (with the onboard estimator: optical flow and "
            "sonar, and GPS where the world has a sky: the pad world does, the indoor world "
            "does not); the attitude run flies centred sticks in the AscTec height mode.",
            "",
            f"Where skeye lands: {where_it_lands(e2['std_m'], e2['max_m'])}. "
            "Plot: `e2_distance.png`; series: `e2_series.csv`.",
            "",
        ]
    if failed:
        lost = [name for name, flew in (flown or {}).items() if not flew]
        lines += [f"{name}: every trial failed, no figures." for name in lost]
        lines += [""] if lost else []
        lines += _failed_lines(failed)
    (out / "report.md").write_text("\n".join(lines))
    (out / "summary.json").write_text(json.dumps(_json_figures(summary), indent=2,
                                                 allow_nan=False))
