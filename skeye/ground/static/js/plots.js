// Time plots with the vendored uPlot (static/vendor/uplot, loaded by index.html as the global
// uPlot before the modules run): a legend with each series' value under the cursor; drag
// across a plot to zoom in on that time span (it then stops following the live data),
// double-click to zoom back out and follow the last ``windowS`` seconds again.
//
// ``columns`` and ``paddedRange`` are pure (tested through the browser harness).

// uPlot's column data from rows {t, key: value|null}: [[t...], [key1...], ...] for the rows
// at or after ``sinceS``; a missing value is null (a gap in the line).
export function columns(rows, keys, sinceS = -Infinity) {
  const kept = rows.filter((r) => r.t >= sinceS);
  return [kept.map((r) => r.t), ...keys.map((k) => kept.map((r) => r[k] ?? null))];
}

// A y range around [lo, hi] at least ``minSpan`` wide, with 10 % margin; no data: ±minSpan.
export function paddedRange(lo, hi, minSpan = 0.5) {
  if (lo === null || hi === null || !Number.isFinite(lo) || !Number.isFinite(hi)) {
    return [-minSpan, minSpan];
  }
  if (hi - lo < minSpan) { const m = (hi + lo) / 2; lo = m - minSpan / 2; hi = m + minSpan / 2; }
  const margin = (hi - lo) * 0.1;
  return [lo - margin, hi + margin];
}

// A time axis label: the local clock, 24 h (uPlot's default adds a date line).
export const clockTime = (tS) => new Date(tS * 1000).toLocaleTimeString([],
  { hour: "2-digit", minute: "2-digit", second: "2-digit", hour12: false });

const AXIS = { stroke: "#8193a5", grid: { stroke: "#1b242e", width: 1 },
  ticks: { stroke: "#1b242e", width: 1 } };

export class TimePlot {
  // ``series``: [{key, label, stroke}]; ``unit``: shown after legend values; ``emptyText``:
  // shown over the plot while no series has a value in the window.
  constructor(el, { series, unit, windowS = 60, height = 150, emptyText = "" }) {
    if (typeof uPlot !== "function") throw new Error("uPlot (static/vendor/uplot) did not load");
    this.el = el;
    this.keys = series.map((s) => s.key);
    this.windowS = windowS;
    this.live = true;
    this.empty = document.createElement("div");
    this.empty.className = "plot-empty hidden";
    this.empty.textContent = emptyText;
    const value = (u, v) => (v === null || v === undefined ? "—" : `${v.toFixed(2)} ${unit}`);
    const opts = {
      width: Math.max(200, el.clientWidth),
      height,
      scales: { x: { time: true }, y: { range: (u, lo, hi) => paddedRange(lo, hi) } },
      axes: [{ ...AXIS, values: (u, vals) => vals.map(clockTime) },
        { ...AXIS, size: 48, values: (u, vals) => vals.map((v) => v.toFixed(2)) }],
      // the cursor's time in the legend: the same clock as the axis, with seconds
      series: [{ label: "time", value: (u, v) => (v === null || v === undefined ? "—"
        : clockTime(v)) },
        ...series.map((s) => ({ label: s.label, stroke: s.stroke, width: 2, value }))],
      cursor: { drag: { x: true, y: false } },
      legend: { live: true },
      // a drag-selection zooms (uPlot's default): stop following the live data
      hooks: { setSelect: [(u) => { if (u.select.width > 0) this.live = false; }] },
    };
    this.plot = new uPlot(opts, columns([], this.keys), el);
    el.append(this.empty);
    this.plot.over.addEventListener("dblclick", () => { this.live = true; });
    new ResizeObserver(() => {
      const w = Math.max(200, el.clientWidth);
      if (w !== this.plot.width) this.plot.setSize({ width: w, height });
    }).observe(el);
    el.dataset.live = "true";
  }

  // New rows; while live, the x axis shows the last ``windowS`` seconds up to ``nowS``.
  update(rows, nowS) {
    const data = columns(rows, this.keys, nowS - 10 * this.windowS);
    this.plot.setData(data, false);
    if (this.live) this.plot.setScale("x", { min: nowS - this.windowS, max: nowS });
    else this.plot.redraw(true, false);
    const since = this.live ? nowS - this.windowS : this.plot.scales.x.min;
    const seen = data.slice(1).some((col) => col.some((v, i) => v !== null && data[0][i] >= since));
    this.empty.classList.toggle("hidden", seen);
    this.el.dataset.live = String(this.live);
    this.el.dataset.points = String(data[0].length);
  }
}
