// Kept markers: points the operator keeps, stored on the server (/api/markers), so they
// survive a reload and every console sees them.
//
// "Keep marker" (the geolocation detail) draws the chosen hit at once and posts it with the
// shown time to POST /api/markers; then a small form above the marker list names it and
// adds a note (PATCH /api/markers/{id}). The server answers the marker with its WGS84
// position, MGRS reference and UTC time, and streams every change (`marker` message,
// action add / update / delete) to every console, this one included: the list is what
// the server holds (GET /api/markers at start-up, then the stream). A row shows
// the name, the clock time (UTC), the MGRS reference, lat/lon and site-frame E/N; a click
// centres the map on it; ✕ deletes it on the server (DELETE /api/markers/{id}).

import * as api from "./api.mjs";
import { fmtClock, zoneLabel } from "./events.mjs";
import { timeline, ui } from "./state.mjs";
import { $, el, fmt } from "./util.mjs";

/** The shape the map and the exports read: the server's body, its source flattened. */
function shown(body) {
  const src = body.source || {};
  return {
    ...body,
    sensor: src.sensor ?? "",
    pixel: src.pixel ?? [NaN, NaN],
    rule: src.rule ?? "",
    range_m: src.range_m ?? NaN,
    sigma_m: src.sigma_m ?? NaN,
  };
}

/** Start-up: the stored markers (the stream adds and removes from then on). */
export async function loadMarkers() {
  try {
    const r = await api.getJSON("/api/markers");
    const byId = new Map(ui.markers.map((m) => [m.id, m]));
    for (const m of r.markers || []) byId.set(m.id, shown(m));
    ui.markers = [...byId.values()].sort((a, b) => a.id - b.id);
  } catch (err) {
    // a server without markers: the list says so, nothing else breaks
    $("#marker-list").replaceChildren(el("div", { class: "muted", text: `markers unavailable: ${err.message || err}` }));
    return;
  }
  drawMarkers();
}

/** A `marker` stream message: a marker added or removed (by any console). */
export function onMarkerMessage(msg) {
  if ((msg.action === "add" || msg.action === "update") && msg.marker) {
    const k = msg.marker;
    // it replaces the same marker, and this page's own not yet answered one of that point
    const same = (m) => m.id === msg.id || (m.id < 0 && m.e_m === k.e_m && m.n_m === k.n_m && m.t_s === k.t_s);
    ui.markers = ui.markers.filter((m) => !same(m)).concat([shown(k)]).sort((a, b) => a.id - b.id);
  } else if (msg.action === "delete") {
    ui.markers = ui.markers.filter((m) => m.id !== msg.id);
  }
  drawMarkers();
}

let pendingN = 0; // markers shown before the server's answer (negative ids)

/** Keeps the chosen hit of the geolocation shown as a marker: drawn at once, stored on the
 * server (POST /api/markers, with the shown time), then a form above the list to name it
 * and add a note (PATCH /api/markers/{id}). */
export async function keepMarker() {
  const res = ui.geo?.result;
  const h = res?.selected?.[0];
  if (!h) return;
  const t = timeline.now();
  const source = { sensor: res.sensor, pixel: res.pixel, rule: res.rule, range_m: h.range_m, sigma_m: h.sigma_m };
  pendingN -= 1;
  const pending = shown({ id: pendingN, t_s: t, time_utc: "", name: "…", note: "", mgrs: "", ...h, source });
  ui.markers = ui.markers.concat([pending]);
  drawMarkers();
  let stored;
  try {
    stored = await api.postJSON("/api/markers", { t_s: t, e_m: h.e_m, n_m: h.n_m, u_m: h.u_m, source });
  } catch (err) {
    ui.markers = ui.markers.filter((m) => m !== pending);
    drawMarkers();
    $("#marker-list").prepend(el("div", { class: "error", text: `marker not kept: ${err.message || err}` }));
    if (err instanceof api.AuthError) import("./conn.mjs").then((c) => c.askToken(err.message));
    return;
  }
  ui.markers = ui.markers.filter((m) => m !== pending && m.id !== stored.id).concat([shown(stored)]).sort((a, b) => a.id - b.id);
  drawMarkers();
  editForm(stored);
}

/** The name / note form of marker `m` above the list (Save: PATCH; Skip: close). */
function editForm(m) {
  const name = el("input", { id: "marker-name", type: "text", value: m.name, maxlength: "200", placeholder: `name (empty: M${m.id})` });
  const note = el("input", { id: "marker-note", type: "text", value: m.note || "", maxlength: "4000", placeholder: "note" });
  const msg = el("span", { class: "error", id: "marker-error" });
  const form = el("form", {
    id: "marker-form",
    "data-marker": String(m.id),
    onsubmit: async (ev) => {
      ev.preventDefault();
      try {
        const resp = await fetch(`/api/markers/${m.id}`, {
          method: "PATCH",
          headers: { Authorization: `Bearer ${api.token()}`, "Content-Type": "application/json" },
          body: JSON.stringify({ name: name.value.trim(), note: note.value }),
        });
        if (!resp.ok) throw new Error(`${resp.status} ${(await resp.json().catch(() => ({}))).detail || resp.statusText}`);
        form.remove(); // the stream's `marker` message updates the list of every console
      } catch (err) {
        msg.textContent = String(err.message || err);
      }
    },
  },
  el("div", { class: "muted", text: `${m.name} · ${m.mgrs} · ${fmtClock(m.t_s, { withDate: true })} ${zoneLabel(m.t_s)}` }),
  el("div", { class: "row" }, name), el("div", { class: "row" }, note),
  el("div", { class: "row" }, el("button", { type: "submit", id: "marker-save" }, "Save"),
    el("button", { type: "button", onclick: () => form.remove() }, "Skip"), msg));
  $("#marker-form")?.remove();
  $("#marker-list").before(form);
}

async function removeMarker(m) {
  if (m.id < 0) return; // not stored yet
  // the stream's `marker` message takes it out of the list (of every console)
  const resp = await fetch(`/api/markers/${m.id}`, { method: "DELETE", headers: { Authorization: `Bearer ${api.token()}` } })
    .catch((err) => ({ ok: false, status: 0, statusText: String(err) }));
  if (!resp.ok && resp.status !== 404) {
    $("#marker-list").prepend(el("div", { class: "error", text: `removing ${m.name}: ${resp.status} ${resp.statusText}` }));
  }
}

export function drawMarkers() {
  ui.map.drawMarkers(ui.markers);
  $("#export-markers").disabled = !ui.markers.length;
  $("#marker-list").replaceChildren(...ui.markers.map((m) => el("div", {
    "data-marker": String(m.id),
    title: `${m.note ? `${m.note} — ` : ""}${m.time_utc}${m.sensor ? `; ${m.sensor} pixel ${m.pixel.join(", ")}, rule ${m.rule}` : ""}`,
    style: "white-space:normal;flex-wrap:wrap",
    onclick: () => ui.map.centreOn(m.e_m, m.n_m),
  },
  el("b", { text: m.name }),
  m.id < 0 ? el("span", { class: "muted", text: "saving…" }) : el("span", { class: "mono muted", text: `${fmtClock(m.t_s)} ${zoneLabel(m.t_s)}` }),
  el("span", { class: "mono", "data-mgrs": "", text: m.mgrs }),
  m.utm ? el("span", { class: "mono muted", "data-utm": "", text: `UTM ${m.utm}` }) : null,
  el("span", { class: "mono muted", text: `${fmt(m.lat_deg, 6)}°, ${fmt(m.lon_deg, 6)}° · E ${fmt(m.e_m, 1)} N ${fmt(m.n_m, 1)}` }),
  m.note ? el("span", { class: "muted", text: m.note }) : null,
  el("span", { class: "grow" }),
  el("button", {
    title: "remove marker (for every console)",
    onclick: (ev) => {
      ev.stopPropagation();
      removeMarker(m);
    },
  }, "✕"))));
}
