"""A sweep's results: one JSON file per finished trial, the tables, the report and its plots.

How this works: every row is written to ``OUT/trials/<key>.json`` the moment it arrives
(write to a temporary name, then rename), so an interrupted sweep loses only the trials that
were running, and a rerun skips every trial whose row exists without an error (the key hashes
parameters, seed and code version: see :mod:`skeye.sweep.spec`). ``results.csv`` (always) and
``results.parquet`` (when pyarrow is installed: ``pip install 'skeye[parquet]'``) hold one row
per trial of the spec; ``report.md`` gives each figure's median and spread per parameter value,
with plots of each figure against each swept parameter (box plots over seeds).
"""

from __future__ import annotations

import csv
import json
import math
import statistics
from pathlib import Path
from typing import Any

from skeye.errors import ConfigError
from skeye.sweep.spec import ROW_FIXED, ROW_TAIL, SweepSpec

FIXED = list(ROW_FIXED)
TAIL = list(ROW_TAIL)
# What a run was, not what it measured (E2's series length): kept in the rows, not summarised
# or plotted as figures.
RUN_DESCRIPTORS = frozenset({"duration_s", "samples"})


class ResultStore:
    """Rows on disk, one file per trial."""

    def __init__(self, out: Path) -> None:
        self.dir = out / "trials"
        self.dir.mkdir(parents=True, exist_ok=True)

    def path(self, key: str) -> Path:
        return self.dir / f"{key}.json"

    def get(self, key: str) -> dict[str, Any] | None:
        try:
            return dict(json.loads(self.path(key).read_text()))
        except (FileNotFoundError, json.JSONDecodeError):
            return None

    def done(self, key: str) -> bool:
        row = self.get(key)
        return row is not None and not row.get("error")

    def put(self, row: dict[str, Any]) -> None:
        """Store ``row`` (whole or not at all).

        Raises:
            ConfigError: it could not be written (a full disk...), naming the file and the
                row, so that its figures are not lost with it.
        """
        path = self.path(row["key"])
        tmp = path.with_suffix(".tmp")
        text = json.dumps(row, indent=1)
        try:
            tmp.write_text(text)
            tmp.replace(path)
        except OSError as exc:
            try:
                tmp.unlink()
            except OSError:
                pass
            raise ConfigError(f"cannot store trial {row['key']}'s row in {path}: "
                              f"{exc.strerror or exc}; its row: {json.dumps(row)}") from None


def columns(rows: list[dict[str, Any]], params: list[str]) -> list[str]:
    figures: list[str] = []
    for r in rows:
        for k in r:
            if k not in FIXED and k not in TAIL and k not in params and k not in figures:
                figures.append(k)
    return FIXED[:2] + params + FIXED[2:] + figures + TAIL


def figure_names(rows: list[dict[str, Any]], params: list[str]) -> list[str]:
    """The measured figures of the rows (numeric columns, not the run's descriptors)."""
    cols = columns(rows, params)
    return [c for c in cols[len(FIXED) + len(params):-len(TAIL)]
            if c not in RUN_DESCRIPTORS and any(_num(r.get(c)) is not None for r in rows)]


def _num(v: Any) -> float | None:
    if isinstance(v, bool) or not isinstance(v, int | float):
        return None
    return float(v) if math.isfinite(v) else None


def write_tables(out: Path, rows: list[dict[str, Any]], params: list[str]) -> list[str]:
    """``results.csv`` and, with pyarrow, ``results.parquet``; the files written."""
    cols = columns(rows, params)
    with open(out / "results.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({c: r.get(c, "") for c in cols})
    written = ["results.csv"]
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return written
    data = {c: [r.get(c) for r in rows] for c in cols}
    for c, values in data.items():  # one type per column: numbers, else text
        if any(isinstance(v, str) for v in values):
            data[c] = [None if v is None else str(v) for v in values]
        elif any(isinstance(v, float) for v in values):
            data[c] = [None if v is None else float(v) for v in values]
    pq.write_table(pa.table(data), out / "results.parquet")
    return [*written, "results.parquet"]


def _spread(values: list[float]) -> str:
    if not values:
        return "-"
    med = statistics.median(values)
    return f"{med:.4g} ({min(values):.4g}-{max(values):.4g})" if len(values) > 1 else f"{med:.4g}"


def _plot(out: Path, rows: list[dict[str, Any]], param: str, values: list[Any],
          figures: list[str]) -> str:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    ncols = min(3, len(figures))
    nrows = math.ceil(len(figures) / ncols)
    fig = Figure(figsize=(4.2 * ncols, 3.2 * nrows))
    for i, name in enumerate(figures):
        ax = fig.add_subplot(nrows, ncols, i + 1)
        groups = [[x for r in rows if r.get(param) == v
                   if (x := _num(r.get(name))) is not None] for v in values]
        positions = list(range(len(values)))
        ax.boxplot([g or [math.nan] for g in groups], positions=positions, widths=0.5)
        meds = [statistics.median(g) if g else math.nan for g in groups]
        ax.plot(positions, meds, "o-", color="tab:blue", linewidth=1, markersize=3,
                label="median")
        ax.set_xticks(positions, [str(v) for v in values])
        ax.set_xlabel(param)
        ax.set_title(name, fontsize=9)
        ax.grid(True, alpha=0.3)
    fig.suptitle(f"figures against {param} (box: spread over seeds)")
    fig.tight_layout()
    name = f"plot_{param}.png"
    fig.savefig(out / name, dpi=100)
    return name


def write_report(out: Path, spec: SweepSpec, rows: list[dict[str, Any]],
                 backend: str, elapsed_s: float) -> None:
    ok = [r for r in rows if not r.get("error")]
    failed = [r for r in rows if r.get("error")]
    figures = figure_names(ok, spec.param_names)
    seeds = sorted({r["seed"] for r in rows})
    lines = [
        f"# skeye sweep: {spec.name}",
        "",
        f"Experiment {spec.experiment}{' (quick runs)' if spec.trials[0].quick else ''}; "
        f"{len(rows)} trials ({len(ok)} ok, {len(failed)} failed), seeds {seeds}; "
        f"backend {backend}; {elapsed_s:.0f} s for the trials run in this invocation.",
        "Each figure: median over the trials with that parameter value (min-max in brackets).",
        "Rows: `results.csv`" + (", `results.parquet`" if (out / "results.parquet").exists()
                                 else "") + ".",
        "",
    ]
    swept = [p for p in spec.param_names if len({repr(r.get(p)) for r in rows}) > 1]
    params_or_all: list[str | None] = list(swept) or [None]
    for param in params_or_all:
        values = (sorted({r.get(param) for r in rows}, key=lambda v: (str(type(v)), v))
                  if param else [None])
        title = f"## by {param}" if param else "## all trials"
        lines += [title, "", f"| {param or 'trials'} | n | " + " | ".join(figures) + " |",
                  "|" + " --- |" * (len(figures) + 2)]
        for v in values:
            group = [r for r in ok if param is None or r.get(param) == v]
            cells = [_spread([x for r in group if (x := _num(r.get(f))) is not None])
                     for f in figures]
            lines.append(f"| {v if param else 'all'} | {len(group)} | " + " | ".join(cells) + " |")
        lines.append("")
        if param and figures and ok:
            lines += [f"![figures against {param}]({_plot(out, ok, param, values, figures)})", ""]
    if failed:
        lines += ["## failed trials", "", "| key | seed | parameters | error |",
                  "| --- | --- | --- | --- |"]
        for r in failed:
            params = ", ".join(f"{p}={r.get(p)}" for p in spec.param_names)
            lines.append(f"| {r['key']} | {r['seed']} | {params} | "
                         f"{str(r['error']).replace('|', '/')[:200]} |")
        lines.append("")
    (out / "report.md").write_text("\n".join(lines))
