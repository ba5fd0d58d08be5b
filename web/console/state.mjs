// The page's shared state: the store of tracks, fixes and events, the UI state and the
// timeline, plus the filters every view applies.
//
// `ui.dirty = true` asks the frame loop (frame.mjs) for a redraw on the next animation
// frame; main.mjs exposes these objects as `window.demtrack` for the browser tests.

import { PastBoxes } from "./history.mjs";
import { SceneFollow } from "./follow.mjs";
import { Store } from "./store.mjs";
import { Timeline } from "./timeline.mjs";

export const store = new Store();

export const ui = {
  site: null,
  sensors: [],
  map: null,
  cams: new Map(),
  selectedId: null,
  following: false,
  geo: null, // {panel, u, v, rule, result}
  rule: "first",
  markers: [],
  filters: { classes: new Set(["vehicle", "human"]), sensors: null, ids: null },
  filterVersion: 0, // bumped on every filter change (what the drawn synopsis was filtered by)
  dirty: true,
  redraws: 0,
  lastVersion: -1,
  lastT: null,
  events: [],
  synopsisApi: undefined, // undefined: not tried; null: absent
  synopsis: null, // {t0, t1, trajs}
  viserUrl: null,
  loadMs: null,
  follow3d: new SceneFollow(false), // replaced at start-up when the server runs a 3D scene
  past: new PastBoxes(), // camera boxes older than the store's recent fixes
  vis: null, // coverage, viewshed and blind-spot layers (loaded when first shown)
};

export const timeline = new Timeline(store, () => (ui.dirty = true));

/** Whether a track passes the class, sensor and id filters. */
export function visible(tr) {
  const f = ui.filters;
  if (!f.classes.has(tr.cls)) return false;
  if (f.sensors && !(tr.sensors || []).some((s) => f.sensors.has(s))) return false;
  if (f.ids && !f.ids.has(tr.id)) return false;
  return true;
}

export function trackList() {
  return [...store.tracks.values()];
}
