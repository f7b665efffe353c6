// The camera card: the newest frame with the landing-pad detection drawn over it (each ring
// border an ellipse, colour per ring; the pad centre a green cross, dashed to the image
// centre) and the detection's readouts. Frames come from video.js.

import { $, pill, setText } from "./dom.js";
import { S } from "./state.js";
import { fmt } from "./telemetry.js";

const RING_COLOURS = ["#ff5c5c", "#ffb23c", "#4fe08a", "#4fb3ff", "#c58cff", "#ffffff"];

export const camera = { meta: null, bitmap: null };
window.camera = camera;

export function showFrame({ bitmap, meta }) {
  if (camera.bitmap) camera.bitmap.close();
  camera.bitmap = bitmap;
  camera.meta = meta;
  drawCamera();
  onDetection(meta);
}

export function showVideoState(text) { $("video-state").textContent = text; }

function drawCamera() {
  const c = $("camera"), g = c.getContext("2d");
  const bm = camera.bitmap, meta = camera.meta;
  if (!bm) return;
  if (c.width !== bm.width || c.height !== bm.height) { c.width = bm.width; c.height = bm.height; }
  g.drawImage(bm, 0, 0);
  const det = meta && meta.detection;
  const lw = Math.max(2, bm.width / 300);
  if (det && det.ellipses) {
    for (const e of det.ellipses) {
      g.strokeStyle = RING_COLOURS[(e.ring - 1) % RING_COLOURS.length];
      g.lineWidth = e.border === "outer" ? lw : lw * 0.6;
      g.setLineDash(e.border === "outer" ? [] : [6, 4]);
      g.beginPath();
      g.ellipse(e.center_px[0], e.center_px[1], e.semi_axes_px[0], e.semi_axes_px[1],
        e.angle_rad, 0, 2 * Math.PI);
      g.stroke();
    }
    g.setLineDash([]);
  }
  // the image centre (straight below the camera) and the pad centre
  const cx = bm.width / 2, cy = bm.height / 2, s = bm.width / 40;
  g.strokeStyle = "rgba(255,255,255,.6)"; g.lineWidth = 1;
  g.beginPath(); g.moveTo(cx - s, cy); g.lineTo(cx + s, cy); g.moveTo(cx, cy - s); g.lineTo(cx, cy + s);
  g.stroke();
  if (det && det.found && det.center_px) {
    const [px, py] = det.center_px;
    g.strokeStyle = "#00ff9c"; g.lineWidth = lw;
    g.beginPath(); g.moveTo(px - 2 * s, py); g.lineTo(px + 2 * s, py);
    g.moveTo(px, py - 2 * s); g.lineTo(px, py + 2 * s); g.stroke();
    g.beginPath(); g.arc(px, py, s * 0.6, 0, 2 * Math.PI); g.stroke();
    g.setLineDash([4, 4]); g.beginPath(); g.moveTo(cx, cy); g.lineTo(px, py); g.stroke();
    g.setLineDash([]);
  }
}

function onDetection(meta) {
  if (!meta) return;
  $("video-state").textContent = `frame ${meta.frame_number ?? meta.seq}` +
    (meta.sim_time_s !== null && meta.sim_time_s !== undefined
      ? ` · t ${meta.sim_time_s.toFixed(1)} s` : "");
  $("video-info").textContent = `${meta.width}×${meta.height} · ${(meta.bytes / 1024).toFixed(0)} kB`;
  const d = meta.detection;
  S.groundDet = d.found && d.offset_body_m
    ? { t: Date.now() / 1000, dx: d.offset_body_m[0], dy: d.offset_body_m[1] } : null;
  pill("det-found", d.found ? "pad: DETECTED" : "pad: not seen", d.found ? "good" : "neutral",
    { found: String(d.found) });
  setText("det-rings", d.rings.length ? d.rings.join(",") : "—", d.rings.length);
  setText("det-offset", d.offset_body_m
    ? `fwd ${d.offset_body_m[0].toFixed(2)} · right ${d.offset_body_m[1].toFixed(2)} m` : "—");
  setText("det-height", fmt(d.height_m, 2, " m"));
  setText("det-quality", fmt(d.quality, 2));
  setText("det-ms", `${meta.detect_ms.toFixed(0)} ms`);
}
