// Small DOM helpers shared by the page's modules. Every readout carries its number in
// data-value (what the browser tests read), its text for people.

export const $ = (id) => document.getElementById(id);

export function setText(id, text, value) {
  const el = $(id);
  el.textContent = text;
  if (value !== undefined) el.dataset.value = value === null ? "" : String(value);
}

export function pill(id, text, cls, attrs = {}) {
  const el = $(id);
  el.textContent = text;
  el.className = `pill ${cls}`;
  for (const [k, v] of Object.entries(attrs)) el.dataset[k] = v;
}

export function banner(text, ok = false) {
  const el = $("banner");
  if (!text) { el.classList.add("hidden"); return; }
  el.textContent = text;
  el.className = ok ? "banner ok" : "banner";
}

export function wsUrl(path) {
  return `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${path}`;
}
