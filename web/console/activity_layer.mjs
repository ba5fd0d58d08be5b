// Activity on the map: each loitering, rendezvous and convoy episode of the chosen window
// drawn as what it is.
//
// - loitering: a circle of the episode's extent radius round where it happened, labelled
//   with the track, the duration and the radius;
// - rendezvous: a link between the meeting tracks (their positions in the middle of the
//   meeting), labelled with the tracks, the duration and their mean distance;
// - convoy: the members in column order, head first, each numbered (1 = head), joined
//   along the road each drove behind the one ahead (chainAlongRoad).
//
// The window is the trajectories' window (synopsis.mjs `synopsisWindow`: 1 min to all)
// ending at the shown time, so an episode stays on the map as long as the operator's
// window holds it. The filters apply (state.mjs `eventVisible`). The selected event
// (selection.mjs `selectEvent`) is drawn in the selection colour together with its tracks'
// paths over the episode. A click on an episode selects it and all its tracks.
//
// Installed with one line in main.mjs (`installActivityLayer(ui.map)`); it redraws itself
// on animation frames when the events, the shown time, the window, the filters or the
// selection changed.

import { ACTIVITY_COLOUR, ACTIVITY_KINDS, fmtClock, KIND, zoneLabel } from "./events.mjs";
import { SELECTED_COLOUR } from "./palette.mjs";
import { selectEvent } from "./selection.mjs";
import { eventVisible, store, timeline, ui } from "./state.mjs";
import { positionAt } from "./store.mjs";
import { synopsisWindow } from "./synopsis.mjs";

const REDRAW_EVERY_MS = 250;

/** Where track `tr` was at time t: interpolated, else its nearest held point. */
function where(tr, t) {
  if (!tr || !tr.points.length) return null;
  const p = positionAt(tr, t);
  if (p) return [p.e_m, p.n_m];
  const pts = tr.points;
  const q = t < pts[0].t_s ? pts[0] : pts[pts.length - 1];
  return [q.e_m, q.n_m];
}

/** A convoy's chain at time tc through the members' positions `pts` (column order, head
 * first; `tracks` theirs): from each member to the one ahead of it along the road that one
 * drove (a follower drives the path of the car ahead; it can be 30 s behind, 200 m or more
 * round a bend, where a straight link would cut across the map). A straight link only
 * between two members where the one ahead's path held in the page does not pass within
 * CHAIN_NEAR_M of the other. */
export function chainAlongRoad(tracks, pts, tc) {
  const line = [pts[pts.length - 1]];
  for (let k = pts.length - 1; k > 0; k -= 1) {
    line.push(...roadBetween(tracks[k - 1], pts[k], tc), pts[k - 1]);
  }
  return line;
}

/** The points of `ahead`'s path from the one nearest `from` (within CHAIN_NEAR_M, in the
 * CHAIN_SPAN_S before tc) to its last before tc; none when it does not pass there. */
function roadBetween(ahead, from, tc) {
  const path = ahead ? ahead.points.filter((p) => p.t_s <= tc && p.t_s >= tc - CHAIN_SPAN_S) : [];
  let best = -1;
  let bestD = CHAIN_NEAR_M ** 2;
  path.forEach((p, k) => {
    const d = (p.e_m - from[0]) ** 2 + (p.n_m - from[1]) ** 2;
    if (d <= bestD) { best = k; bestD = d; }
  });
  return best < 0 ? [] : path.slice(best).map((p) => [p.e_m, p.n_m]);
}

const CHAIN_SPAN_S = 120; // how far back a member's path is searched for its follower (s)
const CHAIN_NEAR_M = 10; // a follower on the path ahead is this close to one of its points

function dur(ev) {
  return Math.max(0, (ev.t_end_s ?? ev.t_s) - ev.t_s);
}

/** The activity episodes of window [a, b] that pass the filters, oldest first. */
export function activityInWindow(a, b) {
  return store.events.filter((ev) => ACTIVITY_KINDS.has(ev.kind) && ev.t_s !== null
    && ev.t_s <= b && (ev.t_end_s ?? ev.t_s) >= a && eventVisible(ev));
}

export class ActivityLayer {
  constructor(siteMap) {
    this.siteMap = siteMap;
    this.layer = new ol.layer.Vector({
      source: new ol.source.Vector(),
      style: (f, res) => this.style(f, res),
      zIndex: 7,
    });
    this.layer.set("name", "activity");
    this.layer.set("title", "Activity (loiter, meet, convoy)");
    siteMap.map.addLayer(this.layer);
    // The episodes' labels on a layer of their own that declutters: where episodes crowd
    // (a busy road's convoys), a label that would overlap one already drawn is left out
    // rather than stacked into an unreadable block; the shapes all stay.
    this.labels = new ol.layer.Vector({
      source: new ol.source.Vector(),
      style: (f, res) => this.style(f, res),
      declutter: "activity", // decluttered among themselves only
      // what is rendered first wins the declutter: the selected episode's label, then in
      // the order drawn (OpenLayers' own order is its feature ids, not the source's order)
      renderOrder: (a, b) => Number(b.get("sel")) - Number(a.get("sel")) || a.get("n") - b.get("n"),
      zIndex: 8,
    });
    this.labels.set("name", "activity-labels");
    this.layer.on("change:visible", () => this.labels.setVisible(this.layer.getVisible()));
    siteMap.map.addLayer(this.labels);
    this.sig = null;
    this.lastDraw = 0;
    this.items = []; // what is drawn: {kind, key, track_ids, ...} (the tests read it)
    siteMap.map.on("singleclick", (e) => {
      if (siteMap.trackAt(e.pixel) !== null) return; // a track's own click wins
      const f = siteMap.map.forEachFeatureAtPixel(e.pixel, (x) => x, {
        layerFilter: (l) => l === this.layer || l === this.labels, hitTolerance: 4,
      });
      const ev = f && f.get("event");
      if (ev) selectEvent(ev);
    });
    const loop = (nowMs) => {
      this.tick(nowMs);
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  tick(nowMs) {
    if (nowMs - this.lastDraw < REDRAW_EVERY_MS) return;
    const t = timeline.now();
    const [a] = synopsisWindow(t);
    const sel = ui.selectedEvent?.key ?? null;
    const sig = `${store.version}|${t}|${a}|${ui.filterVersion}|${sel}`;
    if (sig === this.sig) return;
    this.sig = sig;
    this.lastDraw = nowMs;
    this.draw(activityInWindow(a, t), t);
  }

  /** Features for `events` at shown time t. */
  draw(events, t) {
    const src = this.layer.getSource();
    src.clear(true);
    this.labels.getSource().clear(true);
    const feats = [];
    const labels = [];
    const items = [];
    const selKey = ui.selectedEvent?.key ?? null;
    for (const ev of events) {
      const sel = selKey !== null && ev.key === selKey;
      const tracks = ev.track_ids.map((id) => store.tracks.get(id));
      const add = (geom, role, extra = {}) => {
        const f = new ol.Feature(geom);
        f.setProperties({ kind: ev.kind, role, sel, event: ev, ...extra });
        if (role === "label") {
          f.set("n", labels.length);
          labels.push(f);
        } else {
          feats.push(f);
        }
        return f;
      };
      const d = ev.details || {};
      if (ev.kind === KIND.LOITERING) {
        const r = Math.max(2, d.extent_radius_m ?? 0);
        const c = ev.e_m !== null ? [ev.e_m, ev.n_m] : where(tracks[0], ev.t_s);
        if (!c) continue;
        add(new ol.geom.Circle(c, r), "area");
        add(new ol.geom.Point([c[0], c[1] + r]), "label", {
          label: `loiter #${ev.track_ids[0]} · ${Math.round(dur(ev))} s · r ${Math.round(r)} m`,
        });
        items.push({ kind: ev.kind, key: ev.key, track_ids: ev.track_ids, centre: c, radius_m: r, duration_s: dur(ev) });
      } else if (ev.kind === KIND.RENDEZVOUS) {
        const tm = (ev.t_s + (ev.t_end_s ?? ev.t_s)) / 2;
        const ends = tracks.map((tr) => where(tr, tm));
        const pts = ends.every(Boolean) ? ends : (ev.e_m !== null ? [[ev.e_m, ev.n_m], [ev.e_m, ev.n_m]] : null);
        if (!pts) continue;
        add(new ol.geom.LineString(pts), "link");
        for (const p of pts) add(new ol.geom.Point(p), "end");
        const mid = [(pts[0][0] + pts[1][0]) / 2, (pts[0][1] + pts[1][1]) / 2];
        add(new ol.geom.Point(mid), "label", {
          label: `meet #${ev.track_ids.join("–#")} · ${Math.round(dur(ev))} s · ${Math.round(d.mean_distance_m ?? 0)} m`,
        });
        items.push({ kind: ev.kind, key: ev.key, track_ids: ev.track_ids, ends: pts, duration_s: dur(ev) });
      } else if (ev.kind === KIND.CONVOY) {
        // The members still on the road at tc (a column's members change: one that left
        // long ago is not drawn where it was last seen, across the map); when none is,
        // every member where it was last seen.
        const tc = Math.min(t, ev.t_end_s ?? ev.t_s);
        const at = tracks.map((tr) => (tr ? positionAt(tr, tc) : null));
        let ks = at.flatMap((p, k) => (p ? [k] : [])); // places in the column drawn
        let pts = ks.map((k) => [at[k].e_m, at[k].n_m]);
        if (!ks.length) {
          if (!tracks.every(Boolean)) continue;
          ks = tracks.map((_, k) => k);
          pts = tracks.map((tr) => where(tr, tc));
        }
        add(new ol.geom.LineString(chainAlongRoad(ks.map((k) => tracks[k]), pts, tc)), "chain");
        pts.forEach((p, j) => add(new ol.geom.Point(p), "member", { label: String(ks[j] + 1) }));
        add(new ol.geom.Point(pts[0]), "label", { label: convoyLabel(ev), offset: -22 });
        items.push({
          kind: ev.kind, key: ev.key, track_ids: ev.track_ids, members: pts,
          member_ids: ks.map((k) => ev.track_ids[k]), duration_s: dur(ev),
        });
      }
      if (sel) { // the selected episode's tracks over its span, in the selection colour
        for (const tr of tracks) {
          if (!tr) continue;
          const path = tr.points.filter((p) => p.t_s >= ev.t_s - 5 && p.t_s <= (ev.t_end_s ?? ev.t_s) + 5).map((p) => [p.e_m, p.n_m]);
          if (path.length > 1) add(new ol.geom.LineString(path), "path");
        }
      }
    }
    src.addFeatures(feats);
    this.labels.getSource().addFeatures(labels);
    this.items = items;
  }

  style(f, res) {
    const sel = f.get("sel");
    const colour = sel ? SELECTED_COLOUR : ACTIVITY_COLOUR;
    const role = f.get("role");
    const stroke = (w, dash) => new ol.style.Stroke({ color: colour, width: w, lineDash: dash });
    const text = (label, offsetY = -12) => new ol.style.Text({
      text: label, font: "bold 11px system-ui, sans-serif", offsetY,
      fill: new ol.style.Fill({ color: colour }),
      stroke: new ol.style.Stroke({ color: "rgba(0,0,0,0.85)", width: 3 }),
      overflow: true,
    });
    if (role === "area") {
      return new ol.style.Style({ stroke: stroke(sel ? 3 : 2, [6, 4]), fill: new ol.style.Fill({ color: sel ? "rgba(255,230,0,0.12)" : "rgba(176,124,255,0.14)" }) });
    }
    if (role === "link") return new ol.style.Style({ stroke: stroke(sel ? 4 : 3, [2, 5]) });
    if (role === "chain") return new ol.style.Style({ stroke: stroke(sel ? 4 : 3) });
    if (role === "path") return new ol.style.Style({ stroke: new ol.style.Stroke({ color: SELECTED_COLOUR, width: 3 }) });
    if (role === "end") {
      return new ol.style.Style({ image: new ol.style.Circle({ radius: 4, fill: new ol.style.Fill({ color: colour }), stroke: new ol.style.Stroke({ color: "#000", width: 1 }) }) });
    }
    if (role === "member") {
      return new ol.style.Style({
        image: new ol.style.RegularShape({ points: 4, radius: 8, angle: Math.PI / 4, fill: new ol.style.Fill({ color: colour }), stroke: new ol.style.Stroke({ color: "#000", width: 1 }) }),
        text: new ol.style.Text({ text: f.get("label"), font: "bold 10px system-ui, sans-serif", fill: new ol.style.Fill({ color: "#000" }) }),
      });
    }
    if (role === "label") return new ol.style.Style({ text: text(f.get("label"), f.get("offset") ?? -12) });
    return null;
  }
}

/** A convoy's map label: its members in order while they fit (leader first), else the
 * leader and how many follow; the detail panel lists them all. */
export function convoyLabel(ev) {
  const ids = ev.track_ids;
  const who = ids.length <= 3 ? `#${ids.join("→#")}` : `#${ids[0]} + ${ids.length - 1} vehicles`;
  return `convoy ${who} · ${Math.round(dur(ev))} s`;
}

/** The one line main.mjs calls: the activity layer on `siteMap`, also as
 * `window.demtrack.activity` for the tests. */
export function installActivityLayer(siteMap) {
  const layer = new ActivityLayer(siteMap);
  if (window.demtrack) window.demtrack.activity = layer;
  return layer;
}

/** The episode's time span as clock time (the detail panel's header). */
export function spanText(ev) {
  return `${fmtClock(ev.t_s)}–${fmtClock(ev.t_end_s ?? ev.t_s)} ${zoneLabel(ev.t_s)}`;
}
