// The sidebar's track list (newest first, the filters applied) and event list (newest
// first); a click selects the track, or seeks to the event and selects its track.

import { eventTrackId } from "./events.mjs";
import { select } from "./selection.mjs";
import { store, timeline, trackList, ui, visible } from "./state.mjs";
import { firstT, lastT } from "./store.mjs";
import { $, classColour, el, fmtT } from "./util.mjs";

const LIST_EVERY_MS = 400; // the frame loop redraws the lists at most this often
let lastListDraw = 0;

/** From the frame loop: the lists again when LIST_EVERY_MS have passed. */
export function tickLists(nowMs, t) {
  if (nowMs - lastListDraw > LIST_EVERY_MS) {
    lastListDraw = nowMs;
    drawLists(t);
  }
}

/** Both lists at shown time t (events after t are greyed). */
export function drawLists(t) {
  drawTrackList();
  drawEventList(t);
}

function drawTrackList() {
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
}

function drawEventList(t) {
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
