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


def e2_figures(series: E2Series, baseline: E2Series, settings: RunSettings) -> dict[str, Any]:
    d, b = series.distance_m, baseline.distance_m
    return {
        "mean_m": statistics.fmean(d),
        "std_m": statistics.pstdev(d),
        "max_m": max(d),
        "duration_s": series.time_s[-1] - series.time_s[0] if series.time_s else 0.0,
        "samples": len(d),
        "baseline_mean_m": statistics.fmean(b),
        "baseline_std_m": statistics.pstdev(b),
        "baseline_max_m": max(b),
        "baseline_final_m": b[-1],
        "f_max_n": settings.f_max_n,
        "seed": settings.seed,
    }


def median_summary(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Each numeric figure's median over the runs, plus the runs themselves."""
    if len(runs) == 1:
        return dict(runs[0])
    out: dict[str, Any] = {}
    for key, value in runs[0].items():
        if key == "seed":
            out["seeds"] = [r["seed"] for r in runs]
        elif isinstance(value, int | float):
            values = [r[key] for r in runs]
            out[key] = statistics.median(values)
            out[f"{key}_spread"] = [min(values), max(values)]
    out["runs"] = runs
    return out


def write_e1(out: Path, series_by_seed: dict[int, E1Series]) -> list[dict[str, Any]]:
    runs = []
    with open(out / "e1_series.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["seed", "time_s", "estimated_height_m", "true_height_m"])
        for seed, s in sorted(series_by_seed.items()):
            for t, e, tr in zip(s.time_s, s.estimated_m, s.true_m, strict=True):
                w.writerow([seed, f"{t:.4f}", "" if e is None else f"{e:.4f}", f"{tr:.5f}"])
            runs.append(e1_figures(s, seed))
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
    ax.set_xlabel("sim time (s)")
    ax.set_ylabel("height above the pad (m)")
    ax.set_title(f"E1: height from the pad vs ground truth (seed {seed})")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "e1_height.png", dpi=120)
    return runs


def write_e2(out: Path, series_by_seed: dict[int, tuple[E2Series, E2Series]],
             settings_by_seed: dict[int, RunSettings]) -> list[dict[str, Any]]:
    runs = []
    with open(out / "e2_series.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["seed", "run", "time_s", "distance_m"])
        for seed, (s, b) in sorted(series_by_seed.items()):
            for name, ser in (("vision", s), ("baseline", b)):
                for t, dist in zip(ser.time_s, ser.distance_m, strict=True):
                    w.writerow([seed, name, f"{t:.4f}", f"{dist:.5f}"])
            runs.append(e2_figures(s, b, settings_by_seed[seed]))
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 4.5))
    ax = fig.add_subplot(1, 1, 1)
    seed, (s, b) = sorted(series_by_seed.items())[0]
    ax.plot(b.time_s, [x * 100 for x in b.distance_m], color="tab:gray", linewidth=1,
            label="no vision (drift baseline)")
    ax.plot(s.time_s, [x * 100 for x in s.distance_m], color="tab:blue", linewidth=1,
            label="position hold on the pad")
    ax.axhline(5.0, color="tab:green", linestyle="--", linewidth=0.8, label="deadband 5 cm")
    ax.set_xlabel("time since hold started (s)")
    ax.set_ylabel("distance from the pad centre (cm)")
    ax.set_title(f"E2: position hold under random force, F_max {settings_by_seed[seed].f_max_n} "
                 f"N (seed {seed})")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "e2_distance.png", dpi=120)
    return runs


def write_report(out: Path, summary: dict[str, Any], quick: bool, seeds: list[int]) -> None:
    lines = [
        "# skeye validation report",
        "",
        f"Seeds: {seeds}; mode: {'quick (CI: shortened runs)' if quick else 'full'}; "
        "simulator in lockstep, pilot with landing-pad vision on frames from the image server,",
        "a scripted ground client over the vehicle packet protocol. Figures are medians over",
        "the seeds, computed from the series in the CSV files.",
        "",
    ]
    if "E1" in summary:
        e1 = summary["E1"]
        ok = e1["max_rel_error"] <= 0.01 and e1["max_abs_error_m"] <= 0.01
        lines += [
            "## E1: height from the pad (paper Fig. 6)",
            "",
            "| figure | skeye | paper | target |",
            "| --- | --- | --- | --- |",
            f"| max absolute error | {e1['max_abs_error_m'] * 100:.2f} cm | ~2 cm | <= 1 cm |",
            f"| max relative error | {e1['max_rel_error'] * 100:.2f} % | 2 % (5 % with the "
            f"integer FOV) | <= 1 % (goal 0.5 %) |",
            f"| RMS error | {e1['rms_error_m'] * 100:.2f} cm | - | - |",
            f"| frames processed | {e1['frames']} | - | - |",
            f"| frames with no detection | {e1['missed_frames']} | - | 0 |",
            "",
            f"Error targets (<= 1 %, <= 1 cm): {'met' if ok else 'NOT met'}. "
            f"No missed frames: {'met' if e1['missed_frames'] == 0 else 'NOT met'} "
            f"({e1['missed_frames']} of {e1['frames']} frames without a detection). "
            "Plot: `e1_height.png`; series: `e1_series.csv`.",
            "",
        ]
    if "E2" in summary:
        e2 = summary["E2"]
        ok = e2["std_m"] < PAPER["E2_std_m"] and e2["max_m"] < PAPER["E2_max_m"]
        lines += [
            "## E2: position hold over the pad under wind (paper Fig. 7)",
            "",
            f"Random force on the centre of mass, F_max {e2['f_max_n']} N redrawn every 1/30 s; "
            f"PAD_MODE 1 with deadband 0.05 m and 0.3 m/s; {e2['duration_s']:.0f} s of sim time.",
            "",
            "| figure | skeye | paper (sim) | paper (real) | target |",
            "| --- | --- | --- | --- | --- |",
            f"| mean distance | {e2['mean_m'] * 100:.2f} cm | - | - | - |",
            f"| standard deviation | {e2['std_m'] * 100:.2f} cm | 2.49 cm | 3.8 cm | < 2.49 cm |",
            f"| maximum | {e2['max_m'] * 100:.2f} cm | 13.27 cm | 23 cm | < 13.27 cm |",
            f"| baseline (no vision): std / max / final | {e2['baseline_std_m'] * 100:.1f} / "
            f"{e2['baseline_max_m'] * 100:.1f} / {e2['baseline_final_m'] * 100:.1f} cm | "
            "drifts | - | well away |",
            "",
            f"Target {'met' if ok else 'NOT met'}. Plot: `e2_distance.png`; series: "
            "`e2_series.csv`.",
            "",
        ]
    (out / "report.md").write_text("\n".join(lines))
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
