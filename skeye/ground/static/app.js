// skeye ground control page, the entry module: telemetry and commands over /ws, the camera
// through video.js, forms built from the server's command table (forms.js). Native ES modules,
// no build step, nothing loaded from elsewhere; the one library, uPlot, is vendored under
// static/vendor/uplot. Units are SI from the server; only the display converts.

import { failPending, onResult } from "./js/command.js";
import { $, banner, pill, setText, wsUrl } from "./js/dom.js";
import { eventLine } from "./js/events.js";
import { showFrame, showVideoState } from "./js/camera.js";
import { wireControls } from "./js/controls.js";
import { indexCommands, limitsSummary, renderForms } from "./js/forms.js";
import { drawHorizon } from "./js/horizon.js";
import { renderKeyboard, wireKeyboard } from "./js/keyboard.js";
import { drawMap } from "./js/map.js";
import { TimePlot } from "./js/plots.js";
import { S } from "./js/state.js";
import { showReadouts, stateChangeLine } from "./js/telemetry.js";
import { connectVideo } from "./js/video.js";

const PLOT_WINDOW_S = 60;
const PLOT_PERIOD_MS = 200;
const nowS = () => Date.now() / 1000;

function onHello(msg) {
  S.hellos += 1;
  S.commands = indexCommands(msg.commands);
  S.keyboard = msg.keyboard;
  S.maxInFlight = msg.max_in_flight;
  renderForms(document, S.commands);
  renderKeyboard(msg.keyboard);
  const limits = limitsSummary(msg.commands);
  setText("limits", limits.text, limits.speed);
  S.track = [];
  S.series = [];
  const now = nowS();
  const last = msg.history.length ? msg.history[msg.history.length - 1].t_s : 0;
  for (const p of msg.history) {
    S.track.push({ north_m: p.north_m, east_m: p.east_m });
    S.series.push({ t: now - (last - p.t_s), height: p.height_m,
      dx: p.pad_dx_m ?? null, dy: p.pad_dy_m ?? null });
  }
}

function onTelemetry(t) {
  S.telemetry = t;
  showReadouts(t);
  const n = t.nav, pad = t.pad;
  if (n) {
    if (S.padMode === "land" && n.pad_mode === "off" && n.state === "landed") {
      eventLine("pad-landed", "pad landing finished: landed, pad mode back to off", "ok");
    }
    S.padMode = n.pad_mode;
    const change = stateChangeLine(S.flightState, n.state);
    if (change) eventLine("takeover", change, "bad");
    S.flightState = n.state;
    // the pilot says its detections come too late to hold on (PAD vision flag)
    const slow = Boolean(pad && pad.vision_too_slow);
    if (slow !== Boolean(S.visionSlow)) {
      if (slow) {
        eventLine("vision", "vision too slow to hold (detections too late to use): pad " +
                  "navigation holds still", "bad");
      } else {
        eventLine("vision", "vision in time again: pad navigation resumes", "ok");
      }
      S.visionSlow = slow;
    }
    const lastT = S.track[S.track.length - 1];
    if (!lastT || Math.hypot(lastT.north_m - n.north_m, lastT.east_m - n.east_m) > 0.02) {
      S.track.push({ north_m: n.north_m, east_m: n.east_m });
      if (S.track.length > 5000) S.track.shift();
    }
    if (!S.home && n.state !== "landed") S.home = { north_m: n.north_m, east_m: n.east_m };
    // pad offset: the vehicle's PAD estimate; without one, this page's camera detection
    const now = nowS(), gd = S.groundDet;
    let dx = null, dy = null;
    if (pad && pad.found) { dx = pad.dx_m; dy = pad.dy_m; }
    else if (gd && now - gd.t < 1.0) { dx = gd.dx; dy = gd.dy; }
    S.series.push({ t: now, height: n.height_m, dx, dy });
    if (S.series.length > 3000) S.series.shift();
  }
  if (!t.video) showVideoState("no video source");
}

function connectTelemetry() {
  const ws = new WebSocket(wsUrl("/ws"));
  S.ws = ws;
  ws.onopen = () => pill("server-state", "server: online", "good", { state: "online" });
  ws.onclose = () => {
    pill("server-state", "server: offline", "bad", { state: "offline" });
    pill("link-state", "vehicle: unknown", "bad", { state: "unknown" });
    failPending();
    // A restarted server has a new token: say so instead of retrying silently.
    fetch("/api/state").then((r) => {
      if (r.status === 401) {
        banner("This page's access token is no longer valid: open the URL (with ?token=...) " +
          "that skeye ground or skeye up printed when it started.");
      }
    }).catch(() => {});
    setTimeout(connectTelemetry, 1000);
  };
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    if (msg.type === "telemetry") onTelemetry(msg);
    else if (msg.type === "hello") onHello(msg);
    else if (msg.type === "result") onResult(msg);
  };
}

const plots = {
  height: new TimePlot($("plot-height"), {
    series: [{ key: "height", label: "height above ground", stroke: "#4fb3ff" }],
    unit: "m", windowS: PLOT_WINDOW_S,
  }),
  pad: new TimePlot($("plot-pad"), {
    series: [{ key: "dx", label: "forward", stroke: "#4fb3ff" },
      { key: "dy", label: "right", stroke: "#f0b43c" }],
    unit: "m", windowS: PLOT_WINDOW_S, emptyText: "no pad estimate (vehicle PAD or camera)",
  }),
};
window.plots = plots;

let lastPlotMs = 0;
function frame(ms) {
  drawMap();
  drawHorizon();
  if (ms - lastPlotMs >= PLOT_PERIOD_MS) {
    lastPlotMs = ms;
    for (const p of Object.values(plots)) p.update(S.series, nowS());
  }
  requestAnimationFrame(frame);
}

wireControls();
wireKeyboard();
connectTelemetry();
connectVideo({ onFrame: showFrame, onStatus: showVideoState });
requestAnimationFrame(frame);
