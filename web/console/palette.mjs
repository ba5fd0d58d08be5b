// The console's one palette: every colour the page draws with, each with one meaning.
//
// A colour means one thing wherever it appears (map, camera panels, legends, the 3D scene):
// the class colours are targets of that class, the selection colour is the selected track
// (or the chosen geolocation hit), the hit colour is a terrain hit of a clicked pixel, the
// event colours are their events, and each camera has its own colour (its footprint, its
// symbol on the map, its viewshed, its panel, its frustum and rays in 3D). No two meanings
// share a colour: tests/web/test_console_palette.py checks every pair is far apart
// (CIE76 delta E), and that server/scene3d/style.py uses the same values.

/** Targets by class (map dots and trails, camera boxes, 3D polylines). */
export const CLASS_COLOURS = Object.freeze({
  vehicle: "#ff7a1a",
  human: "#1ad0ff",
});
/** A class the page does not know. */
export const UNKNOWN_CLASS_COLOUR = "#cccccc";
/** The selected track (map, camera boxes, 3D followed track) and the chosen hit, 1σ. */
export const SELECTED_COLOUR = "#ffe600";
/** Terrain hits of a clicked pixel and the ray's ground trace. */
export const HIT_COLOUR = "#ff2bd6";
/** Event symbols (events.mjs keeps the kinds; these are their colours). */
export const EVENT_PALETTE = Object.freeze({
  confirmed: "#70ff70",
  ended: "#ff5050",
  handoff: "#5aa0ff",
  activity: "#b07cff",
  zone: "#ffffff",
});
/** Kept markers: a white diamond edged in this red. */
export const MARKER_COLOUR = "#ffffff";
export const MARKER_EDGE_COLOUR = "#d00000";
/** Roads (cream, drawn at their width). */
export const ROAD_COLOUR = "#f5ebc8";
/** Blind spots (unseen by every sensor): grey, so they read as "nothing here". */
export const BLIND_COLOUR = "#8a8a8a";
/**
 * Per-camera colours, by the sensor's rank in sorted id order (server/scene3d/style.py
 * SENSOR_COLOURS has the same list). None is a class, selection, hit or event colour.
 */
export const SENSOR_COLOURS = Object.freeze(["#10a078", "#b07090", "#909030", "#10f0d0"]);

/** Every colour with a meaning, by its name (what the palette test compares). */
export const MEANINGS = Object.freeze({
  "class vehicle": CLASS_COLOURS.vehicle,
  "class human": CLASS_COLOURS.human,
  selected: SELECTED_COLOUR,
  "geolocation hit": HIT_COLOUR,
  "event confirmed": EVENT_PALETTE.confirmed,
  "event ended": EVENT_PALETTE.ended,
  "event hand-off": EVENT_PALETTE.handoff,
  "event activity": EVENT_PALETTE.activity,
  "blind spot": BLIND_COLOUR,
  road: ROAD_COLOUR,
  ...Object.fromEntries(SENSOR_COLOURS.map((c, k) => [`camera ${k + 1}`, c])),
});

export function classColour(cls) {
  return CLASS_COLOURS[cls] || UNKNOWN_CLASS_COLOUR;
}

/** A sensor's colour, by its rank among `ids` sorted (the same rank the 3D scene uses). */
export function sensorColour(id, ids) {
  const k = [...ids].sort().indexOf(id);
  return k < 0 ? "#ffffff" : SENSOR_COLOURS[k % SENSOR_COLOURS.length];
}

/** ``#rrggbb`` as rgba() with alpha `a`. */
export function withAlpha(hex, a) {
  const n = parseInt(hex.slice(1), 16);
  return `rgba(${n >> 16},${(n >> 8) & 255},${n & 255},${a})`;
}
