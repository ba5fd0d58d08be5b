// The selection and the detail panel: a track picked on the map, in a list or from an
// event (its history in the panel, the 3D scene following it), or a camera pixel
// geolocated (the hits in the panel and on the map). One of them at a time.

import * as api from "./api.mjs";
import { askToken } from "./conn.mjs";
import { drawSpeed, geoDetail, trackDetail } from "./detail.mjs";
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

/** Selects track `id` (ends a geolocation). */
export function select(id) {
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

/** Clears the selected track or geolocation. */
export function clearSelection() {
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
    onExport: () => downloadTracks("geojson", [tr]),
    onClose: clearSelection,
  });
  box.replaceChildren(root);
  detailCanvas = canvas;
  detailVersion = tr.updated;
  drawSpeed(canvas, tr, timeline.now());
}

/** From the frame loop: the selected track's detail again when DETAIL_EVERY_MS have
 * passed (rebuilt when the track changed, else only the speed plot's time cursor). */
export function tickDetail(nowMs, t) {
  if (nowMs - lastDetailDraw <= DETAIL_EVERY_MS) return;
  lastDetailDraw = nowMs;
  if (ui.geo || ui.selectedId === null) return;
  const tr = store.tracks.get(ui.selectedId);
  if (!tr) return;
  if (tr.updated !== detailVersion) renderDetail();
  else if (detailCanvas) drawSpeed(detailCanvas, tr, t);
}

/** Geolocates pixel (u, v) of a camera panel with the chosen rule (ends a track selection). */
export async function geolocate(panel, u, v) {
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

