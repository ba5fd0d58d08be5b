// Pan-tilt-zoom heads in the camera panels: what each active head does and where it
// points, and the operator's controls.
//
// At start-up GET /api/heads lists the active heads (a fixed camera gets nothing; a server
// without heads answers 404 or an empty list). An active camera's panel gets a strip under its
// image: the mode (idle, slew, look, follow, handoff) with its target (a track id, a
// ground point, a pan/tilt), the head's reported pan, tilt and horizontal field of view,
// and three buttons:
//   "Follow selected track"  PUT /api/sensors/{id}/follow {track_id: the selected track}
//   "Release"                DELETE /api/sensors/{id}/follow
//   "Look here"              the next click on the map points the head there:
//                            PUT /api/sensors/{id}/slew {e_m, n_m} (the server checks the
//                            sight line and answers 422 with the reason when it cannot)
// The strips are refreshed from GET /api/heads about once a second; an answer's error is shown
// in the strip until the next command. `window.demtrack.ptz` exposes the state for tests.

import * as api from "./api.mjs";
import { fitCameras } from "./cameras.mjs";
import { ui } from "./state.mjs";
import { $, el, fmt } from "./util.mjs";

const POLL_MS = 1000;

export const ptz = {
  heads: new Map(), // sensor id -> the server's last head body
  strips: new Map(), // sensor id -> {root, text, error}
  lookFor: null, // sensor id waiting for a map click ("Look here"), or null
};

const path = (id, what) => `/api/sensors/${encodeURIComponent(id)}/${what}`;

function targetText(h) {
  const t = h.target || {};
  if (h.mode === "follow") return `following track ${t.track_id}${t.from ? ` (from ${t.from})` : ""}`;
  if (h.mode === "handoff") return `slewing ahead for track ${t.track_id} (from ${t.from})`;
  if (h.mode === "look") return `looking at E ${fmt(t.e_m, 1)} N ${fmt(t.n_m, 1)} m`;
  if (h.mode === "slew") return `slewed to pan ${fmt(t.pan_deg, 1)}° tilt ${fmt(t.tilt_deg, 1)}°`;
  return t.reason ? `idle (${t.reason})` : "idle";
}

function draw(id) {
  const h = ptz.heads.get(id);
  const s = ptz.strips.get(id);
  if (!h || !s) return;
  const st = h.status;
  const pose = st
    ? `pan ${fmt(st.pan_deg, 1)}° tilt ${fmt(st.tilt_deg, 1)}° hfov ${fmt(st.hfov_deg, 1)}°${st.moving ? " · moving" : ""}`
    : "no status yet";
  s.root.dataset.mode = h.mode;
  s.mode.textContent = targetText(h);
  s.pose.textContent = pose;
  s.look.classList.toggle("on", ptz.lookFor === id);
}

function showError(id, err) {
  const s = ptz.strips.get(id);
  if (s) s.error.textContent = err ? String(err.detail || err.message || err) : "";
}

async function command(id, method, what, body) {
  showError(id, null);
  try {
    const h = method === "DELETE" ? await api.deleteJSON(path(id, what)) : await api.putJSON(path(id, what), body);
    ptz.heads.set(id, h);
    draw(id);
  } catch (err) {
    showError(id, err);
  }
}

function strip(id) {
  const mode = el("span", { class: "ptz-mode" });
  const pose = el("span", { class: "ptz-pose mono" });
  const error = el("span", { class: "ptz-error error", role: "status" });
  const follow = el("button", {
    class: "ptz-follow",
    title: "this head follows the track selected on the map or in the list",
    text: "Follow selected track",
    onclick: () => {
      if (ui.selectedId === null || ui.selectedId === undefined) showError(id, "select a track first");
      else command(id, "PUT", "follow", { track_id: ui.selectedId });
    },
  });
  const release = el("button", { class: "ptz-release", text: "Release", onclick: () => command(id, "DELETE", "follow") });
  const look = el("button", {
    class: "ptz-look",
    title: "then click on the map: the head points there",
    text: "Look here",
    onclick: () => {
      ptz.lookFor = ptz.lookFor === id ? null : id;
      ui.map.map.getTargetElement().style.cursor = ptz.lookFor ? "crosshair" : "";
      for (const k of ptz.strips.keys()) draw(k);
    },
  });
  const root = el("div", { class: "ptz", "data-sensor": id }, el("div", { class: "ptz-line" }, mode, pose), el("div", { class: "ptz-line" }, follow, release, look), error);
  return { root, mode, pose, error, look };
}

async function refresh() {
  try {
    for (const h of await api.getJSON("/api/heads")) {
      ptz.heads.set(h.sensor_id, h);
      draw(h.sensor_id);
    }
  } catch (_) {
    /* offline for a moment: keep what is shown */
  }
}

/** Start-up: a strip in each active head's camera panel, the map's "Look here" click. */
export async function installPtz() {
  window.demtrack.ptz = ptz;
  const heads = (await api.getOptionalJSON("/api/heads").catch(() => null)) || [];
  for (const h of heads) {
    const panel = ui.cams.get(h.sensor_id);
    if (!panel) continue;
    const st = strip(h.sensor_id);
    ptz.strips.set(h.sensor_id, st);
    ptz.heads.set(h.sensor_id, h);
    panel.root.append(st.root);
    panel.root.dataset.ptz = "1";
    draw(h.sensor_id);
    panel.extraHeight = st.root.offsetHeight; // fitCameras leaves room for the strip
  }
  if (ptz.strips.size) fitCameras($("#cameras"), () => ui.cams.values())();
  ui.map.map.on("singleclick", (ev) => {
    const id = ptz.lookFor;
    if (!id) return;
    ptz.lookFor = null;
    ui.map.map.getTargetElement().style.cursor = "";
    const [e, n] = ev.coordinate;
    command(id, "PUT", "slew", { e_m: Math.round(e * 100) / 100, n_m: Math.round(n * 100) / 100 });
  });
  if (ptz.strips.size) setInterval(refresh, POLL_MS);
  document.body.dataset.ptz = String(ptz.strips.size);
}
