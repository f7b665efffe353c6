// The page's shared state. Also window.S, so the browser tests (and a curious user's console)
// can read the newest telemetry, the command counter and the commands still waiting.

export const S = {
  telemetry: null,
  track: [],          // {north_m, east_m}
  series: [],         // {t (epoch s), height, dx, dy}
  home: null,
  groundDet: null,    // this page's camera detection: {t, dx, dy}
  cmdId: 0,
  pending: new Map(), // id -> {name, args, resolve}
  ws: null,
  keys: new Set(),
  commands: null,     // Map name -> command, from the server's table (hello)
  keyboard: null,     // the keyboard's speed field and timing (hello)
  padMode: null,
  flightState: null,  // the vehicle's last NAV_STATUS state (a change to manual is logged)
  hellos: 0,          // hello messages so far: one per (re)connection to the server
  maxInFlight: 2,     // the server's limit on this page's commands waiting at once (hello)
  renewalsSkipped: 0, // held-key renewals not sent: the page's commands were at that limit
};

window.S = S;
