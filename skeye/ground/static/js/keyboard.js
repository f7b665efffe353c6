// Keyboard flying: held keys send VELOCITY with a short duration, renewed while held, so a lost
// page or link stops the vehicle by itself; releasing every key sends zero velocity. The speed
// field, the yaw rate, the duration and the renewal period come from the server's table
// (commands.py KEYBOARD); every component is kept inside the velocity argument's range.

import { guarded, send, showResult } from "./command.js";
import { $ } from "./dom.js";
import { applyArg, BlankField, buildField, clampToArg, readField } from "./forms.js";
import { S } from "./state.js";

export const KEYMAP = {
  KeyW: ["fwd", 1], ArrowUp: ["fwd", 1], KeyS: ["fwd", -1], ArrowDown: ["fwd", -1],
  KeyD: ["right", 1], ArrowRight: ["right", 1], KeyA: ["right", -1], ArrowLeft: ["right", -1],
  KeyR: ["up", 1], KeyF: ["up", -1], KeyE: ["yaw", 1], KeyQ: ["yaw", -1],
};
const AXIS_ARGS = { fwd: "forward_m_s", right: "right_m_s", up: "up_m_s", yaw: "yaw_rate_rad_s" };
let timer = null;

// The keyboard's speed field, built (first hello) or updated (later) from the table.
export function renderKeyboard(keyboard) {
  const existing = $("kbd-speed");
  if (existing) { applyArg(existing, keyboard.speed); return; }
  $("kbd-speed-slot").replaceWith(buildField(document, keyboard.speed, "kbd-speed"));
}

// The velocity arguments for held axes ``axes`` ({fwd, right, up, yaw}: -1, 0 or 1), each at
// ``speedMS`` (yaw at the keyboard's rate), clamped to the velocity command's ranges.
export function keyVelocity(velocity, keyboard, axes, speedMS, moving) {
  const arg = (name) => velocity.args.find((a) => a.name === name);
  const raw = {
    fwd: axes.fwd * speedMS, right: axes.right * speedMS, up: axes.up * speedMS,
    yaw: axes.yaw * keyboard.yaw_rate_rad_s,
  };
  const out = {};
  for (const [axis, name] of Object.entries(AXIS_ARGS)) {
    out[name] = clampToArg(arg(name), raw[axis]) + 0;  // + 0: no "-0" in the log
  }
  out.duration_s = moving ? keyboard.duration_s : 0;
  return out;
}

function active() {
  const tag = document.activeElement && document.activeElement.tagName;
  return $("kbd-enable").checked && tag !== "INPUT" && tag !== "SELECT";
}

function heldAxes() {
  const v = { fwd: 0, right: 0, up: 0, yaw: 0 };
  for (const code of S.keys) { const [axis, sign] = KEYMAP[code]; v[axis] += sign; }
  return v;
}

function kbdSend(final = false) {
  if (!S.keyboard || !S.commands) return;
  const axes = heldAxes();
  let speed;
  try { speed = readField($("kbd-speed"), S.keyboard.speed); } catch (e) {
    if (!(e instanceof BlankField)) throw e;
    speed = 0;  // a release still stops the vehicle; a key press sends nothing
    if (!final) {
      showResult("velocity", {}, { ok: false, status: "blank field", error: e.message });
      return;
    }
  }
  const moving = Boolean(axes.fwd || axes.right || axes.up || axes.yaw);
  const args = keyVelocity(S.commands.get("velocity"), S.keyboard, axes, speed, moving);
  $("kbd-state").textContent = moving
    ? `fwd ${args.forward_m_s} · right ${args.right_m_s} · up ${args.up_m_s} · yaw ${axes.yaw}` : "";
  if (!moving && !final) return;
  send("velocity", args);
}

function stopRepeat() { clearInterval(timer); timer = null; }

// A held key's renewal while the page's commands waiting for the vehicle are at the server's
// limit (a slow link or a loaded vehicle) would be refused, 429, and logged between the held
// velocity's lines: it is not sent; the velocity still waiting renews the vehicle's, and the
// next period sends again. A change of keys is always sent.
function renew() {
  if (S.pending.size >= S.maxInFlight) { S.renewalsSkipped += 1; return; }
  kbdSend();
}

export function wireKeyboard() {
  $("kbd-enable").onchange = (e) => {
    $("kbd-enable").closest(".kbd").classList.toggle("active", e.target.checked);
    e.target.blur();
  };
  document.addEventListener("keydown", (e) => {
    if (!active() || !S.keyboard) return;
    if (e.code === "Space") {
      e.preventDefault(); S.keys.clear(); stopRepeat(); guarded("hold", () => send("hold"))();
      return;
    }
    if (!(e.code in KEYMAP)) return;
    e.preventDefault();
    if (S.keys.has(e.code)) return;
    S.keys.add(e.code);
    kbdSend();
    stopRepeat();
    timer = setInterval(renew, S.keyboard.repeat_s * 1000);
  });
  document.addEventListener("keyup", (e) => {
    if (!(e.code in KEYMAP) || !S.keys.has(e.code)) return;
    S.keys.delete(e.code);
    if (S.keys.size === 0) { stopRepeat(); kbdSend(true); } else kbdSend();
  });
  window.addEventListener("blur", () => {
    if (S.keys.size) { S.keys.clear(); stopRepeat(); kbdSend(true); }
  });
}
