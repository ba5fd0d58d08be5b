// The operator console: loads the site, wires the map, cameras, timeline and stream.
//
// Data flow: GET /api/health gives the newest stream seq, GET /api/tracks the tracks so
// far, then /ws?since=<seq> streams what follows (fixes, track updates, events;
// messages.mjs). The map and the camera panels are redrawn on animation frames when the
// data or the shown time changed (frame.mjs). `window.demtrack` exposes the state for the
// browser tests.
//
// This module is the start-up; the page's parts live in their own modules:
// state.mjs (store, ui, timeline, filters), conn.mjs (status pill, token dialog),
// events.mjs (event kinds and shape), messages.mjs (stream messages), frame.mjs (redraw
// loop), synopsis.mjs (trajectories), lists.mjs (track and event lists), selection.mjs
// (selection, detail panel, geolocation), markers.mjs, sidebar.mjs (layers, legends,
// filters), controls.mjs (cameras, map pointer, buttons, tabs, keyboard).

import * as api from "./api.mjs";
import { installActivityLayer } from "./activity_layer.mjs";
import { askToken, setConn, wireTokenForm } from "./conn.mjs";
import { buildCameras, loadRelief, showFollow, wireControls, wireMap } from "./controls.mjs";
import { eventsFromTracks, normEvent } from "./events.mjs";
import { SceneFollow } from "./follow.mjs";
import { startFrames } from "./frame.mjs";
import { drawLists } from "./lists.mjs";
import { SiteMap } from "./map.mjs";
import { loadMarkers } from "./markers.mjs";
import { onMessage, onReset } from "./messages.mjs";
import { installPtz } from "./ptz.mjs";
import { onSelectionChange } from "./selection.mjs";
import { buildFilters, buildLayerList } from "./sidebar.mjs";
import { store, timeline, ui } from "./state.mjs";
import { Stream } from "./stream.mjs";
import { $ } from "./util.mjs";
import { installVideo } from "./video.mjs";
import { VisibilityLayers } from "./visibility.mjs";

let stream = null;

window.demtrack = { store, ui, timeline, get stream() { return stream; } };

async function boot() {
  const t0 = performance.now();
  api.takeTokenFromUrl();
  wireTokenForm();
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
  installActivityLayer(ui.map); // loitering circles, rendezvous links, convoys (activity_layer.mjs)
  ui.vis = new VisibilityLayers(ui.map, site, sensors);
  ui.follow3d = new SceneFollow(!!ui.viserUrl, showFollow);
  ui.past.onLoad = () => (ui.dirty = true);
  onSelectionChange(() => drawLists(timeline.now())); // the lists mark the selected track
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
  // The events of the newest ten minutes (a long session's first 1000 would be its oldest);
  // the event list asks for any other moment's when it is shown (lists.mjs).
  const events = ui.endpoints.events
    ? tracks.catch(() => {}).then(() => {
      const q = store.tMax === null ? "?limit=2000" : `?t_from=${store.tMax - 600}&limit=2000`;
      return api.getOptionalJSON(`/api/events${q}`);
    }).then((r) => {
      const list = Array.isArray(r) ? r : r?.events;
      for (const e of list || []) store.applyEvent(normEvent({ kind: e.kind, t_s: e.t_start_s, event: e }));
    }).catch(() => {})
    : Promise.resolve();
  const markers = loadMarkers(); // stored markers (markers.mjs); the stream keeps them current
  const heads = installPtz(); // the active heads' strips in the camera panels (ptz.mjs)
  installVideo(); // live frames over the stills where the server has them (video.mjs)
  await Promise.all([ortho, relief, roads, images, tracks, events, markers, heads]);
  if (!store.events.length) { // no event log on this server (or none yet)
    eventsFromTracks(store.tracks.values()).forEach((e) => store.applyEvent(e));
  }
  stream = new Stream({
    onMessage,
    onStatus: setConn,
    onHello: () => {},
    onReset,
  });
  stream.start(health.last_seq);
  ui.loadMs = performance.now() - t0;
  ui.readyMs = performance.now(); // since navigation start
  document.body.dataset.ready = "1";
  ui.dirty = true;
  startFrames();
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

boot().catch((err) => {
  window.demtrack.bootError = String(err);
  console.error("console start-up failed:", err);
});
