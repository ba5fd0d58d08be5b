// The frame loop: on each animation frame where the data, the shown time or the UI
// changed (`ui.dirty`), the map and the camera panels are redrawn; the lists and the
// detail panel follow at a slower pace (lists.mjs, selection.mjs).

import { BOX_WINDOW_S, linkBoxes } from "./cameras.mjs";
import { ACTIVITY_KINDS, eventTrackId, KIND } from "./events.mjs";
import { bufferCovers } from "./history.mjs";
import { tickLists } from "./lists.mjs";
import { tickDetail } from "./selection.mjs";
import { boxVisible, store, timeline, trackList, ui, visible } from "./state.mjs";
import { positionAt } from "./store.mjs";
import { drawSynopsis } from "./synopsis.mjs";
import { $ } from "./util.mjs";

/** Starts the loop (once, when the page has loaded). */
export function startFrames() {
  requestAnimationFrame(frame);
}

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
    tickLists(nowMs, t);
    tickDetail(nowMs, t);
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
      panel.draw(fixes || [], (d) => ui.past.trackOf(d) ?? store.trackOfDetection(d), ui.selectedId, boxVisible);
    } else {
      // A box whose track has not arrived yet (tracks lag the fixes by the server's reorder
      // lag) takes the track of the box it continues (cameras.mjs linkBoxes).
      // Over a live video frame (video.mjs): the boxes of the frame's own moment.
      const fixes = store.fixesNear(sid, panel.videoT ?? t, panel.videoWindowS ?? BOX_WINDOW_S);
      const links = linkBoxes(store.fixes.get(sid) || [], fixes, (d) => store.trackOfDetection(d));
      panel.draw(fixes, (d) => links.get(d), ui.selectedId, boxVisible);
    }
    panel.root.dataset.boxes = past ? "stored" : "recent";
  }
  if (ui.following && ui.selectedId !== null) {
    // The view before following is kept, and given back when following stops (Follow
    // again, Esc, another selection).
    if (!followView) followView = { center: map.view.getCenter(), resolution: map.view.getResolution() };
    const tr = store.tracks.get(ui.selectedId);
    const p = tr && (positionAt(tr, t) || lastPoint(tr, t));
    if (p) map.centreOn(p.e_m, p.n_m);
  } else if (followView) {
    map.view.setResolution(followView.resolution);
    map.view.setCenter(followView.center);
    followView = null;
  }
  map.trails.changed();
  $("#counts").textContent = `${store.tracks.size} tracks · ${store.nPoints()} points`;
}

let followView = null; // {center, resolution} of the map before Follow

function lastPoint(tr, t) {
  const pts = tr.points.filter((p) => p.t_s <= t);
  return pts.length ? pts[pts.length - 1] : null;
}

/** The events of the last 120 s of shown time on the map: where the event says, else on
 * its track (at the event's time, or the track's end or start). */
function drawEventsOnMap(t) {
  const items = [];
  for (const ev of store.events) {
    if (ev.t_s === null || ev.t_s > t || ev.t_s < t - 120) continue;
    if (ACTIVITY_KINDS.has(ev.kind)) continue; // drawn by activity_layer.mjs, for the whole window
    const id = eventTrackId(ev);
    const tr = id !== null ? store.tracks.get(id) : null;
    if (tr && !visible(tr)) continue;
    if (ev.e_m !== null) {
      items.push({ kind: ev.kind, e_m: ev.e_m, n_m: ev.n_m });
      continue;
    }
    if (!tr) continue;
    const p = positionAt(tr, ev.t_s) || (ev.kind === KIND.TRACK_ENDED ? tr.points[tr.points.length - 1] : tr.points[0]);
    if (p) items.push({ kind: ev.kind, e_m: p.e_m, n_m: p.n_m });
  }
  ui.map.drawEvents(items);
}

