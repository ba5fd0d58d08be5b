// The sidebar's track list (newest first, the filters applied) and event list.
//
// The event list is a review tool: every event the page holds and the stored ones of
// ±10 min around the shown time (from /api/events), in time order, filtered by the
// page's class, sensor and track filters (state.mjs `eventVisible`) and by its own kind
// chips, in pages of PAGE_ROWS. While "follow time" is ticked (the default) the page shown
// is the one holding the shown time, and the row at or just before it is marked (`now`);
// events after the shown time are greyed. Times are clock time (UTC). A click seeks to the
// event and selects it with all its tracks. Hand-off predictions are not listed: they are
// annotations on their tracks (selection.mjs shows them in the track's detail).

import * as api from "./api.mjs";
import { fmtClock, KIND_LABEL, LISTED_KINDS, normEvent, zoneLabel } from "./events.mjs";
import { isSelected, select, selectEvent } from "./selection.mjs";
import { eventVisible, store, timeline, trackList, ui, visible } from "./state.mjs";
import { firstT, lastT } from "./store.mjs";
import { $, classColour, el } from "./util.mjs";

const LIST_EVERY_MS = 400; // the frame loop redraws the lists at most this often
export const PAGE_ROWS = 25; // event rows per page (default of eventList.pageRows)
const OLDER_CHUNK_S = 600; // stored events asked for around a scrubbed time, ± this
let lastListDraw = 0;

/** The event list's own state (kinds ticked, page, following the time); the tests read it. */
export const eventList = {
  kinds: new Set(LISTED_KINDS),
  follow: true,
  pageRows: PAGE_ROWS,
  page: 0, // when not following
  nPages: 1,
  rows: [], // the events of the page shown
  older: new Map(), // key -> event: stored events older than the store holds
  olderSpan: null, // [a, b] asked for
};

/** From the frame loop: the lists again when LIST_EVERY_MS have passed. */
export function tickLists(nowMs, t) {
  if (nowMs - lastListDraw > LIST_EVERY_MS) {
    lastListDraw = nowMs;
    drawLists(t);
  }
}

/** Both lists at shown time t. */
export function drawLists(t) {
  drawTrackList();
  drawEventList(t);
}

function drawTrackList() {
  const tracks = trackList().filter(visible).sort((a, b) => lastT(b) - lastT(a)).slice(0, 100);
  $("#n-tracks").textContent = `(${tracks.length}${store.tracks.size > tracks.length ? ` of ${store.tracks.size}` : ""})`;
  const list = $("#track-list");
  list.replaceChildren(...tracks.map((tr) => el("div", {
    class: isSelected(tr.id) ? "sel" : "",
    "data-track": String(tr.id),
    title: `sensors ${(tr.sensors || []).join(", ")}; ${fmtClock(firstT(tr), { withDate: true })}–${fmtClock(lastT(tr))} ${zoneLabel(firstT(tr))}`,
    style: "flex-wrap:wrap;white-space:normal",
    onclick: () => select(tr.id),
  },
  el("span", { class: "swatch", style: `background:${classColour(tr.cls)}` }),
  el("b", { text: `#${tr.id}` }),
  el("span", { text: tr.cls }),
  el("span", { class: "muted mono", text: `${fmtClock(firstT(tr), { digits: 0 })}–${fmtClock(lastT(tr), { digits: 0 })}${tr.live ? " ●" : ""}` }))));
}

/** The kind chips, the follow toggle and the pager above the list (built once). */
function controls() {
  let bar = $("#event-controls");
  if (bar) return bar;
  const redraw = () => drawEventList(ui.lastT ?? 0);
  const chips = el("div", { class: "chips", id: "event-kinds", style: "font-size:11px;gap:0 8px", title: "event kinds listed" }, ...LISTED_KINDS.map((k) => el("label", {},
    el("input", {
      type: "checkbox", checked: true, "data-kind": k,
      onchange: (e) => {
        if (e.target.checked) eventList.kinds.add(k);
        else eventList.kinds.delete(k);
        redraw();
      },
    }), ` ${KIND_LABEL[k]}`)));
  const follow = el("input", {
    type: "checkbox", id: "event-follow", checked: true,
    onchange: (e) => {
      eventList.follow = e.target.checked;
      redraw();
    },
  });
  const turn = (d) => {
    eventList.page = Math.max(0, Math.min(eventList.nPages - 1, eventList.page + d));
    eventList.follow = false;
    follow.checked = false;
    redraw();
  };
  bar = el("div", { id: "event-controls" }, chips,
    el("div", { class: "row", style: "align-items:center" },
      el("label", { title: "show the page holding the shown time", style: "white-space:nowrap" }, follow, " follow time"),
      el("span", { class: "grow", style: "flex:1" }),
      el("button", { id: "event-prev", title: "earlier events", onclick: () => turn(-1) }, "◀"),
      el("span", { id: "event-page", class: "mono muted", style: "white-space:nowrap" }),
      el("button", { id: "event-next", title: "later events", onclick: () => turn(1) }, "▶")));
  $("#event-list").before(bar);
  return bar;
}

/** Every event held, older stored ones included, by time (no prediction, no ingest). */
function allEvents() {
  const byKey = new Map(eventList.older);
  const keyless = [];
  for (const ev of store.events) {
    if (ev.key) byKey.set(ev.key, ev);
    else keyless.push(ev);
  }
  return [...byKey.values(), ...keyless].filter((ev) => ev.t_s !== null && KIND_LABEL[ev.kind] && ev.kind !== "handoff")
    .sort((a, b) => a.t_s - b.t_s);
}

/** The stored events of ±OLDER_CHUNK_S around the shown time from /api/events, once per
 * chunk: the page's store keeps only the newest few hundred events (and start-up loads the
 * oldest of a long session), so a review of any moment lists everything stored then. */
function askOlder(t) {
  if (!ui.endpoints?.events || !Number.isFinite(t)) return;
  const span = eventList.olderSpan;
  if (span && t >= span[0] + 60 && t <= span[1] - 60) return;
  const a = t - OLDER_CHUNK_S;
  const b = t + OLDER_CHUNK_S;
  eventList.olderSpan = [a, b];
  api.getOptionalJSON(`/api/events?t_from=${a}&t_to=${b}&limit=2000`).then((r) => {
    for (const e of r?.events || []) {
      const ev = normEvent({ kind: e.kind, t_s: e.t_start_s, event: e });
      eventList.older.set(ev.key, ev);
    }
    if (eventList.older.size > 4000) eventList.older = new Map([...eventList.older].slice(-4000));
    ui.dirty = true;
    drawEventList(ui.lastT ?? t);
  }).catch(() => {});
}

function drawEventList(t) {
  controls();
  askOlder(t);
  const evs = allEvents().filter((ev) => eventList.kinds.has(ev.kind) && eventVisible(ev));
  const per = eventList.pageRows;
  const nPages = Math.max(1, Math.ceil(evs.length / per));
  eventList.nPages = nPages;
  // the row at or just before the shown time (-1: every event is later)
  let now = -1;
  for (let k = 0; k < evs.length && evs[k].t_s <= t; k += 1) now = k;
  if (eventList.follow) eventList.page = now < 0 ? 0 : Math.floor(now / per);
  eventList.page = Math.min(eventList.page, nPages - 1);
  const first = eventList.page * per;
  const rows = evs.slice(first, first + per);
  eventList.rows = rows;
  $("#event-page").textContent = `${eventList.page + 1}/${nPages} · ${evs.length}`;
  $("#event-prev").disabled = eventList.page === 0;
  $("#event-next").disabled = eventList.page >= nPages - 1;
  const selKey = ui.selectedEvent?.key ?? null;
  $("#event-list").replaceChildren(...rows.map((ev, k) => el("div", {
    class: [ev.t_s > t ? "muted" : "", first + k === now ? "now" : "", selKey && ev.key === selKey ? "sel" : ""].filter(Boolean).join(" "),
    "data-kind": ev.kind,
    "data-key": ev.key || "",
    "data-t": String(ev.t_s),
    title: `${ev.text} — ${fmtClock(ev.t_s, { withDate: true })} ${zoneLabel(ev.t_s)}`,
    // wrap instead of cutting the row (the sidebar is narrow at 1280 px)
    style: `white-space:normal;flex-wrap:wrap;row-gap:0;align-items:baseline;${first + k === now ? "box-shadow:inset 3px 0 #ffe600;" : ""}`,
    onclick: () => {
      if (ev.t_s !== null) timeline.seek(ev.t_s);
      selectEvent(ev);
    },
  },
  el("span", { class: "mono muted", style: "flex:none", text: fmtClock(ev.t_s) }),
  el("span", { class: "tag muted", style: "flex:none", text: KIND_LABEL[ev.kind] || ev.kind }),
  el("span", { style: "flex:1 1 100%;padding-left:10px;overflow-wrap:anywhere", text: ev.text }))));
}
