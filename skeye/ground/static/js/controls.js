// The Flight card: every button with data-send="command" sends that command with the values of
// its fields (built from the table by forms.js) and the choices its data-set fixes.

import { guarded, send, showResult } from "./command.js";
import { $ } from "./dom.js";
import { fieldId, fixedArgs, readArgs } from "./forms.js";
import { S } from "./state.js";

function sendFrom(button) {
  const name = button.dataset.send;
  if (!S.commands) {
    showResult(name, {}, { ok: false, status: "not ready",
      error: "the command table has not arrived from the server yet" });
    return;
  }
  const command = S.commands.get(name);
  if (!command) throw new Error(`page layout: no command ${name} in the server's table`);
  guarded(name, () => send(name, readArgs(document, command,
    fixedArgs(command, button.dataset.set))))();
}

// "here": the vehicle's position estimate (INS anchored to its GPS fixes, GPS_DATA_ADVANCED),
// not the raw fix, which wanders metres; the note beside the button says which was used.
export function fillHere(gps, lat, lon, note) {
  if (!gps || !gps.fix) { note.textContent = "no GPS fix: nothing to fill in"; return; }
  const est = gps.estimate_latitude_deg !== null && gps.estimate_latitude_deg !== undefined;
  lat.value = (est ? gps.estimate_latitude_deg : gps.latitude_deg).toFixed(7);
  lon.value = (est ? gps.estimate_longitude_deg : gps.longitude_deg).toFixed(7);
  note.textContent = est ? "filled: the vehicle's position estimate"
    : `filled: the raw GPS fix (±${gps.horizontal_accuracy_m} m; no estimate from this vehicle)`;
  note.dataset.source = est ? "estimate" : "fix";
}

export function wireControls() {
  for (const button of document.querySelectorAll("button[data-send]")) {
    button.onclick = () => sendFrom(button);
  }
  $("g-here").onclick = () => {
    const lat = $(fieldId("goto_gps", "latitude_deg")), lon = $(fieldId("goto_gps", "longitude_deg"));
    if (!lat || !lon) { $("g-source").textContent = "the GPS fields are not built yet"; return; }
    fillHere(S.telemetry && S.telemetry.gps, lat, lon, $("g-source"));
  };
  $("map-clear").onclick = () => { S.track = []; };
}
