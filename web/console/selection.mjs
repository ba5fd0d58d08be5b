// The selection and the detail panel: a track picked on the map, in a list or from an
// event (its history in the panel, the 3D scene following it), or a camera pixel
// geolocated (the hits in the panel and on the map). One of them at a time.
//
// Selecting an event (`selectEvent`: a row of the event list, an episode on the map)
// selects all its tracks: `ui.selectedEvent` holds it, `ui.selectedIds` its tracks (the
// lists and the activity layer mark them all), and the first is the track shown below the
// event in the detail panel (each of the others one click away). A track's detail ends
// with its hand-off prediction (events.mjs `predictions`), which is not an event.

import * as api from "./api.mjs";
import { askToken } from "./conn.mjs";
import { drawSpeed, geoDetail, trackDetail } from "./detail.mjs";
import { applyPrediction, fmtClock, KIND, predictions, predictionText, zoneLabel } from "./events.mjs";
import { downloadTracks } from "./export.mjs";
import { keepMarker } from "./markers.mjs";
import { store, timeline, ui } from "./state.mjs";
import { $, el } from "./util.mjs";

const DETAIL_EVERY_MS = 250; // the frame loop refreshes the detail panel at most this often
let lastDetailDraw = 0;
const listeners = [];

/** fn() after every change of the selection (the lists mark the selected track). */
export function onSelectionChange(fn) {
  listeners.push(fn);
}

function selectionChanged() {
  for (const fn of listeners) fn();
}

/** Selects track `id` (ends a geolocation and an event selection). */
export function select(id, { keepEvent = false } = {}) {
  if (!keepEvent) {
    ui.selectedEvent = null;
    ui.selectedIds = id === null ? new Set() : new Set([id]);
  }
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
  selectionChanged();
}

/** Selects event `ev` and all its tracks (the first held one shown in the detail). */
export function selectEvent(ev) {
  ui.selectedEvent = ev;
  ui.selectedIds = new Set(ev.track_ids || []);
  const first = (ev.track_ids || []).find((id) => store.tracks.has(id)) ?? null;
  select(first, { keepEvent: true });
}

/** Whether track `id` is selected (alone, or as one of the selected event's tracks). */
export function isSelected(id) {
  return id === ui.selectedId || !!ui.selectedIds?.has(id);
}

/** Clears the selected track or geolocation. */
export function clearSelection() {
  ui.selectedEvent = null;
  ui.selectedIds = new Set();
  ui.selectedId = null;
  ui.following = false;
  ui.follow3d.set(null);
  ui.geo = null;
  for (const p of ui.cams.values()) p.click = null;
  ui.map.drawGeolocation(null);
  ui.dirty = true;
  renderDetail();
  selectionChanged();
}

let detailCanvas = null; // the speed plot of the track shown
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
  const head = ui.selectedEvent ? eventHead(ui.selectedEvent) : null;
  if (!tr) {
    box.replaceChildren(...(head ? [head] : []), el("p", { class: "muted hint", text: "Click a camera image to geolocate a pixel; click a track on the map or in the list to see its history." }));
    return;
  }
  const { root, canvas } = trackDetail(tr, {
    following: ui.following,
    onFollow: () => {
      ui.following = !ui.following;
      renderDetail();
      ui.dirty = true;
    },
    onExport: () => downloadTracks("geojson", [tr]),
    onClose: clearSelection,
  });
  root.append(predictionBlock(tr));
  box.replaceChildren(...(head ? [head] : []), root);
  detailCanvas = canvas;
  const pv = predictions.get(tr.id);
  detailVersion = `${tr.updated}|${pv ? pv.t_s + pv.text : ""}`;
  drawSpeed(canvas, tr, timeline.now());
}

/** The selected event above the track's detail: what, when, and each of its tracks. */
function eventHead(ev) {
  return el("div", { class: "detail-event", "data-event": ev.key || "" },
    el("div", { class: "detail-head" },
      el("b", { text: ev.text }),
      el("span", { class: "grow" }),
      el("button", { onclick: clearSelection, title: "clear selection (Esc)" }, "✕")),
    el("div", { class: "muted", text: `${fmtClock(ev.t_s, { withDate: true })}${ev.t_end_s > ev.t_s ? `–${fmtClock(ev.t_end_s)}` : ""} ${zoneLabel(ev.t_s)}` }),
    el("div", { class: "row" }, ...(ev.track_ids || []).map((id) => el("button", {
      class: id === ui.selectedId ? "on" : "",
      "data-track": String(id),
      disabled: !store.tracks.has(id),
      title: store.tracks.has(id) ? `show track ${id}` : "track not held by this page",
      onclick: () => select(id, { keepEvent: true }),
    }, `#${id}`))));
}

const asked = new Set(); // tracks whose prediction was asked of /api/events

/** The track's hand-off prediction (an annotation, updated in place; not an event). */
function predictionBlock(tr) {
  const p = predictions.get(tr.id);
  if (!p && tr.live && ui.endpoints?.events && !asked.has(tr.id)) {
    asked.add(tr.id); // loaded before this page held the stream: ask once
    api.getOptionalJSON(`/api/events?kind=${KIND.HANDOFF}&track=${tr.id}&limit=1`).then((r) => {
      for (const e of r?.events || []) applyPrediction(e);
      if (predictions.has(tr.id) && ui.selectedId === tr.id) renderDetail();
    }).catch(() => {});
  }
  const text = !tr.live ? "none (track ended)" : p ? predictionText(p) : "none";
  const t = timeline.now();
  const age = p && tr.live
    ? `predicted at ${fmtClock(p.t_s)} ${zoneLabel(p.t_s)}${p.details?.exit_t_s < t ? " · its exit time has passed" : ""}`
    : null;
  return el("table", { class: "kv prediction" },
    el("tr", {}, el("th", { text: "hand-off (predicted)" }), el("td", { "data-prediction": p ? p.key : "", text })),
    age ? el("tr", {}, el("th", { text: "" }), el("td", { class: "muted", text: age })) : null);
}

/** From the frame loop: the selected track's detail again when DETAIL_EVERY_MS have
 * passed (rebuilt when the track changed, else only the speed plot's time cursor). */
export function tickDetail(nowMs, t) {
  if (nowMs - lastDetailDraw <= DETAIL_EVERY_MS) return;
  lastDetailDraw = nowMs;
  if (ui.geo || ui.selectedId === null) return;
  const tr = store.tracks.get(ui.selectedId);
  if (!tr) return;
  const p = predictions.get(tr.id);
  const version = `${tr.updated}|${p ? p.t_s + p.text : ""}`;
  if (version !== detailVersion) renderDetail();
  else if (detailCanvas) drawSpeed(detailCanvas, tr, t);
}

/** Geolocates pixel (u, v) of a camera panel with the chosen rule (ends a track selection). */
export async function geolocate(panel, u, v) {
  const rule = ui.rule;
  ui.selectedId = null;
  ui.selectedEvent = null;
  ui.selectedIds = new Set();
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

