// Telemetry messages (SI, from skeye/ground/telemetry.py) to the page's readouts. ``readouts``
// is pure: telemetry in, [element id, text, data-value] out; only the display converts units.

import { $, banner, pill, setText } from "./dom.js";

export const fmt = (v, d = 2, unit = "") => (v === null || v === undefined || Number.isNaN(v))
  ? "—" : `${Number(v).toFixed(d)}${unit}`;

export const LINK_CLASSES = { connected: "good", connecting: "warn", refused: "bad",
  disconnected: "bad", closed: "bad" };
export const FLIGHT_CLASSES = { landed: "neutral", taking_off: "warn", flying: "good",
  holding: "good", landing: "warn", failsafe: "bad", manual: "warn",
  crashed: "bad" };

// The log line when the flight state changes to ``now`` from ``before`` (null: no line). The
// sticks take over from every automatic mode (docs/pilot.md): the page says from which.
export function stateChangeLine(before, now) {
  if (!before || before === now || now !== "manual") return null;
  return `vehicle: manual sticks took over (was ${before.replace("_", " ")})`;
}

// [id, text, value] for every readout the message carries (value undefined: text only).
export function readouts(t) {
  const out = [];
  const put = (id, text, value) => out.push([id, text, value]);
  const L = t.link;
  if (L) {
    put("lq-rate", fmt(L.packet_rate_hz, 0), L.packet_rate_hz);
    put("lq-rtt", L.round_trip_ms === null ? "—" : `${L.round_trip_ms.toFixed(0)} ms`);
    put("lq-age", L.last_packet_age_s === null ? "—" : `${L.last_packet_age_s.toFixed(1)} s`,
      L.last_packet_age_s);
    put("lq-errors", String(L.frame_errors), L.frame_errors);
    put("lq-connects", String(Math.max(0, L.connects - 1)), L.connects);
  }
  const n = t.nav, imu = t.imu, st = t.status, gps = t.gps;
  if (n) {
    put("ro-height", fmt(n.height_m, 2, " m"), n.height_m);
    put("ro-north", fmt(n.north_m, 2), n.north_m);
    put("ro-east", fmt(n.east_m, 2), n.east_m);
    put("ro-up", fmt(n.height_m, 2), n.height_m);
    put("ro-vn", fmt(n.vel_ned_m_s[0], 2));
    put("ro-ve", fmt(n.vel_ned_m_s[1], 2));
    put("ro-vd", fmt(n.vel_ned_m_s[2], 2));
    put("ro-speed", fmt(n.speed_m_s, 2, " m/s"), n.speed_m_s);
    put("ro-climb", fmt(n.climb_m_s, 2, " m/s"), n.climb_m_s);
    put("ro-battery", fmt(n.battery_v, 2, " V"), n.battery_v);
  }
  if (imu) {
    put("ro-roll", fmt(imu.roll_deg, 1, "°"), imu.roll_deg);
    put("ro-pitch", fmt(imu.pitch_deg, 1, "°"), imu.pitch_deg);
    put("ro-yaw", fmt(imu.yaw_deg, 1, "°"), imu.yaw_deg);
    put("ro-p", fmt(imu.rates_deg_s[0], 1, "°/s"));
    put("ro-q", fmt(imu.rates_deg_s[1], 1, "°/s"));
    put("ro-r", fmt(imu.rates_deg_s[2], 1, "°/s"));
    put("ro-ax", fmt(imu.acc_body_frd_m_s2[0], 2));
    put("ro-ay", fmt(imu.acc_body_frd_m_s2[1], 2));
    put("ro-az", fmt(imu.acc_body_frd_m_s2[2], 2));
    put("ro-baro", fmt(imu.baro_height_m, 2, " m"));
    put("ro-fused", fmt(imu.height_m, 2, " m"));
    put("ro-mag", fmt(imu.mag_heading_deg, 0, "°"));
  }
  if (st) {
    put("ro-motors", st.motors_on ? (st.flying ? "on · flying" : "on") : "off");
    const modes = [st.height_control ? "alt" : null, st.position_control ? "pos" : null]
      .filter(Boolean).join("+") || "att";
    put("ro-fmode", modes);
    put("ro-uptime", `${st.up_time_s} s`);
    if (!n) put("ro-battery", fmt(st.battery_v, 2, " V"), st.battery_v);
  }
  if (n) {
    const pm = n.sigma_h_m === null || n.sigma_h_m === undefined ? "± not stated"
      : `± ${n.sigma_h_m.toFixed(2)} m`;
    put("map-estimate", `estimate (onboard): N ${n.north_m.toFixed(2)} E ${n.east_m.toFixed(2)} ${pm}`,
      n.sigma_h_m);
  }
  const tr = t.truth;
  if (tr && n) {
    const off = Math.hypot(n.north_m - tr.north_m, n.east_m - tr.east_m);
    put("map-truth", `simulator truth: N ${tr.north_m.toFixed(2)} E ${tr.east_m.toFixed(2)} ` +
      `(estimate off by ${off.toFixed(2)} m)`, off);
  }
  const v = t.vehicle;
  put("vehicle-name", v ? `flying: ${v.description}${v.simulated ? "" : " (real vehicle)"}`
    : "flying: —");
  if (gps) {
    put("ro-latlon", `${gps.latitude_deg.toFixed(7)}, ${gps.longitude_deg.toFixed(7)}`);
    put("ro-gpsfix", gps.fix ? "3D fix" : "no fix");
    put("ro-gpsalt", fmt(gps.height_m, 1, " m"));
    put("ro-gpsacc", fmt(gps.horizontal_accuracy_m, 1, " m"));
    put("ro-sats", String(gps.num_sv));
  }
  return out;
}

// The pills of the top bar and the link banner.
export function showStatus(t) {
  const L = t.link;
  pill("link-state", `vehicle: ${L.state}`, LINK_CLASSES[L.state] || "bad", { state: L.state });
  $("link-state").title = L.last_error ? `${L.uri}: ${L.last_error}` : L.uri;
  // The vehicle's health (HEALTH: crashed or lost, and why) while it is not ok.
  const h = t.health;
  if (L.state === "refused") {
    banner(`The vehicle refused this ground station: ${L.last_error}`);
    $("banner").dataset.kind = "link";
  } else if (h && h.status !== "ok") {
    const what = h.status === "crashed" ? "Vehicle crashed" : "Vehicle lost";
    banner(`${what}: ${h.reason}${h.status === "crashed" ? " (Reset brings it back)" : ""}`);
    $("banner").dataset.kind = "health";
    $("banner").dataset.health = h.status;
  } else if (["link", "health"].includes($("banner").dataset.kind)) {
    banner("");
    $("banner").dataset.kind = "";
    $("banner").dataset.health = "";
  }
  // the truth marker's legend: only while the vehicle is simulated and sends its truth
  $("map-truth").hidden = !(t.truth && t.nav);
  const v = t.vehicle;
  $("vehicle-name").dataset.simulated = v ? (v.simulated ? "true" : "false") : "";
  const n = t.nav;
  if (n) {
    pill("flight-state", `state: ${n.state.replace("_", " ")}`,
      FLIGHT_CLASSES[n.state] || "neutral", { state: n.state });
    pill("pad-mode", `pad: ${n.pad_mode}`, n.pad_mode === "off" ? "neutral" : "warn",
      { mode: n.pad_mode });
  }
}

export function showReadouts(t) {
  showStatus(t);
  for (const [id, text, value] of readouts(t)) setText(id, text, value);
}
