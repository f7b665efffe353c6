"""``skeye validate [E1|E2|all] --seeds N --out DIR [--quick]``: the paper's experiments."""

from __future__ import annotations

import argparse
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from skeye.errors import LocalProtocolError
from skeye.validate.experiments import E1Series, E2Series, RunSettings, run_all
from skeye.validate.report import PAPER, median_summary, write_e1, write_e2, write_report


def validate(which: str, seeds: int, out: Path, quick: bool, first_seed: int = 1,
             workers: int | None = None, keep_recordings: bool = False) -> dict[str, Any]:
    """Run the experiments for ``seeds`` seeds in parallel worker processes; write the report."""
    which = which.upper()
    if which not in ("E1", "E2", "ALL"):
        raise LocalProtocolError(f"unknown experiment {which!r}: E1, E2 or all")
    if seeds < 1:
        raise LocalProtocolError(f"--seeds must be >= 1, got {seeds}")
    experiments = ("E1", "E2") if which == "ALL" else (which,)
    out.mkdir(parents=True, exist_ok=True)
    settings = {s: RunSettings(seed=s, quick=quick) for s in range(first_seed, first_seed + seeds)}
    results: dict[int, dict[str, Any]] = {}
    from rich.progress import Progress

    workers = workers or max(1, min(seeds, (os.cpu_count() or 2) // 2 or 1))
    with Progress() as progress, ProcessPoolExecutor(max_workers=workers) as pool:
        task = progress.add_task(f"validate {'/'.join(experiments)} x {seeds} seed(s)",
                                 total=seeds)
        futures = {
            pool.submit(run_all, st, experiments,
                        str(out / f"recordings_seed{s}") if keep_recordings else None): s
            for s, st in settings.items()
        }
        for fut in as_completed(futures):
            results[futures[fut]] = fut.result()
            progress.advance(task)
    summary: dict[str, Any] = {"paper": PAPER}
    if "E1" in experiments:
        e1: dict[int, E1Series] = {s: r["E1"] for s, r in results.items()}
        summary["E1"] = median_summary(write_e1(out, e1))
    if "E2" in experiments:
        e2: dict[int, tuple[E2Series, E2Series]] = {
            s: (r["E2"], r["E2_baseline"]) for s, r in results.items()
        }
        summary["E2"] = median_summary(write_e2(out, e2, settings))
    write_report(out, summary, quick, sorted(settings))
    return summary


def cmd_validate(args: argparse.Namespace) -> int:
    summary = validate(args.experiment, args.seeds, Path(args.out), args.quick, args.first_seed,
                       args.workers, args.keep_recordings)
    print((Path(args.out) / "report.md").read_text())
    del summary
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("validate", help="reproduce the paper's experiments and report them")
    p.add_argument("experiment", nargs="?", default="all", help="E1, E2 or all")
    p.add_argument("--seeds", type=int, default=1, help="number of seeds (run in parallel)")
    p.add_argument("--first-seed", type=int, default=1)
    p.add_argument("--out", default="validation", help="output folder")
    p.add_argument("--quick", action="store_true", help="shortened runs (CI)")
    p.add_argument("--workers", type=int, default=None, help="worker processes")
    p.add_argument("--keep-recordings", action="store_true",
                   help="keep the simulator recordings in the output folder")
    p.set_defaults(func=cmd_validate)
