// The page's controls: the camera panels (a click geolocates), the map's cursor readout
// and track picking, the DEM, trajectory and export controls, the Map / 3D tabs and the
// keyboard (space, arrows, Esc).

import * as api from "./api.mjs";
import { CameraPanel, fitCameras } from "./cameras.mjs";
import { downloadMarkers, downloadTracks } from "./export.mjs";
import { viserFrameUrl } from "./follow.mjs";
import { clearSelection, geolocate, select } from "./selection.mjs";
import { store, timeline, trackList, ui, visible } from "./state.mjs";
import { clipTrack, synopsisWindow } from "./synopsis.mjs";
import { CLASS_COLOURS, HIT_COLOUR, SELECTED_COLOUR } from "./palette.mjs";
import { $, el, fmt } from "./util.mjs";

/** The DEM layer's image of that kind (shaded-relief, hillshade, relief). */
export async function loadRelief(kind) {
  const url = await api.imageURL(`/api/site/relief.png?kind=${encodeURIComponent(kind)}`);
  const old = ui.map.relief.getSource();
  ui.map.setImage(ui.map.relief, url, ui.site.dem.bounds_enu);
  const oldUrl = old?.getUrl?.();
  if (oldUrl) URL.revokeObjectURL(oldUrl);
}

/** What "Export tracks" saves: the selected track, else the tracks passing the filters,
 * clipped to the trajectory window when that is shown. */
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

/** A panel per sensor in the right column. */
export function buildCameras() {
  const root = $("#cameras");
  root.replaceChildren();
  ui.cams.clear();
  for (const s of ui.sensors) {
    const panel = new CameraPanel(s, (p, u, v) => geolocate(p, u, v));
    panel.setColour(ui.map.sensorColour(s.id)); // the camera's colour everywhere (palette.mjs)
    ui.cams.set(s.id, panel);
    root.append(panel.root);
  }
  fitCameras(root, () => ui.cams.values())();
  build3dLegend();
}

/** The 3D view's legend: the scene's colours are the map's (palette.mjs, server/scene3d/style.py). */
function build3dLegend() {
  const item = (colour, text, kind = "swatch") =>
    el("span", {}, el("span", { class: kind, style: kind === "swatch" ? `background:${colour}` : `border-color:${colour}` }), text);
  $("#legend-3d").replaceChildren(
    el("b", { text: "3D scene" }),
    item(CLASS_COLOURS.vehicle, "vehicle track (ended: dimmed)", "swatch line"),
    item(CLASS_COLOURS.human, "human track (ended: dimmed)", "swatch line"),
    item(SELECTED_COLOUR, "followed track, tracker's chosen hit", "swatch line"),
    item(HIT_COLOUR, "terrain hits of the newest rays"),
    ...ui.sensors.map((s) => item(ui.map.sensorColour(s.id), `${s.id}: frustum and rays`, "swatch line")),
  );
}

/** The cursor readout's text for an /api/site/elevation answer: the elevation in its
 * vertical datum (named), then the local frame's up. */
export function readoutText(e, n, r) {
  const where = `E ${fmt(e, 1)} m  N ${fmt(n, 1)} m  │  ${fmt(r.lat_deg, 6)}°, ${fmt(r.lon_deg, 6)}°`;
  if (r.u_m === null || r.u_m === undefined) return `${where}  │  off the DEM`;
  const elev = r.elevation_m !== undefined && r.elevation_m !== null
    ? `elevation ${fmt(r.elevation_m, 1)} m (${r.elevation_datum})`
    : `h ${fmt(r.h_m, 1)} m (WGS84 ellipsoid)`;
  return `${where}  │  ${elev} · local up ${fmt(r.u_m, 1)} m`;
}

/** The cursor readout (site frame at once, then WGS84 and the DEM from the API; one
 * request in flight, the newest position wins) and a click on a track selects it. */
export function wireMap() {
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
        readout.textContent = readoutText(e, n, r);
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

/** The sidebar's and the timeline bar's controls, the tabs and the keyboard. */
export function wireControls() {
  $("#relief-kind").addEventListener("change", (ev) => loadRelief(ev.target.value));
  $("#relief-opacity").addEventListener("input", (ev) => ui.map.relief.setOpacity(Number(ev.target.value)));
  $("#syn-on").addEventListener("change", () => (ui.dirty = true));
  $("#syn-window").addEventListener("change", () => (ui.dirty = true));
  $("#export-tracks").addEventListener("click", () => downloadTracks($("#export-format").value, selectionTracks()));
  $("#export-markers").addEventListener("click", () => downloadMarkers($("#export-format").value));
  $("#tab-map").addEventListener("click", () => showTab("map"));
  $("#tab-3d").addEventListener("click", () => showTab("3d"));
  ui.follow3d.register().catch(() => {}); // at once: the 3D tab then loads without waiting
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
    } else if (ev.key === "Home") {
      ev.preventDefault();
      ui.map.home();
    }
  });
}

/** The 3D view's note: which track its cameras follow (or why they do not). */
export function showFollow({ trackId, pending, error, retrying }) {
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
  document.body.dataset.tab = which; // the 2D layer controls hide in the 3D tab (style.css)
  $("#legend-3d").classList.toggle("hidden", !ui.viserUrl);
  const frame = $("#viser");
  if (is3d && ui.viserUrl) {
    // The scene admits only viser clients of a session the page registered with its
    // operator token (follow.mjs), so the iframe loads once that is done.
    if (!frame.src && ui.follow3d.admitted) {
      frame.src = viserFrameUrl(ui.viserUrl, ui.follow3d.session);
    } else if (!frame.src && !frame.dataset.pending) {
      frame.dataset.pending = "1";
      ui.follow3d.register().then(() => {
        frame.src = viserFrameUrl(ui.viserUrl, ui.follow3d.session);
      }, (err) => {
        showFollow({ trackId: null, error: `3D view refused: ${err.message || err}` });
      }).finally(() => delete frame.dataset.pending);
    }
    frame.hidden = false;
    $("#no-3d").classList.add("hidden");
  } else if (is3d) {
    frame.hidden = true;
    $("#no-3d").classList.remove("hidden");
  }
  if (!is3d) ui.map.map.updateSize();
}
