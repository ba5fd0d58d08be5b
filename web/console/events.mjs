// Events: the kinds the page knows, their map colours, the one shape the page keeps events
// in, the one wording of an event, and the hand-off predictions kept apart from them.
//
// Events come from GET /api/events (the stored event bodies), from the stream (`event`
// messages: {type, kind, t_s, text, event: <body>}) and, on a server without an event log,
// from the tracks the page holds (`eventsFromTracks`). Each becomes
// {kind, t_s, t_end_s, state, open, text, key, track_ids, sensors, details, e_m, n_m}: the
// track ids are the body's `track_ids` (or the synthesised event's own), never read back
// out of the text, and the text is worded here from the body (`eventText`), so a row reads
// the same whether it was streamed or loaded from /api/events (the stream's own `text` is
// not used).
//
// A hand-off prediction (kind `handoff`) is not something that happened: it is an
// annotation on a live track, one per track, replaced as it changes (`predictions`). It is
// shown in the track's detail, never in the event list.

import { fmtClock, zoneLabel } from "./clock.mjs";
import { EVENT_PALETTE } from "./palette.mjs";
import { firstT, lastT } from "./store.mjs";

/**
 * Every event kind the page meets: the kinds the server stores (`EVENT_KINDS` of its
 * /api/events router) and `ingest`, the stream's note of each accepted batch (which the
 * event list leaves out).
 */
export const KIND = Object.freeze({
  LOITERING: "loitering",
  RENDEZVOUS: "rendezvous",
  CONVOY: "convoy",
  ZONE_ENTER: "zone-enter",
  ZONE_LEAVE: "zone-leave",
  HANDOFF: "handoff",
  TRACK_CONFIRMED: "track_confirmed",
  TRACK_ENDED: "track_ended",
  INGEST: "ingest",
});

/** The same kinds as a list. */
export const EVENT_KINDS = Object.freeze(Object.values(KIND));

/** Kinds that are activity episodes (drawn by activity_layer.mjs, not as a symbol). */
export const ACTIVITY_KINDS = Object.freeze(new Set([KIND.LOITERING, KIND.RENDEZVOUS, KIND.CONVOY]));

/** Kinds the event list offers as its own filter (what happened; no prediction). */
export const LISTED_KINDS = Object.freeze([
  KIND.LOITERING, KIND.RENDEZVOUS, KIND.CONVOY, KIND.ZONE_ENTER, KIND.ZONE_LEAVE,
  KIND.TRACK_CONFIRMED, KIND.TRACK_ENDED,
]);

/** A short label per listed kind (the kind filter's chips, the rows' tags). */
export const KIND_LABEL = Object.freeze({
  [KIND.LOITERING]: "loiter",
  [KIND.RENDEZVOUS]: "rendezvous",
  [KIND.CONVOY]: "convoy",
  [KIND.ZONE_ENTER]: "zone in",
  [KIND.ZONE_LEAVE]: "zone out",
  [KIND.HANDOFF]: "hand-off",
  [KIND.TRACK_CONFIRMED]: "confirmed",
  [KIND.TRACK_ENDED]: "ended",
});

/** Map symbol colours (palette.mjs); the activity kinds share one, drawn by shape. */
export const ACTIVITY_COLOUR = EVENT_PALETTE.activity;
export const EVENT_COLOURS = Object.freeze({
  [KIND.TRACK_CONFIRMED]: EVENT_PALETTE.confirmed,
  [KIND.TRACK_ENDED]: EVENT_PALETTE.ended,
  [KIND.HANDOFF]: EVENT_PALETTE.handoff,
  [KIND.ZONE_ENTER]: EVENT_PALETTE.zone,
  [KIND.ZONE_LEAVE]: EVENT_PALETTE.zone,
});

export function eventColour(kind) {
  return EVENT_COLOURS[kind] || ACTIVITY_COLOUR;
}

// Clock times (UTC, or local on request) are clock.mjs's; re-exported for older imports.
export { fmtClock, zoneLabel };

const ids = (list) => list.join(", ");
const secs = (s) => (Number.isFinite(s) ? `${Math.round(s)} s` : "");

/**
 * The one wording of an event, from its kind and body fields (normEvent's shape or a
 * stored body: `track_ids`, `t_start_s`/`t_s`, `t_end_s`, `state`, `details`, `sensors`).
 * Activity rows carry no camera: who took part and for how long; track rows say which
 * sensors saw the track.
 */
export function eventText(ev) {
  const tids = ev.track_ids || [];
  const d = ev.details || {};
  const t0 = ev.t_start_s ?? ev.t_s;
  const dur = Number.isFinite(ev.t_end_s) && Number.isFinite(t0) ? ev.t_end_s - t0 : NaN;
  const over = ev.state === "end" ? ", over" : ev.open ? ", ongoing" : "";
  switch (ev.kind) {
    case KIND.LOITERING:
      return `track ${ids(tids)} loitering ${secs(dur)} within ${Math.round(d.extent_radius_m ?? 0)} m${over}`;
    case KIND.RENDEZVOUS:
      return `tracks ${tids.join(" & ")} met for ${secs(dur)}, ${Math.round(d.mean_distance_m ?? 0)} m apart${over}`;
    case KIND.CONVOY:
      return `convoy of ${tids.length}: tracks ${tids.join(" → ")} for ${secs(dur)}${over}`;
    case KIND.ZONE_ENTER:
      return `track ${ids(tids)} entered ${d.zone ?? "a zone"}`;
    case KIND.ZONE_LEAVE:
      return `track ${ids(tids)} left ${d.zone ?? "a zone"}`;
    case KIND.TRACK_CONFIRMED:
    case KIND.TRACK_ENDED: {
      const seen = ev.sensors?.length ? ` · ${ev.sensors.join(", ")}` : "";
      return `track ${ids(tids)}${d.cls ? ` (${d.cls})` : ""} ${ev.kind === KIND.TRACK_ENDED ? "ended" : "confirmed"}${seen}`;
    }
    case KIND.HANDOFF:
      return predictionText(ev);
    default:
      return `${String(ev.kind).replace(/[-_]/g, " ")}: track${tids.length > 1 ? "s" : ""} ${ids(tids)}`;
  }
}

/** A hand-off prediction in words, its times as clock time: "cam1 loses it at 14:50:10.4
 * UTC; next cam2 at 14:50:12.0 UTC" (local time with its offset on request). */
export function predictionText(p) {
  const d = p.details || {};
  const exit = fmtClock(d.exit_t_s);
  const zone = zoneLabel(d.exit_t_s);
  const next = d.next_t_s === null || d.next_t_s === undefined ? "" : ` at ${fmtClock(d.next_t_s)} ${zone}`;
  return `${d.current ?? "—"} loses it at ${exit} ${zone}; next ${d.next_sensor ?? "none"}${next}${d.slew ? " (slew)" : ""}`;
}

/**
 * One shape for the events of GET /api/events, of the stream and of `eventsFromTracks`.
 *
 * `raw` is a stream message or {kind, t_s, event: <body>} (the body's `track_ids`,
 * `sensors`, `p_enu`, `key`, `details`), or {kind, t_s, track_ids, details} made up by the
 * page. The text is always `eventText` of it.
 */
export function normEvent(raw) {
  const body = raw.event || null;
  const trackIds = body?.track_ids ?? raw.track_ids ?? [];
  const p = body?.p_enu;
  const t0 = body?.t_start_s ?? raw.t_s ?? null;
  const ev = {
    kind: raw.kind,
    t_s: t0,
    t_end_s: body?.t_end_s ?? raw.t_end_s ?? t0,
    state: body?.state ?? raw.state ?? "start",
    open: body?.open ?? false,
    key: body?.key || raw.key || null,
    track_ids: trackIds,
    sensors: body?.sensors ?? raw.sensors ?? [],
    details: body?.details ?? raw.details ?? {},
    e_m: p ? p[0] : null,
    n_m: p ? p[1] : null,
  };
  ev.text = eventText(ev);
  return ev;
}

/** The event's first track (the one a click centres on), else null. */
export function eventTrackId(ev) {
  return ev.track_ids && ev.track_ids.length ? ev.track_ids[0] : null;
}

/** Whether `raw` (a stream message or an /api/events body) is a hand-off prediction. */
export function isPrediction(raw) {
  return raw.kind === KIND.HANDOFF;
}

/** Each live track's newest hand-off prediction, by track id (normEvent's shape). */
export const predictions = new Map();

/** Keeps a prediction (stream message or /api/events body), replacing the track's last. */
export function applyPrediction(raw) {
  const p = raw.event ? normEvent(raw) : normEvent({ kind: raw.kind, event: raw });
  const id = eventTrackId(p);
  if (id === null) return;
  const old = predictions.get(id);
  if (!old || !(old.t_s > p.t_s)) predictions.set(id, p);
  if (predictions.size > 1000) predictions.delete(predictions.keys().next().value);
}

/** Without GET /api/events: the tracks' confirmations and ends, worded as any event is,
 * in time order. */
export function eventsFromTracks(tracks) {
  const evs = [];
  for (const tr of tracks) {
    if (!tr.points.length) continue;
    const base = { track_ids: [tr.id], sensors: tr.sensors || [], details: { cls: tr.cls } };
    evs.push(normEvent({ kind: KIND.TRACK_CONFIRMED, t_s: firstT(tr), key: `${KIND.TRACK_CONFIRMED}:${tr.id}`, ...base }));
    if (!tr.live) evs.push(normEvent({ kind: KIND.TRACK_ENDED, t_s: lastT(tr), key: `${KIND.TRACK_ENDED}:${tr.id}`, ...base }));
  }
  return evs.sort((a, b) => a.t_s - b.t_s);
}
