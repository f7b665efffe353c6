// The artificial horizon of the Vehicle card (roll and pitch from IMU_CALCDATA).

import { $ } from "./dom.js";
import { S } from "./state.js";

export function drawHorizon() {
  const c = $("horizon"), g = c.getContext("2d");
  const W = c.width, R = W / 2;
  const imu = S.telemetry && S.telemetry.imu;
  const roll = imu ? imu.roll_deg * Math.PI / 180 : 0;
  const pitch = imu ? imu.pitch_deg : 0;
  g.save();
  g.beginPath(); g.arc(R, R, R - 2, 0, 2 * Math.PI); g.clip();
  g.translate(R, R); g.rotate(-roll);
  const off = pitch * (R / 45);
  g.fillStyle = "#2d6da3"; g.fillRect(-W, -W + off, 2 * W, W);
  g.fillStyle = "#6b4a2b"; g.fillRect(-W, off, 2 * W, W);
  g.strokeStyle = "#fff"; g.lineWidth = 2;
  g.beginPath(); g.moveTo(-W, off); g.lineTo(W, off); g.stroke();
  g.lineWidth = 1; g.font = "9px sans-serif"; g.fillStyle = "#fff";
  for (const p of [-20, -10, 10, 20]) {
    const y = off - p * (R / 45), w = Math.abs(p) === 10 ? 18 : 28;
    g.beginPath(); g.moveTo(-w, y); g.lineTo(w, y); g.stroke();
  }
  g.restore();
  g.strokeStyle = "#ffcc33"; g.lineWidth = 3;
  g.beginPath(); g.moveTo(R - 40, R); g.lineTo(R - 12, R); g.lineTo(R, R + 8);
  g.lineTo(R + 12, R); g.lineTo(R + 40, R); g.stroke();
  g.strokeStyle = "#3a4a5c"; g.lineWidth = 3;
  g.beginPath(); g.arc(R, R, R - 2, 0, 2 * Math.PI); g.stroke();
}
