// The operator console: loads the site, wires the map, cameras, timeline and stream.
//
// Data flow: GET /api/health gives the newest stream seq, GET /api/tracks the tracks so
// far, then /ws?since=<seq> streams what follows (fixes, track updates, events). The map
// and the camera panels are redrawn on animation frames when the data or the shown time
// changed. `window.demtrack` exposes the state for the browser tests.

/* global ol */
import * as api from "./api.mjs";
import { BOX_WINDOW_S, CameraPanel } from "./cameras.mjs";
import { drawSpeed, geoDetail, trackDetail } from "./detail.mjs";
import { FORMATS, renderMarkers, renderTracks } from "./export.mjs";
import { SceneFollow, viserFrameUrl } from "./follow.mjs";
import { bufferCovers, PastBoxes } from "./history.mjs";
import { SiteMap } from "./map.mjs";
import { firstT, lastT, positionAt, Store, trackParts } from "./store.mjs";
import { Stream } from "./stream.mjs";
import { Timeline } from "./timeline.mjs";
import { $, classColour, download, el, fmt, fmtT } from "./util.mjs";
import { VisibilityLayers } from "./visibility.mjs";

const store = new Store();
const ui = {
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
const timeline = new Timeline(store, () => (ui.dirty = true));
let stream = null;

window.demtrack = { store, ui, timeline, get stream() { return stream; } };

// ------------------------------------------------------------------------- helpers
function setConn(state, detail) {
  const pill = $("#conn");
  pill.dataset.state = state;
  pill.textContent = { live: "connected", reconnecting: "reconnecting…" }[state] || state;
  pill.title = detail || "live stream";
  $("#banner").classList.toggle("hidden", state !== "reconnecting");
  if (state === "unauthorized") askToken("the server refused the token");
}

function askToken(why) {
  const dlg = $("#token-dialog");
  $("#token-error").textContent = why || "";
  if (!dlg.open) dlg.showModal();
}

function visible(tr) {
  const f = ui.filters;
  if (!f.classes.has(tr.cls)) return false;
  if (f.sensors && !(tr.sensors || []).some((s) => f.sensors.has(s))) return false;
  if (f.ids && !f.ids.has(tr.id)) return false;
  return true;
}

function trackList() {
  return [...store.tracks.values()];
}

// --------------------------------------------------------------------------- start
async function boot() {
  const t0 = performance.now();
  api.takeTokenFromUrl();
  $("#token-form").addEventListener("submit", (ev) => {
    const v = $("#token-input").value.trim();
    if (!v) {
      ev.preventDefault();
      return;
    }
    api.setToken(v);
    window.location.reload();
  });
  const config = fetch("/console-config.json").then((r) => (r.ok ? r.json() : {})).catch(() => ({}));
  if (!api.token()) {
    askToken();
    setConn("unauthorized", "no operator token");
    return;
  }
  let site, sensors, health;
  try {
    [site, sensors, health] = await Promise.all([
      api.getJSON("/api/site"), api.getJSON("/api/sensors"), api.getJSON("/api/health"),
    ]);
  } catch (err) {
    if (err instanceof api.AuthError) askToken(err.message);
    else setConn("offline", String(err));
    throw err;
  }
  const cfg = await config;
  ui.endpoints = cfg.endpoints || {};
  if (!ui.endpoints.synopsis) ui.synopsisApi = null;
  ui.site = site;
  ui.sensors = sensors;
  ui.viserUrl = cfg.viser_url || site.viser_url || health.viser_url || null;
  $("#site-name").textContent = site.name;
  ui.map = new SiteMap("map", site);
  window.demtrack.map = ui.map;
  ui.vis = new VisibilityLayers(ui.map, site, sensors);
  ui.follow3d = new SceneFollow(!!ui.viserUrl, showFollow);
  ui.past.onLoad = () => (ui.dirty = true);
  buildLayerList();
  buildFilters();
  buildCameras();
  wireMap();
  wireControls();

  const ortho = site.orthophoto
    ? api.imageURL("/api/site/orthophoto.png").then((u) => ui.map.setImage(ui.map.ortho, u, site.orthophoto.bounds_enu))
    : Promise.resolve();
  const relief = loadRelief("shaded-relief");
  const roads = api.getJSON("/api/site/roads.geojson?frame=enu").then((g) => ui.map.setRoads(g));
  ui.map.setSensors(sensors);
  const images = Promise.all(sensors.map(async (s) => {
    const url = s.image ? await api.imageURL(`/api/sensors/${encodeURIComponent(s.id)}/image`) : null;
    const panel = ui.cams.get(s.id);
    panel.setImage(url);
    if (url) await panel.img.decode().catch(() => {});
  }));
  const tracks = api.getJSON("/api/tracks")
    .then((r) => r.tracks.forEach((t) => store.applyTrack(t)))
    .then(() => recentDetections().catch(() => {}));
  const events = ui.endpoints.events
    ? api.getOptionalJSON("/api/events").then((r) => {
      const list = Array.isArray(r) ? r : r?.events;
      for (const e of list || []) store.applyEvent(normEvent({ kind: e.kind, t_s: e.t_start_s, event: e }));
    }).catch(() => {})
    : Promise.resolve();
  await Promise.all([ortho, relief, roads, images, tracks, events]);
  if (!store.events.length) eventsFromTracks(); // no event log on this server (or none yet)
  stream = new Stream({
    onMessage,
    onStatus: setConn,
    onHello: () => {},
    onReset: async () => {
      store.clear();
      const r = await api.getJSON("/api/tracks");
      r.tracks.forEach((t) => store.applyTrack(t));
      ui.dirty = true;
    },
  });
  stream.start(health.last_seq);
  ui.loadMs = performance.now() - t0;
  ui.readyMs = performance.now(); // since navigation start
  document.body.dataset.ready = "1";
  ui.dirty = true;
  requestAnimationFrame(frame);
}

async function loadRelief(kind) {
  const url = await api.imageURL(`/api/site/relief.png?kind=${encodeURIComponent(kind)}`);
  const old = ui.map.relief.getSource();
  ui.map.setImage(ui.map.relief, url, ui.site.dem.bounds_enu);
  const oldUrl = old?.getUrl?.();
  if (oldUrl) URL.revokeObjectURL(oldUrl);
}

/** The newest stored detections as boxes for the camera panels (the stream adds more). */
async function recentDetections() {
  let maxId = 0;
  for (const tr of store.tracks.values()) {
    for (let i = Math.max(0, tr.points.length - 5); i < tr.points.length; i += 1) {
      for (const d of tr.points[i].detection_ids || []) maxId = Math.max(maxId, d);
    }
  }
  if (!maxId) return;
  const n = 200 * Math.max(1, ui.sensors.length);
  const rows = await api.getJSON(`/api/detections?after_id=${Math.max(0, maxId - n)}&limit=${2 * n}`);
  for (const d of rows) {
    store.applyFix({ detection_id: d.id, t_s: d.t, sensor: d.sensor, cls: d.class ?? d.cls, bbox: d.bbox, tracked: true });
  }
}

/** Without GET /api/events: the history's track events, as the stream words them. */
function eventsFromTracks() {
  const evs = [];
  for (const tr of store.tracks.values()) {
    if (!tr.points.length) continue;
    evs.push(normEvent({ kind: "track_confirmed", t_s: firstT(tr), text: `track ${tr.id} (${tr.cls}) confirmed` }));
    if (!tr.live) evs.push(normEvent({ kind: "track_ended", t_s: lastT(tr), text: `track ${tr.id} (${tr.cls}) ended` }));
  }
  evs.sort((a, b) => a.t_s - b.t_s).forEach((e) => store.applyEvent(e));
}

// --------------------------------------------------------------------------- stream
function onMessage(msg) {
  if (msg.type === "fix") store.applyFix(msg.fix);
  else if (msg.type === "track_update") store.applyTrack(msg.track);
  else if (msg.type === "event") {
    const ev = normEvent(msg);
    if (ev.kind !== "ingest") store.applyEvent(ev);
  }
  else if (msg.type === "sensor_status") {
    store.sensorStatus.set(msg.sensor, msg);
    const p = ui.cams.get(msg.sensor);
    if (p) p.status.textContent = `${msg.n_detections} detections · last ${fmtT(msg.last_t_s)}`;
  }
  ui.dirty = true;
}

// ---------------------------------------------------------------------------- frame
let lastListDraw = 0;
let lastDetailDraw = 0;

function frame(nowMs) {
  const moved = timeline.tick(nowMs);
  const t = timeline.now();
  if (moved || ui.dirty || store.version !== ui.lastVersion || t !== ui.lastT) {
    ui.dirty = false;
    ui.redraws += 1; // counted for the soak benchmark
    ui.lastVersion = store.version;
    ui.lastT = t;
    timeline.sync();
    redraw(t);
    if (nowMs - lastListDraw > 400) {
      lastListDraw = nowMs;
      drawLists(t);
    }
    if (nowMs - lastDetailDraw > 250) {
      lastDetailDraw = nowMs;
      refreshDetail(t);
    }
  }
  requestAnimationFrame(frame);
}

function redraw(t) {
  const map = ui.map;
  map.setSelected(ui.selectedId);
  const tracks = trackList();
  map.drawTracks(tracks, t, visible);
  drawSynopsis(t);
  drawEventsOnMap(t);
  for (const [sid, panel] of ui.cams) {
    // Scrubbed back beyond the fixes the store keeps: the boxes of that moment come from
    // the API (history.mjs); none are drawn while they load.
    const past = !timeline.live && !bufferCovers(store, sid, t, BOX_WINDOW_S);
    if (past) {
      const fixes = ui.past.fixesNear(sid, t, BOX_WINDOW_S);
      panel.draw(fixes || [], (d) => ui.past.trackOf(d) ?? store.trackOfDetection(d), ui.selectedId);
    } else {
      panel.draw(store.fixesNear(sid, t, BOX_WINDOW_S), (d) => store.trackOfDetection(d), ui.selectedId);
    }
    panel.root.dataset.boxes = past ? "stored" : "recent";
  }
  if (ui.following && ui.selectedId !== null) {
    const tr = store.tracks.get(ui.selectedId);
    const p = tr && (positionAt(tr, t) || lastPoint(tr, t));
    if (p) map.centreOn(p.e_m, p.n_m);
  }
  map.trails.changed();
  $("#counts").textContent = `${store.tracks.size} tracks · ${store.nPoints()} points`;
}

function lastPoint(tr, t) {
  const pts = tr.points.filter((p) => p.t_s <= t);
  return pts.length ? pts[pts.length - 1] : null;
}

// ------------------------------------------------------------------ trajectories
function synopsisWindow(t) {
  const w = Number($("#syn-window").value);
  return [Number.isFinite(w) ? t - w : -Infinity, t];
}

function clipTrack(tr, a, b) {
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

function drawSynopsis(t) {
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

// ------------------------------------------------------------------------- events
/**
 * One shape for the events of GET /api/events and of the stream:
 * {kind, t_s, text, key, track_ids, e_m, n_m} (e_m/n_m null when not given).
 */
function normEvent(raw) {
  const body = raw.event || null;
  const ids = body?.track_ids || [];
  const m = /track (\d+)/.exec(raw.text || "");
  const trackIds = ids.length ? ids : m ? [Number(m[1])] : [];
  const p = body?.p_enu;
  const where = body?.sensors?.length ? ` (${body.sensors.join(" → ")})` : "";
  const text = raw.text || `${raw.kind.replace(/[-_]/g, " ")}: track${trackIds.length > 1 ? "s" : ""} ${trackIds.join(", ")}${where}`;
  return {
    kind: raw.kind,
    t_s: raw.t_s ?? body?.t_start_s ?? null,
    text,
    key: body?.key || null,
    track_ids: trackIds,
    e_m: p ? p[0] : null,
    n_m: p ? p[1] : null,
  };
}

function eventTrackId(ev) {
  return ev.track_ids && ev.track_ids.length ? ev.track_ids[0] : null;
}

function drawEventsOnMap(t) {
  const items = [];
  for (const ev of store.events) {
    if (ev.t_s === null || ev.t_s > t || ev.t_s < t - 120) continue;
    const id = eventTrackId(ev);
    const tr = id !== null ? store.tracks.get(id) : null;
    if (tr && !visible(tr)) continue;
    if (ev.e_m !== null) {
      items.push({ kind: ev.kind, e_m: ev.e_m, n_m: ev.n_m });
      continue;
    }
    if (!tr) continue;
    const p = positionAt(tr, ev.t_s) || (ev.kind === "track_ended" ? tr.points[tr.points.length - 1] : tr.points[0]);
    if (p) items.push({ kind: ev.kind, e_m: p.e_m, n_m: p.n_m });
  }
  ui.map.drawEvents(items);
}

// -------------------------------------------------------------------------- lists
function drawLists(t) {
  const tracks = trackList().filter(visible).sort((a, b) => lastT(b) - lastT(a)).slice(0, 100);
  $("#n-tracks").textContent = `(${tracks.length}${store.tracks.size > tracks.length ? ` of ${store.tracks.size}` : ""})`;
  const list = $("#track-list");
  list.replaceChildren(...tracks.map((tr) => el("div", {
    class: tr.id === ui.selectedId ? "sel" : "",
    "data-track": String(tr.id),
    title: `sensors ${(tr.sensors || []).join(", ")}`,
    onclick: () => select(tr.id),
  },
  el("span", { class: "swatch", style: `background:${classColour(tr.cls)}` }),
  el("b", { text: `#${tr.id}` }),
  el("span", { text: tr.cls }),
  el("span", { class: "muted", text: `${fmtT(firstT(tr))}–${fmtT(lastT(tr))}${tr.live ? " ●" : ""}` }))));
  const evs = store.events.slice(-60).reverse();
  $("#event-list").replaceChildren(...evs.map((ev) => el("div", {
    class: ev.t_s !== null && ev.t_s > t ? "muted" : "",
    title: ev.text,
    onclick: () => {
      if (ev.t_s !== null) timeline.seek(ev.t_s);
      const id = eventTrackId(ev);
      if (id !== null && store.tracks.has(id)) select(id);
    },
  }, el("span", { class: "mono muted", text: fmtT(ev.t_s) }), el("span", { text: ev.text }))));
}

// ------------------------------------------------------------------------ selection
function select(id) {
  ui.selectedId = id;
  ui.following = false;
  ui.follow3d.set(id);
  ui.geo = null;
  for (const p of ui.cams.values()) p.click = null;
  ui.map.drawGeolocation(null);
  ui.map.setSelected(id);
  lastDetailDraw = 0;
  ui.dirty = true;
  renderDetail();
  drawLists(timeline.now());
}

function clearSelection() {
  ui.selectedId = null;
  ui.following = false;
  ui.follow3d.set(null);
  ui.geo = null;
  for (const p of ui.cams.values()) p.click = null;
  ui.map.drawGeolocation(null);
  ui.dirty = true;
  renderDetail();
  drawLists(timeline.now());
}

let detailCanvas = null;
let detailVersion = -1;

function renderDetail() {
  const box = $("#detail");
  detailCanvas = null;
  if (ui.geo && ui.geo.result) {
    box.replaceChildren(geoDetail(ui.geo.result, ui.geo.panel.sensor.id, {
      rule: ui.geo.rule,
      onRule: (r) => {
        ui.rule = r;
        geolocate(ui.geo.panel, ui.geo.u, ui.geo.v);
      },
      onKeep: keepMarker,
      onClose: clearSelection,
    }));
    return;
  }
  const tr = ui.selectedId !== null ? store.tracks.get(ui.selectedId) : null;
  if (!tr) {
    box.replaceChildren(el("p", { class: "muted hint", text: "Click a camera image to geolocate a pixel; click a track on the map or in the list to see its history." }));
    return;
  }
  const { root, canvas } = trackDetail(tr, {
    following: ui.following,
    onFollow: () => {
      ui.following = !ui.following;
      renderDetail();
      ui.dirty = true;
    },
    onExport: () => exportTracks("geojson", [tr]),
    onClose: clearSelection,
  });
  box.replaceChildren(root);
  detailCanvas = canvas;
  detailVersion = tr.updated;
  drawSpeed(canvas, tr, timeline.now());
}

function refreshDetail(t) {
  if (ui.geo || ui.selectedId === null) return;
  const tr = store.tracks.get(ui.selectedId);
  if (!tr) return;
  if (tr.updated !== detailVersion) renderDetail();
  else if (detailCanvas) drawSpeed(detailCanvas, tr, t);
}

// ------------------------------------------------------------------- geolocation
async function geolocate(panel, u, v) {
  const rule = ui.rule;
  ui.selectedId = null;
  ui.following = false;
  ui.follow3d.set(null);
  for (const p of ui.cams.values()) if (p !== panel) p.click = null;
  panel.click = { u, v, result: null };
  ui.geo = { panel, u, v, rule, result: null, pending: true };
  ui.dirty = true;
  try {
    const result = await api.postJSON("/api/geolocate", { sensor: panel.sensor.id, u, v, rule });
    if (!ui.geo || ui.geo.panel !== panel || ui.geo.u !== u || ui.geo.v !== v || ui.rule !== rule) return;
    ui.geo = { panel, u, v, rule, result, pending: false };
    panel.click = { u, v, result };
    ui.map.drawGeolocation(result, panel.sensor);
    renderDetail();
  } catch (err) {
    $("#detail").replaceChildren(el("p", { class: "error", text: String(err.message || err) }));
    if (err instanceof api.AuthError) askToken(err.message);
  }
  ui.dirty = true;
}

function keepMarker() {
  const res = ui.geo?.result;
  const h = res?.selected?.[0];
  if (!h) return;
  const n = ui.markers.length ? ui.markers[ui.markers.length - 1].id + 1 : 1;
  ui.markers.push({ id: n, name: `M${n}`, sensor: res.sensor, pixel: res.pixel, rule: res.rule, ...h });
  drawMarkers();
}

function drawMarkers() {
  ui.map.drawMarkers(ui.markers);
  $("#export-markers").disabled = !ui.markers.length;
  $("#marker-list").replaceChildren(...ui.markers.map((m) => el("div", {
    title: `${m.sensor} pixel ${m.pixel.join(", ")}, rule ${m.rule}`,
    onclick: () => ui.map.centreOn(m.e_m, m.n_m),
  },
  el("b", { text: m.name }),
  el("span", { class: "mono", text: `E ${fmt(m.e_m, 1)} N ${fmt(m.n_m, 1)}` }),
  el("span", { class: "grow" }),
  el("button", {
    title: "remove marker",
    onclick: (ev) => {
      ev.stopPropagation();
      ui.markers = ui.markers.filter((x) => x !== m);
      drawMarkers();
    },
  }, "✕"))));
}

// ------------------------------------------------------------------------ export
function selectionTracks() {
  const t = timeline.now();
  let tracks = ui.selectedId !== null && store.tracks.has(ui.selectedId)
    ? [store.tracks.get(ui.selectedId)]
    : trackList().filter(visible);
  if ($("#syn-on").checked) {
    const [a, b] = synopsisWindow(t);
    tracks = tracks.map((tr) => clipTrack(tr, a, b));
  }
  return tracks.filter((tr) => tr.points.length).sort((a, b) => a.id - b.id);
}

function exportTracks(format, tracks) {
  const f = FORMATS[format];
  download(`demtrack-tracks.${f.ext}`, f.mime, renderTracks(format, tracks));
}

// ---------------------------------------------------------------------- building
function layerChecked(name) {
  const box = document.querySelector(`#layers input[data-layer="${name}"]`);
  return box ? box.checked : true;
}

const LEGENDS = {
  tracks: [["swatch", "vehicle", "vehicle"], ["swatch", "human", "human"]],
  synopsis: [["swatch line", "#ccc", "tracked"], ["swatch dash", "#ccc", "hand-off gap"]],
  sensors: [["swatch", "#7fdcff", "camera"]],
  coverage: [["swatch", "rgba(120,200,255,0.35)", "ground footprint"]],
  geolocation: [["swatch", "#ff2bd6", "terrain hit"], ["swatch", "#ffe600", "chosen hit, 1σ"]],
  events: [["swatch", "#70ff70", "track confirmed"], ["swatch", "#ff5050", "track ended"],
    ["swatch", "#b07cff", "activity (loiter, meet, convoy)"], ["swatch", "#5aa0ff", "hand-off"]],
  markers: [["swatch", "#ffffff", "kept marker"]],
  roads: [["swatch line", "#f5ebc8", "road"]],
};

function buildLayerList() {
  const root = $("#layers");
  root.replaceChildren();
  for (const layer of ui.map.layerList()) {
    const name = layer.get("name");
    const box = el("input", { type: "checkbox", checked: layer.getVisible(), "data-layer": name, id: `layer-${name}` });
    box.addEventListener("change", () => {
      layer.setVisible(box.checked);
      if (box.checked) ui.vis.ensure(name); // the visibility layers load when first shown
      ui.dirty = true;
    });
    // One parameter group (target, range) above the first of the visibility layers.
    if (ui.vis.owns(name) && !root.querySelector("#vis-params")) root.append(ui.vis.paramControls());
    root.append(el("div", { class: "layer-row" }, box, el("label", { for: `layer-${name}`, text: layer.get("title") })));
    const controls = ui.vis.controls(name);
    const legend = LEGENDS[name];
    if (controls) {
      root.append(controls);
    } else if (legend) {
      root.append(el("div", { class: "legend" }, ...legend.map(([cls, colour, text]) => {
        const c = colour === "vehicle" || colour === "human" ? classColour(colour) : colour;
        const style = cls.includes("line") || cls.includes("dash") ? `border-color:${c}` : `background:${c}`;
        return el("span", {}, el("span", { class: cls, style }), text);
      })));
    }
  }
}

function buildFilters() {
  const cls = $("#filter-class");
  for (const c of ["vehicle", "human"]) {
    const box = el("input", { type: "checkbox", checked: true, "data-class": c });
    box.addEventListener("change", () => {
      if (box.checked) ui.filters.classes.add(c);
      else ui.filters.classes.delete(c);
      ui.filterVersion += 1;
      ui.dirty = true;
      drawLists(timeline.now());
    });
    cls.append(el("label", {}, box, " ", el("span", { class: "swatch", style: `background:${classColour(c)}` }), ` ${c}`));
  }
  const sens = $("#filter-sensor");
  const chosen = new Set(ui.sensors.map((s) => s.id));
  for (const s of ui.sensors) {
    const box = el("input", { type: "checkbox", checked: true, "data-sensor": s.id });
    box.addEventListener("change", () => {
      if (box.checked) chosen.add(s.id);
      else chosen.delete(s.id);
      ui.filters.sensors = chosen.size === ui.sensors.length ? null : new Set(chosen);
      ui.filterVersion += 1;
      ui.dirty = true;
      drawLists(timeline.now());
    });
    sens.append(el("label", {}, box, ` ${s.id}`));
  }
  $("#filter-track").addEventListener("input", (ev) => {
    const ids = ev.target.value.split(/[\s,;]+/).filter(Boolean).map(Number).filter(Number.isInteger);
    ui.filters.ids = ids.length ? new Set(ids) : null;
    ui.filterVersion += 1;
    ui.dirty = true;
    drawLists(timeline.now());
  });
}

function buildCameras() {
  const root = $("#cameras");
  root.replaceChildren();
  ui.cams.clear();
  for (const s of ui.sensors) {
    const panel = new CameraPanel(s, (p, u, v) => geolocate(p, u, v));
    ui.cams.set(s.id, panel);
    root.append(panel.root);
  }
}

function wireMap() {
  const map = ui.map.map;
  const readout = $("#readout");
  let pending = null;
  let inFlight = false;
  let last = null;
  const ask = async () => {
    if (inFlight || !pending) return;
    const [e, n] = pending;
    pending = null;
    inFlight = true;
    try {
      const r = await api.getJSON(`/api/site/elevation?e=${e.toFixed(2)}&n=${n.toFixed(2)}`);
      if (last && last[0] === e && last[1] === n) {
        readout.textContent = `E ${fmt(e, 1)} m  N ${fmt(n, 1)} m  │  ${fmt(r.lat_deg, 6)}°, ${fmt(r.lon_deg, 6)}°  │  DEM ${r.u_m === null ? "no data" : `${fmt(r.u_m, 1)} m`}`;
      }
    } catch (_) {
      /* offline: keep the local readout */
    } finally {
      inFlight = false;
      if (pending) setTimeout(ask, 30);
    }
  };
  map.on("pointermove", (ev) => {
    if (ev.dragging) return;
    const [e, n] = ev.coordinate;
    last = [e, n];
    readout.textContent = `E ${fmt(e, 1)} m  N ${fmt(n, 1)} m  │  …`;
    pending = [e, n];
    ask();
    map.getTargetElement().style.cursor = ui.map.trackAt(ev.pixel) !== null ? "pointer" : "";
  });
  map.on("singleclick", (ev) => {
    const id = ui.map.trackAt(ev.pixel);
    if (id !== null) select(id);
  });
}

function wireControls() {
  $("#relief-kind").addEventListener("change", (ev) => loadRelief(ev.target.value));
  $("#relief-opacity").addEventListener("input", (ev) => ui.map.relief.setOpacity(Number(ev.target.value)));
  $("#syn-on").addEventListener("change", () => (ui.dirty = true));
  $("#syn-window").addEventListener("change", () => (ui.dirty = true));
  $("#export-tracks").addEventListener("click", () => exportTracks($("#export-format").value, selectionTracks()));
  $("#export-markers").addEventListener("click", () => {
    const format = $("#export-format").value;
    const f = FORMATS[format];
    download(`demtrack-markers.${f.ext}`, f.mime, renderMarkers(format, ui.markers));
  });
  $("#tab-map").addEventListener("click", () => showTab("map"));
  $("#tab-3d").addEventListener("click", () => showTab("3d"));
  document.addEventListener("keydown", (ev) => {
    const tag = (ev.target.tagName || "").toLowerCase();
    if (tag === "input" && (ev.target.type === "text" || ev.target.type === "number")) return;
    if (tag === "select" || $("#token-dialog").open) return;
    if (ev.key === " ") {
      ev.preventDefault();
      timeline.toggle();
    } else if (ev.key === "ArrowLeft" || ev.key === "ArrowRight") {
      ev.preventDefault();
      timeline.step((ev.key === "ArrowLeft" ? -1 : 1) * (ev.shiftKey ? 10 : 1));
    } else if (ev.key === "Escape") {
      clearSelection();
    }
  });
}

/** The 3D view's note: which track its cameras follow (or why they do not). */
function showFollow({ trackId, pending, error, retrying }) {
  const note = $("#follow-3d");
  note.classList.toggle("hidden", trackId === null && !error);
  note.classList.toggle("error", !!error);
  note.textContent = error
    ? `3D follow ${retrying ? "failed, trying again" : "failed"}: ${error}`
    : trackId === null ? "" : `3D cameras follow track #${trackId}${pending ? " …" : ""} · Esc stops`;
}

function showTab(which) {
  const is3d = which === "3d";
  $("#tab-map").classList.toggle("on", !is3d);
  $("#tab-3d").classList.toggle("on", is3d);
  $("#tab-map").setAttribute("aria-selected", String(!is3d));
  $("#tab-3d").setAttribute("aria-selected", String(is3d));
  $("#map-view").classList.toggle("on", !is3d);
  $("#view-3d").classList.toggle("on", is3d);
  const frame = $("#viser");
  if (is3d && ui.viserUrl) {
    if (!frame.src) frame.src = viserFrameUrl(ui.viserUrl, ui.follow3d.session);
    frame.hidden = false;
    $("#no-3d").classList.add("hidden");
  } else if (is3d) {
    frame.hidden = true;
    $("#no-3d").classList.remove("hidden");
  }
  if (!is3d) ui.map.map.updateSize();
}

boot().catch((err) => {
  window.demtrack.bootError = String(err);
  console.error("console start-up failed:", err);
});
