// The trajectories layer: the long-term trajectories of a window ending at the shown time.
//
// From GET /api/synopsis when the server has it (polled while live, at a pace set by how
// long the server takes to answer), else the page's own tracks clipped to the window
// (recomputed at a pace set by how long drawing them takes). docs/console.md, "Live
// tracks, timeline and synopsis".

import * as api from "./api.mjs";
import { layerChecked } from "./sidebar.mjs";
import { store, timeline, trackList, ui, visible } from "./state.mjs";
import { trackParts } from "./store.mjs";
import { $ } from "./util.mjs";

/** The window [a, b] the trajectories of time t cover (a = -Infinity: all). */
export function synopsisWindow(t) {
  const w = Number($("#syn-window").value);
  return [Number.isFinite(w) ? t - w : -Infinity, t];
}

/** The track's points and gaps within [a, b]. */
export function clipTrack(tr, a, b) {
  const points = tr.points.filter((p) => p.t_s >= a && p.t_s <= b);
  return { ...tr, points, gaps: (tr.gaps || []).filter(([g0, g1]) => g1 >= a && g0 <= b) };
}

/** How often (ms) to redo a job that took costMs: 20 times its cost (about 5 % of the
 * time), within [least, most]. */
function refreshEveryMs([least, most], costMs) {
  return Math.min(most, Math.max(least, 20 * costMs));
}

let localCache = null;
/** How often (ms) the page's own synopsis follows a sliding window or new data: once a
 * second, or less often when drawing it takes more than 5 % of that (at most every 5 s). */
const LOCAL_SYNOPSIS_REFRESH_MS = [1000, 5000];

/**
 * The page's own synopsis of the window [a, b].
 *
 * Recomputed when the window's length changes, it jumps (a seek), or, while it slides
 * (live, or playing) or data streams in, every LOCAL_SYNOPSIS_REFRESH_MS: the trajectories
 * of a window of minutes barely change between frames, and the live trails show the
 * newest seconds.
 */
function localSynopsis(a, b) {
  const now = performance.now();
  const c = localCache;
  if (c && c.a === a && c.b === b && c.version === store.version) return c.trajs;
  const span = b - a;
  const sameSpan = c && (c.b - c.a === span || (!Number.isFinite(span) && !Number.isFinite(c.b - c.a)));
  const slide = c ? Math.abs(b - c.b) : Infinity;
  const every = refreshEveryMs(LOCAL_SYNOPSIS_REFRESH_MS, ui.map.synopsisRenderMs);
  if (sameSpan && now - c.at < every && slide <= Math.max(30, 0.05 * span)) return c.trajs;
  const trajs = computeLocalSynopsis(a, b);
  localCache = { a, b, version: store.version, at: now, trajs };
  return trajs;
}

function computeLocalSynopsis(a, b) {
  return trackList()
    .map((tr) => clipTrack(tr, a, b))
    .filter((tr) => tr.points.length >= 2)
    .map((tr) => ({ id: tr.id, cls: tr.cls, sensors: tr.sensors, parts: trackParts(tr) }));
}

/** GET /api/synopsis trajectories as synopsis parts (tracked paths, gap jumps), else null. */
function apiSynopsis(body) {
  if (!Array.isArray(body?.trajectories)) return null;
  const xy = (p) => [p.e_m, p.n_m];
  return body.trajectories.map((tr) => ({
    id: tr.track_id,
    cls: tr.cls,
    sensors: tr.sensors,
    parts: (tr.parts || []).map((part) => (part.kind === "gap"
      ? { gap: true, coords: [xy(part.start), xy(part.end)] }
      : { gap: false, coords: (part.path || []).map(xy) })),
  }));
}

let synopsisFetch = null;
/** Live, the server's synopsis is asked for every 3 s, or less often when answering takes
 * the server long (20 times the last answer's duration: at most about 5 % of its time,
 * whatever the window holds), at most every 15 s. */
const LIVE_SYNOPSIS_POLL_MS = [3000, 15000];

/** Draws (or hides) the trajectories of the window ending at the shown time t. */
export function drawSynopsis(t) {
  const on = $("#syn-on").checked;
  ui.map.synopsis.setVisible(on && layerChecked("synopsis"));
  if (!on) return;
  const [a, b] = synopsisWindow(t);
  // The server's synopsis when it has one, asked again when the window has moved by a
  // second or more (or new data came); the page's own tracks meanwhile.
  const s = ui.synopsis;
  const sameWindow = s && (s.t0 === a || b - a === s.t1 - s.t0);
  const fresh = sameWindow && Math.abs(s.t1 - b) < 0.5 && s.version === store.version;
  const close = sameWindow && Math.abs(s.t1 - b) < 5;
  const now = performance.now();
  // Live, the window slides all the time: ask every few seconds; after a seek, at once.
  const every = timeline.live ? refreshEveryMs(LIVE_SYNOPSIS_POLL_MS, ui.synopsisFetchMs || 0) : 500;
  const wait = every - (now - (ui.synopsisAt || 0));
  if (ui.synopsisApi !== null && !fresh && !synopsisFetch && wait > 0 && !ui.synopsisTimer) {
    ui.synopsisTimer = setTimeout(() => {
      ui.synopsisTimer = null;
      ui.dirty = true;
    }, wait);
  }
  if (ui.synopsisApi !== null && !fresh && !synopsisFetch && wait <= 0) {
    ui.synopsisAt = now;
    // About 1500 path points per trajectory at most, whatever the window.
    const span = b - (Number.isFinite(a) ? a : store.tMin ?? b);
    const q = new URLSearchParams({ t1: String(b), step_s: String(Math.max(0.5, span / 1500)) });
    if (Number.isFinite(a)) q.set("t0", String(a));
    const version = store.version;
    synopsisFetch = api.getOptionalJSON(`/api/synopsis?${q}`).then((body) => {
      ui.synopsisFetchMs = performance.now() - now;
      const trajs = body === null ? null : apiSynopsis(body);
      if (trajs === null) ui.synopsisApi = null;
      else ui.synopsis = { t0: a, t1: b, trajs, version };
    }).catch(() => {
      ui.synopsisApi = null;
    }).finally(() => {
      synopsisFetch = null;
      ui.dirty = true;
    });
  }
  const trajs = ui.synopsisApi !== null && close ? s.trajs : localSynopsis(a, b);
  // The layer's features are rebuilt only when what they show changed.
  const drawn = ui.synopsisDrawn;
  if (!drawn || drawn.trajs !== trajs || drawn.filters !== ui.filterVersion) {
    ui.map.drawSynopsis(trajs, visible);
    ui.synopsisDrawn = { trajs, filters: ui.filterVersion };
  }
}

