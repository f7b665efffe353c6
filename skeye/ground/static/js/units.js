// Unit conversions between the SI values of the wire (and of the command table) and the units
// the page shows. The pairs are the ones of skeye/ground/commands.py DISPLAY_FACTORS:
// display = SI * factor. A pair not listed is an error, never a silent 1.

export const DISPLAY_FACTORS = {
  "rad/s→°/s": 180 / Math.PI,
  "rad→°": 180 / Math.PI,
};

export function factor(siUnit, unit) {
  if (siUnit === unit || !unit) return 1;
  const f = DISPLAY_FACTORS[`${siUnit}→${unit}`];
  if (f === undefined) throw new Error(`no conversion from ${siUnit || "(none)"} to ${unit}`);
  return f;
}

// Ten significant digits: 1.7453292519943295 rad/s shows as 100 °/s, not 99.99999999999999.
export const tidy = (x) => Number(Number(x).toPrecision(10));

export const toDisplay = (valueSi, siUnit, unit) => tidy(valueSi * factor(siUnit, unit));
export const fromDisplay = (value, siUnit, unit) => value / factor(siUnit, unit);

export const degToRad = (deg) => deg * Math.PI / 180;
export const radToDeg = (rad) => rad * 180 / Math.PI;
