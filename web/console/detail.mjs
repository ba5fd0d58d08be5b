// The selection panel: a track's history (times, sensors, speed profile) or a geolocation.

import { classColour, SELECTED_COLOUR } from "./palette.mjs";
import { fmtClock, zoneLabel } from "./clock.mjs";
import { el, fmt } from "./util.mjs";

/** When each sensor saw the track: {sensor: [[t0, t1], ...]}, breaks longer than `joinS` split. */
export function sensorSpans(track, joinS = 2.0) {
  const spans = {};
  for (const p of track.points) {
    for (const s of p.sensors || []) {
      const list = (spans[s] ||= []);
      const last = list[list.length - 1];
      if (last && p.t_s - last[1] <= joinS) last[1] = p.t_s;
      else list.push([p.t_s, p.t_s]);
    }
  }
  return spans;
}

/** Ground speed (m/s) over a sliding window of at least `winS` seconds: [[t, v], ...]. */
export function speedProfile(track, winS = 2.0) {
  const pts = track.points;
  const out = [];
  let j = 0;
  for (let i = 1; i < pts.length; i += 1) {
    while (j < i - 1 && pts[i].t_s - pts[j + 1].t_s >= winS) j += 1;
    const dt = pts[i].t_s - pts[j].t_s;
    if (dt <= 0) continue;
    let d = 0;
    for (let k = j + 1; k <= i; k += 1) d += Math.hypot(pts[k].e_m - pts[k - 1].e_m, pts[k].n_m - pts[k - 1].n_m);
    out.push([0.5 * (pts[i].t_s + pts[j].t_s), d / dt]);
  }
  return out;
}

/** Draw the speed profile on `canvas`, with a cursor at `tNow`. */
export function drawSpeed(canvas, track, tNow) {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth || 300;
  const h = canvas.clientHeight || 90;
  canvas.width = Math.round(w * dpr);
  canvas.height = Math.round(h * dpr);
  const g = canvas.getContext("2d");
  g.scale(dpr, dpr);
  g.fillStyle = "#11161c";
  g.fillRect(0, 0, w, h);
  const prof = speedProfile(track);
  const left = 34;
  const bottom = h - 16;
  g.font = "10px system-ui, sans-serif";
  g.fillStyle = "#9aa7b4";
  if (prof.length < 2) {
    g.fillText("not enough points for a speed profile", left, h / 2);
    return;
  }
  const t0 = track.points[0].t_s;
  const t1 = track.points[track.points.length - 1].t_s;
  const vmax = Math.max(1, ...prof.map((p) => p[1])) * 1.1;
  const X = (t) => left + ((t - t0) / Math.max(1e-9, t1 - t0)) * (w - left - 6);
  const Y = (v) => bottom - (v / vmax) * (bottom - 6);
  g.strokeStyle = "#2c3642";
  g.lineWidth = 1;
  for (const f of [0, 0.5, 1]) {
    g.beginPath();
    g.moveTo(left, Y(f * vmax));
    g.lineTo(w - 6, Y(f * vmax));
    g.stroke();
    g.fillText(`${(f * vmax).toFixed(f ? 1 : 0)}`, 4, Y(f * vmax) + (f === 1 ? 8 : 3));
  }
  g.fillText("speed, m/s", left + 4, 14);
  g.fillText(fmtClock(t0, { digits: 0 }), left, h - 3);
  g.textAlign = "right";
  g.fillText(fmtClock(t1, { digits: 0 }), w - 6, h - 3);
  g.textAlign = "left";
  // Gaps shaded: no measurement there.
  g.fillStyle = "rgba(255,255,255,0.07)";
  for (const [a, b] of track.gaps || []) g.fillRect(X(a), 6, X(b) - X(a), bottom - 6);
  g.strokeStyle = classColour(track.cls);
  g.lineWidth = 1.5;
  g.beginPath();
  prof.forEach(([t, v], k) => (k ? g.lineTo(X(t), Y(v)) : g.moveTo(X(t), Y(v))));
  g.stroke();
  if (tNow >= t0 && tNow <= t1) {
    g.strokeStyle = SELECTED_COLOUR;
    g.beginPath();
    g.moveTo(X(tNow), 4);
    g.lineTo(X(tNow), bottom);
    g.stroke();
  }
}

export function trackDetail(track, { following, onFollow, onExport, onClose }) {
  const pts = track.points;
  const t0 = pts.length ? pts[0].t_s : null;
  const t1 = pts.length ? pts[pts.length - 1].t_s : null;
  const prof = speedProfile(track);
  const vmean = prof.length ? prof.reduce((a, p) => a + p[1], 0) / prof.length : NaN;
  let length = 0;
  for (let i = 1; i < pts.length; i += 1) length += Math.hypot(pts[i].e_m - pts[i - 1].e_m, pts[i].n_m - pts[i - 1].n_m);
  const spans = sensorSpans(track);
  const canvas = el("canvas", { class: "speed-plot", id: "speed-plot" });
  const root = el(
    "div",
    { class: "detail-track", "data-track": String(track.id) },
    el("div", { class: "detail-head" },
      el("span", { class: "swatch", style: `background:${classColour(track.cls)}` }),
      el("b", { text: `Track ${track.id}` }),
      el("span", { text: ` ${track.cls}${track.live ? " · live" : " · ended"}` }),
      el("span", { class: "grow" }),
      el("button", { id: "follow-btn", class: following ? "on" : "", onclick: onFollow, title: "keep the map centred on this track" }, following ? "Following" : "Follow"),
      el("button", { onclick: onExport, title: "download this track as GeoJSON" }, "GeoJSON"),
      el("button", { onclick: onClose, title: "clear selection (Esc)" }, "✕")),
    el("table", { class: "kv" },
      row("time", `${fmtClock(t0, { withDate: true })} → ${fmtClock(t1)} ${zoneLabel(t0)} (${fmt(t1 - t0, 1)} s)`),
      row("points", `${pts.length}${track.n_points > pts.length ? ` of ${track.n_points}` : ""}`),
      row("path", `${fmt(length, 0)} m, mean ${fmt(vmean, 1)} m/s`),
      row("hand-off gaps", (track.gaps || []).length ? track.gaps.map(([a, b]) => `${fmtClock(a)}–${fmtClock(b)}`).join(", ") : "none")),
    el("table", { class: "kv runs" },
      ...Object.keys(spans).sort().map((k) => {
        const list = spans[k];
        const shown = list.slice(-4).map(([a, b]) => `${fmtClock(a)}–${fmtClock(b)}`).join(", ");
        return row(k, list.length > 4 ? `… ${shown}` : shown);
      })),
    canvas,
  );
  return { root, canvas };
}

function row(k, v) {
  return el("tr", {}, el("th", { text: k }), el("td", { text: v }));
}

/** The geolocation answer as a table: every hit, the chosen ones marked. */
export function geoDetail(res, sensor, { rule, onRule, onKeep, onClose }) {
  const chosen = new Set((res.selected || []).map((h) => `${h.e_m},${h.n_m}`));
  const rows = [];
  (res.hits || []).forEach((h, k) => rows.push(...hitRow(`hit ${k + 1}`, h, chosen.has(`${h.e_m},${h.n_m}`))));
  if (res.road) rows.push(...hitRow("road", res.road, chosen.has(`${res.road.e_m},${res.road.n_m}`)));
  const rules = ["first", "last", "road"].map((r) =>
    el("label", {}, el("input", { type: "radio", name: "geo-rule", value: r, checked: r === rule, onchange: () => onRule(r) }), ` ${r}`));
  return el(
    "div",
    { class: "detail-geo", id: "geo-result", "data-status": res.status },
    el("div", { class: "detail-head" },
      el("b", { text: `Geolocation · ${sensor} pixel (${fmt(res.pixel[0], 1)}, ${fmt(res.pixel[1], 1)})` }),
      el("span", { class: "grow" }),
      el("button", { id: "keep-marker", onclick: onKeep, disabled: !(res.selected || []).length }, "Keep marker"),
      el("button", { onclick: onClose, title: "clear (Esc)" }, "✕")),
    el("div", { class: "rules" }, el("span", { text: "rule: " }), ...rules,
      el("span", { class: "muted", text: ` · ${res.status}${res.crossed_nodata ? " · ray crossed a DEM hole" : ""}` })),
    el("table", { class: "hits" },
      el("tr", {}, ...["", "E m", "N m", "U m", "range m", "σ m"].map((t) => el("th", { text: t }))),
      ...rows),
  );
}

/** A hit as three rows: site frame, range and σ, then its WGS84 position and its grid
 * references (MGRS, UTM) under them (one row of eight columns does not fit the 400 px
 * column: σ was cut off). */
function hitRow(name, h, isChosen) {
  return [
    el("tr", { class: isChosen ? "chosen" : "", "data-e": String(h.e_m), "data-n": String(h.n_m), "data-lat": String(h.lat_deg), "data-lon": String(h.lon_deg) },
      el("td", { text: `${isChosen ? "▶ " : ""}${name}` }),
      el("td", { text: fmt(h.e_m, 2) }), el("td", { text: fmt(h.n_m, 2) }), el("td", { text: fmt(h.u_m, 2) }),
      el("td", { text: fmt(h.range_m, 1) }), el("td", { class: "sigma", text: fmt(h.sigma_m, 2) })),
    el("tr", { class: `latlon${isChosen ? " chosen-ll" : ""}` },
      el("td", { colspan: "6", text: `lat ${fmt(h.lat_deg, 7)}°  lon ${fmt(h.lon_deg, 7)}°` })),
    h.mgrs ? el("tr", { class: `grid-ref${isChosen ? " chosen-ll" : ""}` },
      el("td", { colspan: "6", "data-mgrs": "", title: `UTM ${h.utm.text}`, text: `MGRS ${h.mgrs}  ·  UTM ${h.utm.text}` })) : null,
  ];
}
