// skeye ground control page: telemetry over /ws, camera over /ws/video, commands over /ws.
// Everything is drawn on canvases with no external library. Units are SI from the server;
// only the display converts (degrees, cm).
"use strict";

const $ = (id) => document.getElementById(id);
const fmt = (v, d = 2, unit = "") => (v === null || v === undefined || Number.isNaN(v))
  ? "—" : `${Number(v).toFixed(d)}${unit}`;
const RING_COLOURS = ["#ff5c5c", "#ffb23c", "#4fe08a", "#4fb3ff", "#c58cff", "#ffffff"];

// ---------------------------------------------------------------- state
const S = {
  telemetry: null,
  track: [],          // {north_m, east_m}
  series: [],         // {t, height, dx, dy}
  home: null,
  groundDet: null,    // this page's camera detection: {t, dx, dy}
  cmdId: 0,
  pending: new Map(), // id -> {name, args, resolve}
  ws: null,
  keys: new Set(),
};

function setText(id, text, value) {
  const el = $(id);
  el.textContent = text;
  if (value !== undefined) el.dataset.value = value === null ? "" : String(value);
}

function pill(id, text, cls, attrs = {}) {
  const el = $(id);
  el.textContent = text;
  el.className = `pill ${cls}`;
  for (const [k, v] of Object.entries(attrs)) el.dataset[k] = v;
}

function banner(text, ok = false) {
  const el = $("banner");
  if (!text) { el.classList.add("hidden"); return; }
  el.textContent = text;
  el.className = ok ? "banner ok" : "banner";
}

// ---------------------------------------------------------------- telemetry socket
function wsUrl(path) {
  return `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${path}`;
}

function connectTelemetry() {
  const ws = new WebSocket(wsUrl("/ws"));
  S.ws = ws;
  ws.onopen = () => pill("server-state", "server: online", "good", { state: "online" });
  ws.onclose = () => {
    pill("server-state", "server: offline", "bad", { state: "offline" });
    pill("link-state", "vehicle: unknown", "bad", { state: "unknown" });
    for (const [, p] of S.pending) p.resolve({ status: 503, error: "page lost its server" });
    S.pending.clear();
    setTimeout(connectTelemetry, 1000);
  };
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    if (msg.type === "telemetry") onTelemetry(msg);
    else if (msg.type === "hello") onHello(msg);
    else if (msg.type === "result") onResult(msg);
  };
}

// Inputs that carry a command argument with a vehicle limit (GET /api/commands "limit").
const LIMITED_INPUTS = {
  "velocity.forward_m_s": ["v-fwd"], "velocity.right_m_s": ["v-right"],
  "velocity.up_m_s": ["v-up"], "move_by.speed_m_s": ["m-speed"],
  "goto_gps.speed_m_s": ["g-speed"], "pad_mode.max_speed_m_s": ["p-speed"],
};

function applyLimits(commands) {
  const found = {};
  for (const c of commands) for (const a of c.args) {
    if (!a.limit) continue;
    found[a.limit.key] = a.limit;
    for (const id of LIMITED_INPUTS[`${c.name}.${a.name}`] || []) {
      if (a.max !== null) $(id).max = a.max;
      if (a.min !== null) $(id).min = a.min;
      $(id).title = `at most ${a.limit.value} (${a.limit.key}, ${a.limit.source})`;
    }
  }
  const speed = found.max_speed_m_s;
  if (speed) $("kbd-speed").max = speed.value;
  const parts = [];
  if (speed) parts.push(`speed ${speed.value} m/s`);
  if (found.max_climb_m_s) parts.push(`climb ${found.max_climb_m_s.value} m/s`);
  if (found.max_yaw_rate_rad_s) {
    parts.push(`yaw ${(found.max_yaw_rate_rad_s.value * 180 / Math.PI).toFixed(0)} °/s`);
  }
  const source = (speed || found.max_climb_m_s || {}).source;
  setText("limits", parts.length ? `vehicle limits: ${parts.join(" · ")} (${source})` : "",
    speed ? speed.value : null);
  S.limits = found;
}

function onHello(msg) {
  applyLimits(msg.commands);
  S.track = [];
  S.series = [];
  const now = performance.now() / 1000;
  const last = msg.history.length ? msg.history[msg.history.length - 1].t_s : 0;
  for (const p of msg.history) {
    S.track.push({ north_m: p.north_m, east_m: p.east_m });
    S.series.push({ t: now - (last - p.t_s), height: p.height_m,
      dx: p.pad_dx_m ?? null, dy: p.pad_dy_m ?? null });
  }
}

function onTelemetry(t) {
  S.telemetry = t;
  const L = t.link;
  const stateCls = { connected: "good", connecting: "warn", refused: "bad",
    disconnected: "bad", closed: "bad" }[L.state] || "bad";
  pill("link-state", `vehicle: ${L.state}`, stateCls, { state: L.state });
  $("link-state").title = L.last_error ? `${L.uri}: ${L.last_error}` : L.uri;
  setText("lq-rate", fmt(L.packet_rate_hz, 0), L.packet_rate_hz);
  setText("lq-rtt", L.round_trip_ms === null ? "—" : `${L.round_trip_ms.toFixed(0)} ms`);
  setText("lq-age", L.last_packet_age_s === null ? "—" : `${L.last_packet_age_s.toFixed(1)} s`,
    L.last_packet_age_s);
  setText("lq-errors", String(L.frame_errors), L.frame_errors);
  setText("lq-connects", String(Math.max(0, L.connects - 1)), L.connects);
  if (L.state === "refused") {
    banner(`The vehicle refused this ground station: ${L.last_error}`);
    $("banner").dataset.kind = "link";
  } else if ($("banner").dataset.kind === "link") {
    banner("");
    $("banner").dataset.kind = "";
  }

  const n = t.nav, imu = t.imu, st = t.status, gps = t.gps, pad = t.pad;
  if (n) {
    const fsCls = { landed: "neutral", taking_off: "warn", flying: "good", holding: "good",
      landing: "warn", failsafe: "bad" }[n.state] || "neutral";
    pill("flight-state", `state: ${n.state.replace("_", " ")}`, fsCls, { state: n.state });
    pill("pad-mode", `pad: ${n.pad_mode}`, n.pad_mode === "off" ? "neutral" : "warn",
      { mode: n.pad_mode });
    if (S.padMode === "land" && n.pad_mode === "off" && n.state === "landed") {
      logLine("pad landing finished: landed, pad mode back to off", "ok", "pad-landed");
    }
    S.padMode = n.pad_mode;
    setText("ro-height", fmt(n.height_m, 2, " m"), n.height_m);
    setText("ro-north", fmt(n.north_m, 2), n.north_m);
    setText("ro-east", fmt(n.east_m, 2), n.east_m);
    setText("ro-up", fmt(n.height_m, 2), n.height_m);
    setText("ro-vn", fmt(n.vel_ned_m_s[0], 2));
    setText("ro-ve", fmt(n.vel_ned_m_s[1], 2));
    setText("ro-vd", fmt(n.vel_ned_m_s[2], 2));
    setText("ro-speed", fmt(n.speed_m_s, 2, " m/s"), n.speed_m_s);
    setText("ro-climb", fmt(n.climb_m_s, 2, " m/s"), n.climb_m_s);
    setText("ro-battery", fmt(n.battery_v, 2, " V"), n.battery_v);
    const lastT = S.track[S.track.length - 1];
    if (!lastT || Math.hypot(lastT.north_m - n.north_m, lastT.east_m - n.east_m) > 0.02) {
      S.track.push({ north_m: n.north_m, east_m: n.east_m });
      if (S.track.length > 5000) S.track.shift();
    }
    if (!S.home && n.state !== "landed") S.home = { north_m: n.north_m, east_m: n.east_m };
    // pad offset: the vehicle's PAD estimate; without one, this page's camera detection
    const now = performance.now() / 1000, gd = S.groundDet;
    let dx = null, dy = null;
    if (pad && pad.found) { dx = pad.dx_m; dy = pad.dy_m; }
    else if (gd && now - gd.t < 1.0) { dx = gd.dx; dy = gd.dy; }
    S.series.push({ t: now, height: n.height_m, dx, dy });
    if (S.series.length > 3000) S.series.shift();
  }
  if (imu) {
    setText("ro-roll", fmt(imu.roll_deg, 1, "°"), imu.roll_deg);
    setText("ro-pitch", fmt(imu.pitch_deg, 1, "°"), imu.pitch_deg);
    setText("ro-yaw", fmt(imu.yaw_deg, 1, "°"), imu.yaw_deg);
    setText("ro-p", fmt(imu.rates_deg_s[0], 1, "°/s"));
    setText("ro-q", fmt(imu.rates_deg_s[1], 1, "°/s"));
    setText("ro-r", fmt(imu.rates_deg_s[2], 1, "°/s"));
    setText("ro-ax", fmt(imu.acc_body_frd_m_s2[0], 2));
    setText("ro-ay", fmt(imu.acc_body_frd_m_s2[1], 2));
    setText("ro-az", fmt(imu.acc_body_frd_m_s2[2], 2));
    setText("ro-baro", fmt(imu.baro_height_m, 2, " m"));
    setText("ro-fused", fmt(imu.height_m, 2, " m"));
    setText("ro-mag", fmt(imu.mag_heading_deg, 0, "°"));
  }
  if (st) {
    setText("ro-motors", st.motors_on ? (st.flying ? "on · flying" : "on") : "off");
    const modes = [st.height_control ? "alt" : null, st.position_control ? "pos" : null]
      .filter(Boolean).join("+") || "att";
    setText("ro-fmode", modes);
    setText("ro-uptime", `${st.up_time_s} s`);
    if (!n) setText("ro-battery", fmt(st.battery_v, 2, " V"), st.battery_v);
  }
  if (gps) {
    setText("ro-latlon", `${gps.latitude_deg.toFixed(7)}, ${gps.longitude_deg.toFixed(7)}`);
    setText("ro-gpsfix", gps.fix ? "3D fix" : "no fix");
    setText("ro-gpsalt", fmt(gps.height_m, 1, " m"));
    setText("ro-gpsacc", fmt(gps.horizontal_accuracy_m, 1, " m"));
    setText("ro-sats", String(gps.num_sv));
  }
  if (!t.video) $("video-state").textContent = "no video source";
}

// ---------------------------------------------------------------- commands
function send(name, args = {}) {
  return new Promise((resolve) => {
    if (!S.ws || S.ws.readyState !== WebSocket.OPEN) {
      resolve({ status: 503, error: "the page is not connected to its server" });
      return;
    }
    const id = ++S.cmdId;
    S.pending.set(id, { name, args, resolve });
    S.ws.send(JSON.stringify({ type: "command", id, name, args }));
  }).then((r) => { showResult(name, args, r); return r; });
}

function onResult(msg) {
  const p = S.pending.get(msg.id);
  if (!p) { if (msg.error) showResult("?", {}, msg); return; }
  S.pending.delete(msg.id);
  p.resolve(msg);
}

function showResult(name, args, r) {
  const el = $("last-result");
  const argText = Object.entries(args).map(([k, v]) => `${k}=${v}`).join(" ");
  let text, cls;
  if (r.ok) {
    text = `${name}: accepted`;
    cls = "ok";
  } else if (r.code !== undefined && r.code !== 0 && r.reason !== undefined) {
    text = `${name}: REFUSED by the vehicle — code ${r.code} ${r.code_name}: ${r.reason}`;
    cls = "bad";
  } else {
    text = `${name}: not sent (${r.status}) — ${r.error}`;
    cls = "bad";
  }
  el.textContent = text;
  el.className = `result ${cls}`;
  el.dataset.ok = r.ok ? "true" : "false";
  el.dataset.code = r.code ?? "";
  el.dataset.command = name;
  logLine(`${text}${argText ? `  [${argText}]` : ""}`, cls, name);
}

// One line per change: an answer identical to the newest line (a held key renews the same
// velocity every few hundred ms) counts up "×n" on that line instead of adding another.
function logLine(text, cls, kind) {
  const log = $("cmd-log"), top = log.firstElementChild;
  const t = new Date().toLocaleTimeString();
  if (top && top.dataset.text === text) {
    const n = Number(top.dataset.repeats) + 1;
    top.dataset.repeats = String(n);
    top.children[0].textContent = t;
    top.children[2].textContent = ` ×${n}`;
    return;
  }
  const li = document.createElement("li");
  li.innerHTML = `<span class="t"></span><span class="${cls}"></span><span class="dim"></span>`;
  li.children[0].textContent = t;
  li.children[1].textContent = text;
  li.dataset.text = text;
  li.dataset.kind = kind;
  li.dataset.repeats = "1";
  log.prepend(li);
  while (log.children.length > 100) log.lastChild.remove();
}

// A blank (or unparsable) field is "not given", never a zero: the command is not sent and
// the log says which field to fill in.
class BlankField extends Error {}
const num = (id) => {
  const v = $(id).valueAsNumber;
  if (Number.isFinite(v)) return v;
  const label = $(id).closest("label");
  const what = label ? label.firstChild.textContent.trim() : id;
  throw new BlankField(`the "${what}" field is ${$(id).value === "" ? "blank" : "not a number"}`
    + "; fill it in (0 where you mean none)");
};
const rad = (deg) => deg * Math.PI / 180;

// Run a control's handler; a blank field refuses the command on the page, visibly.
function guarded(name, fn) {
  return () => {
    try { fn(); } catch (e) {
      if (!(e instanceof BlankField)) throw e;
      showResult(name, {}, { ok: false, status: "blank field", error: e.message });
    }
  };
}

function wireControls() {
  $("btn-takeoff").onclick = guarded("take_off", () => send("take_off", { height_m: num("to-height") }));
  $("btn-hold").onclick = () => send("hold");
  $("btn-land").onclick = () => send("land");
  $("btn-velocity").onclick = guarded("velocity", () => send("velocity", {
    forward_m_s: num("v-fwd"), right_m_s: num("v-right"), up_m_s: num("v-up"),
    yaw_rate_rad_s: rad(num("v-yaw")), duration_s: num("v-dur"),
  }));
  $("btn-move").onclick = guarded("move_by", () => send("move_by", {
    forward_m: num("m-fwd"), right_m: num("m-right"), up_m: num("m-up"),
    yaw_rad: rad(num("m-yaw")), frame: $("m-frame").value, speed_m_s: num("m-speed"),
  }));
  // "here": the vehicle's position estimate (INS anchored to its GPS fixes, GPS_DATA_ADVANCED),
  // not the raw fix, which wanders metres; the note beside the button says which was used.
  $("g-here").onclick = () => {
    const g = S.telemetry && S.telemetry.gps;
    if (!g || !g.fix) { $("g-source").textContent = "no GPS fix: nothing to fill in"; return; }
    const est = g.estimate_latitude_deg !== null && g.estimate_latitude_deg !== undefined;
    $("g-lat").value = (est ? g.estimate_latitude_deg : g.latitude_deg).toFixed(7);
    $("g-lon").value = (est ? g.estimate_longitude_deg : g.longitude_deg).toFixed(7);
    $("g-source").textContent = est ? "filled: the vehicle's position estimate"
      : `filled: the raw GPS fix (±${g.horizontal_accuracy_m} m; no estimate from this vehicle)`;
    $("g-source").dataset.source = est ? "estimate" : "fix";
  };
  $("btn-goto").onclick = guarded("goto_gps", () => send("goto_gps", {
    latitude_deg: num("g-lat"), longitude_deg: num("g-lon"), height_m: num("g-height"),
    speed_m_s: num("g-speed"),
  }));
  const pad = (mode) => guarded("pad_mode", () => send("pad_mode", {
    mode, deadband_m: num("p-deadband"), max_speed_m_s: num("p-speed"),
  }))();
  $("btn-pad-hold").onclick = () => pad("hold");
  $("btn-pad-land").onclick = () => pad("land");
  $("btn-pad-off").onclick = () => pad("off");
  $("map-clear").onclick = () => { S.track = []; };
  wireKeyboard();
}

// ---------------------------------------------------------------- keyboard velocity control
const KEYMAP = {
  KeyW: ["fwd", 1], ArrowUp: ["fwd", 1], KeyS: ["fwd", -1], ArrowDown: ["fwd", -1],
  KeyD: ["right", 1], ArrowRight: ["right", 1], KeyA: ["right", -1], ArrowLeft: ["right", -1],
  KeyR: ["up", 1], KeyF: ["up", -1], KeyE: ["yaw", 1], KeyQ: ["yaw", -1],
};
const KBD_YAW_RAD_S = 0.6;
const KBD_REPEAT_MS = 300;
let kbdTimer = null;

function keyboardActive() {
  const tag = document.activeElement && document.activeElement.tagName;
  return $("kbd-enable").checked && tag !== "INPUT" && tag !== "SELECT";
}

function kbdVelocity() {
  const v = { fwd: 0, right: 0, up: 0, yaw: 0 };
  for (const code of S.keys) { const [axis, sign] = KEYMAP[code]; v[axis] += sign; }
  return v;
}

function kbdSend(final = false) {
  const v = kbdVelocity();
  let speed;
  try { speed = num("kbd-speed"); } catch (e) {
    if (!(e instanceof BlankField)) throw e;
    speed = 0;  // a release still stops the vehicle; a key press sends nothing
    if (!final) {
      showResult("velocity", {}, { ok: false, status: "blank field", error: e.message });
      return;
    }
  }
  const moving = v.fwd || v.right || v.up || v.yaw;
  $("kbd-state").textContent = moving
    ? `fwd ${v.fwd * speed} · right ${v.right * speed} · up ${v.up * speed} · yaw ${v.yaw}` : "";
  if (!moving && !final) return;
  // A short duration, renewed while keys are held, so a lost page or link stops the vehicle.
  send("velocity", {
    forward_m_s: v.fwd * speed, right_m_s: v.right * speed, up_m_s: v.up * speed,
    yaw_rate_rad_s: v.yaw * KBD_YAW_RAD_S, duration_s: moving ? 1.0 : 0,
  });
}

function wireKeyboard() {
  $("kbd-enable").onchange = (e) => {
    $("kbd-enable").closest(".kbd").classList.toggle("active", e.target.checked);
    e.target.blur();
  };
  document.addEventListener("keydown", (e) => {
    if (!keyboardActive()) return;
    if (e.code === "Space") { e.preventDefault(); S.keys.clear(); send("hold"); return; }
    if (!(e.code in KEYMAP)) return;
    e.preventDefault();
    if (S.keys.has(e.code)) return;
    S.keys.add(e.code);
    kbdSend();
    clearInterval(kbdTimer);
    kbdTimer = setInterval(() => kbdSend(), KBD_REPEAT_MS);
  });
  document.addEventListener("keyup", (e) => {
    if (!(e.code in KEYMAP) || !S.keys.has(e.code)) return;
    S.keys.delete(e.code);
    if (S.keys.size === 0) { clearInterval(kbdTimer); kbdSend(true); } else kbdSend();
  });
  window.addEventListener("blur", () => {
    if (S.keys.size) { S.keys.clear(); clearInterval(kbdTimer); kbdSend(true); }
  });
}

// ---------------------------------------------------------------- camera
const camera = { frame: null, meta: null, bitmap: null, nextMeta: null };

function connectVideo() {
  const ws = new WebSocket(wsUrl("/ws/video"));
  ws.binaryType = "arraybuffer";
  ws.onclose = () => {
    $("video-state").textContent = "video: reconnecting";
    setTimeout(connectVideo, 1500);
  };
  ws.onmessage = async (ev) => {
    if (typeof ev.data === "string") {
      const msg = JSON.parse(ev.data);
      if (msg.type === "frame") camera.nextMeta = msg;
      else if (msg.type === "status") $("video-state").textContent = msg.state;
      return;
    }
    const meta = camera.nextMeta;
    const bitmap = await createImageBitmap(new Blob([ev.data], { type: "image/jpeg" }));
    if (camera.bitmap) camera.bitmap.close();
    camera.bitmap = bitmap;
    camera.meta = meta;
    drawCamera();
    onDetection(meta);
  };
}

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
    (meta.sim_time_s !== null ? ` · t ${meta.sim_time_s.toFixed(1)} s` : "");
  $("video-info").textContent = `${meta.width}×${meta.height} · ${(meta.bytes / 1024).toFixed(0)} kB`;
  const d = meta.detection;
  S.groundDet = d.found && d.offset_body_m
    ? { t: performance.now() / 1000, dx: d.offset_body_m[0], dy: d.offset_body_m[1] } : null;
  pill("det-found", d.found ? "pad: DETECTED" : "pad: not seen", d.found ? "good" : "neutral",
    { found: String(d.found) });
  setText("det-rings", d.rings.length ? d.rings.join(",") : "—", d.rings.length);
  setText("det-offset", d.offset_body_m
    ? `fwd ${d.offset_body_m[0].toFixed(2)} · right ${d.offset_body_m[1].toFixed(2)} m` : "—");
  setText("det-height", fmt(d.height_m, 2, " m"));
  setText("det-quality", fmt(d.quality, 2));
  setText("det-ms", `${meta.detect_ms.toFixed(0)} ms`);
}

// ---------------------------------------------------------------- map
function drawMap() {
  const c = $("map"), g = c.getContext("2d");
  const W = c.width, H = c.height;
  g.clearRect(0, 0, W, H);
  const n = S.telemetry && S.telemetry.nav;
  const pts = S.track.slice();
  if (n) pts.push({ north_m: n.north_m, east_m: n.east_m });
  // fit: centre on the vehicle's surroundings, at least +-3 m, always include the origin
  let minN = -1, maxN = 1, minE = -1, maxE = 1;
  for (const p of pts) {
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
  // vehicle
  if (n) {
    const yaw = n.yaw_deg * Math.PI / 180;
    g.save(); g.translate(X(n.east_m), Y(n.north_m)); g.rotate(yaw);
    g.fillStyle = "#ffffff"; g.strokeStyle = "#0b1015"; g.lineWidth = 2;
    g.beginPath(); g.moveTo(0, -14); g.lineTo(9, 10); g.lineTo(0, 5); g.lineTo(-9, 10);
    g.closePath(); g.fill(); g.stroke(); g.restore();
    g.fillStyle = "#d8e0e8";
    g.fillText(`N ${n.north_m.toFixed(2)}  E ${n.east_m.toFixed(2)}  ↑ ${n.height_m.toFixed(2)} m`, 8, 16);
  }
}

// ---------------------------------------------------------------- attitude indicator
function drawHorizon() {
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

// ---------------------------------------------------------------- plots
function drawPlot(id, series, colours, windowS = 60) {
  const c = $(id), g = c.getContext("2d");
  const W = c.width, H = c.height, padL = 40, padB = 16;
  g.clearRect(0, 0, W, H);
  const now = performance.now() / 1000;
  const data = S.series.filter((p) => p.t >= now - windowS);
  let lo = Infinity, hi = -Infinity;
  for (const p of data) for (const k of series) {
    const v = p[k];
    if (v !== null && v !== undefined) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
  }
  if (!Number.isFinite(lo)) { lo = -0.5; hi = 0.5; }
  if (hi - lo < 0.5) { const m = (hi + lo) / 2; lo = m - 0.25; hi = m + 0.25; }
  const margin = (hi - lo) * 0.1; lo -= margin; hi += margin;
  const X = (t) => padL + (W - padL - 6) * (1 - (now - t) / windowS);
  const Y = (v) => 6 + (H - padB - 6) * (1 - (v - lo) / (hi - lo));
  g.font = "10px sans-serif"; g.fillStyle = "#5d6e80"; g.strokeStyle = "#1b242e"; g.lineWidth = 1;
  for (let i = 0; i <= 4; i++) {
    const v = lo + (hi - lo) * i / 4;
    g.beginPath(); g.moveTo(padL, Y(v)); g.lineTo(W, Y(v)); g.stroke();
    g.fillText(v.toFixed(2), 2, Y(v) + 3);
  }
  for (let s = 0; s <= windowS; s += 10) g.fillText(`-${s}s`, X(now - s) - 10, H - 3);
  if (lo < 0 && hi > 0) {
    g.strokeStyle = "#3a4a5c"; g.beginPath(); g.moveTo(padL, Y(0)); g.lineTo(W, Y(0)); g.stroke();
  }
  series.forEach((k, i) => {
    g.strokeStyle = colours[i]; g.lineWidth = 2; g.beginPath();
    let pen = false;
    for (const p of data) {
      const v = p[k];
      if (v === null || v === undefined) { pen = false; continue; }
      if (pen) g.lineTo(X(p.t), Y(v)); else g.moveTo(X(p.t), Y(v));
      pen = true;
    }
    g.stroke();
  });
  if (series.includes("dx") && !data.some((p) => p.dx !== null)) {
    g.fillStyle = "#8193a5"; g.font = "12px sans-serif";
    g.fillText("no pad estimate (vehicle PAD or camera)", padL + 12, H / 2);
  }
}

function frame() {
  drawMap();
  drawHorizon();
  drawPlot("plot-height", ["height"], ["#4fb3ff"]);
  drawPlot("plot-pad", ["dx", "dy"], ["#4fb3ff", "#f0b43c"]);
  requestAnimationFrame(frame);
}

wireControls();
connectTelemetry();
connectVideo();
requestAnimationFrame(frame);
