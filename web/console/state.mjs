// The page's shared state: the store of tracks, fixes and events, the UI state and the
// timeline, plus the filters every view applies.
//
// The filter state is `ui.filters`; every view tests a track with `visible`, a camera box
// with `boxVisible`, an event with `eventVisible`, and hears of changes via
// `onFiltersChange`.
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
  // classes ticked; sensors ticked (null: all); track ids typed (null: none typed);
  // idError: what in the id field is not a track id (null: nothing), shown under it.
  filters: { classes: new Set(["vehicle", "human"]), sensors: null, ids: null, idError: null },
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

const filterListeners = [];

/** Call `cb(ui.filters)` after every filter change (lists, events, camera boxes). */
export function onFiltersChange(cb) {
  filterListeners.push(cb);
}

/** Tell the page the filters changed (sidebar.mjs calls it): bumps `filterVersion`,
 * asks for a redraw and calls the listeners. */
export function filtersChanged() {
  ui.filterVersion += 1;
  ui.dirty = true;
  for (const cb of filterListeners) cb(ui.filters);
}

/**
 * The track-id field's text as filter ids: {ids: Set | null, error: string | null}.
 * Ids are whole numbers 0 or more, separated by commas, semicolons or spaces; anything
 * else is named in `error` (and the ids that parse still apply, so junk alone shows
 * nothing rather than everything).
 */
export function parseTrackIds(text) {
  const tokens = String(text).split(/[\s,;]+/).filter(Boolean);
  if (!tokens.length) return { ids: null, error: null };
  const ids = new Set();
  const bad = [];
  for (const tok of tokens) {
    const t = tok.replace(/^#/, "");
    if (/^\d{1,15}$/.test(t)) ids.add(Number(t));
    else bad.push(tok);
  }
  const error = bad.length
    ? `not a track id: ${bad.slice(0, 3).map((b) => `"${b.length > 12 ? `${b.slice(0, 12)}…` : b}"`).join(", ")}${bad.length > 3 ? ` and ${bad.length - 3} more` : ""}${ids.size ? "" : " (no track shown)"}`
    : null;
  return { ids, error };
}

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

/**
 * Whether a camera box passes the filters. A box of a track the page holds shows when that
 * track passes (`visible`); any other box when its class and its camera are ticked and no
 * track id is typed (or its track's id is one of them).
 */
export function boxVisible(fix, trackId) {
  const tr = trackId === undefined || trackId === null ? null : store.tracks.get(trackId);
  if (tr) return visible(tr);
  const f = ui.filters;
  if (!f.classes.has(fix.cls)) return false;
  if (f.sensors && !f.sensors.has(fix.sensor)) return false;
  if (f.ids && !(trackId !== undefined && trackId !== null && f.ids.has(trackId))) return false;
  return true;
}

/**
 * Whether an event (events.mjs `normEvent` shape: `track_ids`, optional `sensors`) passes
 * the filters: one of its tracks passes; an event with no track the page holds passes when
 * no id is typed (or one of its ids is typed) and, with sensors named, one is ticked.
 */
export function eventVisible(ev) {
  const ids = ev.track_ids || [];
  const held = ids.map((id) => store.tracks.get(id)).filter(Boolean);
  if (held.length) return held.some(visible);
  const f = ui.filters;
  if (f.ids && !ids.some((id) => f.ids.has(id))) return false;
  if (f.sensors && ev.sensors?.length && !ev.sensors.some((s) => f.sensors.has(s))) return false;
  return true;
}
