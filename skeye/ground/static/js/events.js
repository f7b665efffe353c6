// What the vehicle reports of itself (vision too slow, a pad landing done, a take-over, a
// crash), in its own list beside the commands' answers, so the answers are never buried.
// One line per kind of event a minute at most: a kind that comes again within EVENT_REPEAT_S
// of its line's first time updates that line (newest text, time, ×n) instead of adding one.

import { $ } from "./dom.js";

export const EVENT_REPEAT_S = 60;
const MAX_LINES = 100;

export function eventLine(kind, text, cls, nowS = Date.now() / 1000) {
  const log = $("event-log");
  const t = new Date(nowS * 1000).toLocaleTimeString();
  const same = [...log.children].find((li) => li.dataset.kind === kind &&
    nowS - Number(li.dataset.first) < EVENT_REPEAT_S);
  if (same) {
    const n = Number(same.dataset.repeats) + 1;
    same.dataset.repeats = String(n);
    same.dataset.text = text;
    same.children[0].textContent = t;
    same.children[1].textContent = text;
    same.children[1].className = cls;
    same.children[2].textContent = ` ×${n} in ${Math.round(nowS - Number(same.dataset.first))} s`;
    log.prepend(same);
    return;
  }
  const li = document.createElement("li");
  li.innerHTML = `<span class="t"></span><span></span><span class="dim"></span>`;
  li.children[0].textContent = t;
  li.children[1].textContent = text;
  li.children[1].className = cls;
  li.dataset.kind = kind;
  li.dataset.text = text;
  li.dataset.first = String(nowS);
  li.dataset.repeats = "1";
  log.prepend(li);
  while (log.children.length > MAX_LINES) log.lastChild.remove();
}
