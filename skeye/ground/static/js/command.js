// Sending commands over /ws and showing every answer: the "last result" line and the log.

import { $ } from "./dom.js";
import { BlankField } from "./forms.js";
import { S } from "./state.js";

export function send(name, args = {}) {
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

export function onResult(msg) {
  const p = S.pending.get(msg.id);
  if (!p) { if (msg.error) showResult("?", {}, msg); return; }
  S.pending.delete(msg.id);
  p.resolve(msg);
}

// Every command still waiting is answered "page lost its server" (the socket closed).
export function failPending() {
  for (const [, p] of S.pending) p.resolve({ status: 503, error: "page lost its server" });
  S.pending.clear();
}

// The text and class of an answer: accepted, refused by the vehicle (code, reason), or not sent.
export function describeResult(name, r) {
  if (r.ok) return { text: `${name}: accepted`, cls: "ok" };
  if (r.code !== undefined && r.code !== 0 && r.reason !== undefined) {
    return {
      text: `${name}: REFUSED by the vehicle — code ${r.code} ${r.code_name}: ${r.reason}`,
      cls: "bad",
    };
  }
  return { text: `${name}: not sent (${r.status}) — ${r.error}`, cls: "bad" };
}

export function showResult(name, args, r) {
  const el = $("last-result");
  const argText = Object.entries(args).map(([k, v]) => `${k}=${v}`).join(" ");
  const { text, cls } = describeResult(name, r);
  el.textContent = text;
  el.className = `result ${cls}`;
  el.dataset.ok = r.ok ? "true" : "false";
  el.dataset.code = r.code ?? "";
  el.dataset.command = name;
  logLine(`${text}${argText ? `  [${argText}]` : ""}`, cls, name);
}

// One line per change: an answer identical to the newest line (a held key renews the same
// velocity every few hundred ms) counts up "×n" on that line instead of adding another.
export function logLine(text, cls, kind) {
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

// Run a control's handler; a blank field refuses the command on the page, visibly.
export function guarded(name, fn) {
  return () => {
    try { fn(); } catch (e) {
      if (!(e instanceof BlankField)) throw e;
      showResult(name, {}, { ok: false, status: "blank field", error: e.message });
    }
  };
}
