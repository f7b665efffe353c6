// Command forms built from the server's command table (GET /api/commands, the WebSocket
// "hello"): skeye/ground/commands.py is the one source of every field's label, unit, range
// (with the vehicle's limits), step, starting value and help. index.html only says where each
// command's fields go (data-form="name", a data-fields slot) and which buttons send it
// (data-send="name", data-set="arg=choice" for an argument a button fixes).
//
// Values: a field shows its argument in the table's display unit (°/s for a rad/s rate); the
// page converts back to SI before sending. A blank field is "not given": BlankField, and the
// command is not sent. A number out of range is still sent: the server's check is the one
// that counts and its answer names the argument and the limit; the field is only marked.

import { factor, fromDisplay, toDisplay } from "./units.js";

export class BlankField extends Error {}

export const fieldId = (command, arg) => `arg-${command}-${arg}`;

// The table as a map name -> command, with each argument's SI unit checked against the page's
// conversions (a unit the page cannot show is an error at once, not a wrong number later).
export function indexCommands(commands) {
  const table = new Map();
  for (const c of commands) {
    for (const a of c.args) if (!a.choices) factor(a.si_unit, a.unit);
    table.set(c.name, c);
  }
  return table;
}

// [min, max] of an argument in its display unit (null: unbounded).
export function displayRange(arg) {
  const conv = (v) => (v === null || v === undefined ? null : toDisplay(v, arg.si_unit, arg.unit));
  return [conv(arg.min), conv(arg.max)];
}

export function fieldTitle(arg) {
  const parts = [];
  if (arg.help) parts.push(arg.help);
  if (arg.limit) {  // in the field's own unit; the robot file's key and SI value beside it
    const shown = Number(toDisplay(arg.limit.value, arg.si_unit, arg.unit).toFixed(3));
    const unit = arg.unit ? ` ${arg.unit}` : "";
    parts.push(`at most ${shown}${unit} (${arg.limit.key} = ${arg.limit.value} ` +
               `${arg.si_unit}, ${arg.limit.source})`);
  }
  return parts.join("; ");
}

// Set an input's min/max/step/title from the table (on every hello: the limits may change).
export function applyArg(input, arg) {
  input.title = fieldTitle(arg);
  if (arg.choices) return;
  const [lo, hi] = displayRange(arg);
  if (lo === null) input.removeAttribute("min"); else input.min = String(lo);
  if (hi === null) input.removeAttribute("max"); else input.max = String(hi);
  if (arg.step !== null && arg.step !== undefined) input.step = String(arg.step);
  else input.step = "any";
}

// <label title=help>label <input|select> unit</label> for one argument, with id ``id``.
export function buildField(doc, arg, id) {
  const label = doc.createElement("label");
  label.append(`${arg.label} `);
  let input;
  if (arg.choices) {
    input = doc.createElement("select");
    for (const choice of arg.choices) {
      const option = doc.createElement("option");
      option.value = choice;
      option.textContent = choice;
      input.append(option);
    }
    if (arg.initial !== null && arg.initial !== undefined) input.value = String(arg.initial);
  } else {
    input = doc.createElement("input");
    input.type = "number";
    if (arg.initial !== null && arg.initial !== undefined) {
      input.value = String(toDisplay(arg.initial, arg.si_unit, arg.unit));
    }
  }
  input.id = id;
  input.name = arg.name;
  input.dataset.arg = arg.name;
  applyArg(input, arg);
  label.append(input);
  if (arg.unit) label.append(` ${arg.unit}`);
  label.title = input.title;
  return label;
}

// Why ``valueSi`` is out of ``arg``'s range (in display units), or "" when it is inside.
export function rangeProblem(arg, valueSi) {
  const [lo, hi] = displayRange(arg);
  const shown = toDisplay(valueSi, arg.si_unit, arg.unit);
  const unit = arg.unit ? ` ${arg.unit}` : "";
  if (lo !== null && shown < lo) return `${arg.label}: ${shown}${unit} is under the minimum ${lo}${unit}`;
  if (hi !== null && shown > hi) return `${arg.label}: ${shown}${unit} is over the maximum ${hi}${unit}`;
  return "";
}

// ``valueSi`` kept inside ``arg``'s range (with the vehicle's limit).
export function clampToArg(arg, valueSi) {
  let v = valueSi;
  if (arg.min !== null && arg.min !== undefined) v = Math.max(arg.min, v);
  if (arg.max !== null && arg.max !== undefined) v = Math.min(arg.max, v);
  return v;
}

// A field's value as SI (numbers) or the chosen string; BlankField names the field.
export function readField(input, arg) {
  if (arg.choices) return input.value;
  const v = input.valueAsNumber;
  if (!Number.isFinite(v)) {
    const what = input.value === "" ? "blank" : "not a number";
    throw new BlankField(`the "${arg.label}" field is ${what}; fill it in (0 where you mean none)`);
  }
  return fromDisplay(v, arg.si_unit, arg.unit);
}

// Mark a field out of range (class and title) as it is typed in; the server still decides.
export function markRange(input, arg) {
  if (arg.choices) return;
  const v = input.valueAsNumber;
  const problem = Number.isFinite(v) ? rangeProblem(arg, fromDisplay(v, arg.si_unit, arg.unit)) : "";
  input.classList.toggle("out-of-range", problem !== "");
  input.title = problem || fieldTitle(arg);
}

// "k=v" pairs of a button's data-set, checked against the command's choices.
export function fixedArgs(command, text) {
  const fixed = {};
  for (const pair of (text || "").split(/\s+/).filter(Boolean)) {
    const [name, value] = pair.split("=");
    const arg = command.args.find((a) => a.name === name);
    if (!arg || !arg.choices || !arg.choices.includes(value)) {
      throw new Error(`page layout: ${command.name} has no choice ${pair}`);
    }
    fixed[name] = value;
  }
  return fixed;
}

// Create (first time) or update (later) the fields of every data-form container.
export function renderForms(doc, table) {
  for (const box of doc.querySelectorAll("[data-form]")) {
    const command = table.get(box.dataset.form);
    if (!command) throw new Error(`page layout: no command ${box.dataset.form} in the table`);
    const fixed = new Set((box.dataset.fixed || "").split(/\s+/).filter(Boolean));
    const slot = box.querySelector("[data-fields]");
    for (const arg of command.args) {
      if (fixed.has(arg.name)) continue;
      const existing = doc.getElementById(fieldId(command.name, arg.name));
      if (existing) { applyArg(existing, arg); continue; }
      const label = buildField(doc, arg, fieldId(command.name, arg.name));
      const input = label.querySelector("input, select");
      input.addEventListener("input", () => markRange(input, arg));
      if (slot) slot.before(label); else box.prepend(label);
    }
  }
}

// The arguments of ``command`` from its fields, plus those a button fixes.
export function readArgs(doc, command, fixed = {}) {
  const args = {};
  for (const arg of command.args) {
    if (arg.name in fixed) { args[arg.name] = fixed[arg.name]; continue; }
    const input = doc.getElementById(fieldId(command.name, arg.name));
    if (!input) throw new Error(`page layout: no field for ${command.name}.${arg.name}`);
    args[arg.name] = readField(input, arg);
  }
  return args;
}

// "vehicle limits: speed 3 m/s · climb 1.5 m/s · yaw 100 °/s (robot file hummingbird)" and the
// speed limit, from the limits the table's arguments carry.
export function limitsSummary(commands) {
  const found = {};
  for (const c of commands) for (const a of c.args) if (a.limit) found[a.limit.key] = a.limit;
  const speed = found.max_speed_m_s, climb = found.max_climb_m_s, yaw = found.max_yaw_rate_rad_s;
  const parts = [];
  if (speed) parts.push(`speed ${speed.value} m/s`);
  if (climb) parts.push(`climb ${climb.value} m/s`);
  if (yaw) parts.push(`yaw ${(yaw.value * 180 / Math.PI).toFixed(0)} °/s`);
  const source = (speed || climb || yaw || {}).source;
  return {
    text: parts.length ? `vehicle limits: ${parts.join(" · ")} (${source})` : "",
    speed: speed ? speed.value : null,
    found,
  };
}
