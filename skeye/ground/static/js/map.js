// The Track card: top-down map, north up, auto-scaled grid, the world origin (the default
// world's pad), home, the drawn track and the vehicle with its heading: where its onboard
// estimate puts it, with the estimator's 1-sigma as a circle, and, for a simulated vehicle,
// the simulator's truth as a separate marker (the legend under the map names both).

import { $ } from "./dom.js";
import { S } from "./state.js";

export function drawMap() {
  const c = $("map"), g = c.getContext("2d");
  const W = c.width, H = c.height;
  g.clearRect(0, 0, W, H);
  const n = S.telemetry && S.telemetry.nav;
  const tr = S.telemetry && S.telemetry.truth;
  const pts = S.track.slice();
  if (n) pts.push({ north_m: n.north_m, east_m: n.east_m });
  const fit = tr ? pts.concat([{ north_m: tr.north_m, east_m: tr.east_m }]) : pts;
  // fit: centre on the vehicle's surroundings, at least +-3 m, always include the origin
  let minN = -1, maxN = 1, minE = -1, maxE = 1;
  for (const p of fit) {
    minN = Math.min(minN, p.north_m); maxN = Math.max(maxN, p.north_m);
    minE = Math.min(minE, p.east_m); maxE = Math.max(maxE, p.east_m);
  }
  const span = Math.max(6, (maxN - minN) * 1.2, (maxE - minE) * 1.2);
  const cN = (minN + maxN) / 2, cE = (minE + maxE) / 2;
  const scale = (Math.min(W, H) - 40) / span;
  const X = (e) => W / 2 + (e - cE) * scale;
  const Y = (nn) => H / 2 - (nn - cN) * scale;
  // grid
  const step = [0.5, 1, 2, 5, 10, 20, 50, 100].find((s) => s * scale >= 40) || 200;
  g.lineWidth = 1; g.font = "11px sans-serif"; g.fillStyle = "#5d6e80";
  for (let e = Math.ceil((cE - span) / step) * step; e <= cE + span; e += step) {
    g.strokeStyle = Math.abs(e) < 1e-9 ? "#3a4a5c" : "#1b242e";
    g.beginPath(); g.moveTo(X(e), 0); g.lineTo(X(e), H); g.stroke();
  }
  for (let nn = Math.ceil((cN - span) / step) * step; nn <= cN + span; nn += step) {
    g.strokeStyle = Math.abs(nn) < 1e-9 ? "#3a4a5c" : "#1b242e";
    g.beginPath(); g.moveTo(0, Y(nn)); g.lineTo(W, Y(nn)); g.stroke();
  }
  g.fillText(`grid ${step} m`, 8, H - 8);
  g.fillText("N ↑", W - 30, 16);
  // origin (world reference, where the default world's pad lies) and home
  g.strokeStyle = "#c58cff"; g.lineWidth = 2;
  g.beginPath(); g.arc(X(0), Y(0), Math.max(6, 0.4 * scale), 0, 2 * Math.PI); g.stroke();
  g.fillStyle = "#c58cff"; g.fillText("origin", X(0) + 8, Y(0) - 8);
  if (S.home) {
    g.fillStyle = "#39c27a";
    g.fillRect(X(S.home.east_m) - 4, Y(S.home.north_m) - 4, 8, 8);
  }
  // track
  if (pts.length > 1) {
    g.strokeStyle = "#4fb3ff"; g.lineWidth = 2; g.beginPath();
    pts.forEach((p, i) => (i ? g.lineTo : g.moveTo).call(g, X(p.east_m), Y(p.north_m)));
    g.stroke();
  }
  // the simulator's truth: a hollow orange diamond with its heading tick
  if (tr) {
    const x = X(tr.east_m), y = Y(tr.north_m), yaw = tr.yaw_deg * Math.PI / 180;
    g.strokeStyle = "#ffa23a"; g.lineWidth = 2; g.beginPath();
    g.moveTo(x, y - 9); g.lineTo(x + 9, y); g.lineTo(x, y + 9); g.lineTo(x - 9, y); g.closePath();
    g.moveTo(x, y); g.lineTo(x + 16 * Math.sin(yaw), y - 16 * Math.cos(yaw)); g.stroke();
    g.fillStyle = "#ffa23a"; g.fillText("simulator truth", x + 12, y + 14);
  }
  // the estimate's 1-sigma (horizontal): a circle around the vehicle
  if (n && n.sigma_h_m) {
    g.strokeStyle = "rgba(255,255,255,0.45)"; g.fillStyle = "rgba(255,255,255,0.08)";
    g.lineWidth = 1; g.beginPath();
    g.arc(X(n.east_m), Y(n.north_m), Math.max(2, n.sigma_h_m * scale), 0, 2 * Math.PI);
    g.fill(); g.stroke();
  }
  // vehicle (its onboard estimate)
  if (n) {
    const yaw = n.yaw_deg * Math.PI / 180;
    g.save(); g.translate(X(n.east_m), Y(n.north_m)); g.rotate(yaw);
    g.fillStyle = "#ffffff"; g.strokeStyle = "#0b1015"; g.lineWidth = 2;
    g.beginPath(); g.moveTo(0, -14); g.lineTo(9, 10); g.lineTo(0, 5); g.lineTo(-9, 10);
    g.closePath(); g.fill(); g.stroke(); g.restore();
    g.fillStyle = "#d8e0e8";
    g.textAlign = "right"; g.fillText("estimate", X(n.east_m) - 12, Y(n.north_m) - 10);
    g.textAlign = "left";
    g.fillText(`N ${n.north_m.toFixed(2)}  E ${n.east_m.toFixed(2)}  ↑ ${n.height_m.toFixed(2)} m`, 8, 16);
  }
}
