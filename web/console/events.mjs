// Events: the kinds the page knows, their map colours, and the one shape the page keeps
// events in.
//
// Events come from GET /api/events (the stored event bodies), from the stream (`event`
// messages: {type, kind, t_s, text, event: <body>}) and, on a server without an event log,
// from the tracks the page holds (`eventsFromTracks`). Each becomes
// {kind, t_s, text, key, track_ids, e_m, n_m}: the track ids are the body's `track_ids`
// (or the synthesised event's own), never read back out of the text.

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

/** Map symbol colours; the activity kinds (loitering, rendezvous, convoy) share one. */
export const ACTIVITY_COLOUR = "#b07cff";
export const EVENT_COLOURS = Object.freeze({
  [KIND.TRACK_CONFIRMED]: "#70ff70",
  [KIND.TRACK_ENDED]: "#ff5050",
  [KIND.HANDOFF]: "#5aa0ff",
  [KIND.ZONE_ENTER]: "#ffffff",
  [KIND.ZONE_LEAVE]: "#ffffff",
});

export function eventColour(kind) {
  return EVENT_COLOURS[kind] || ACTIVITY_COLOUR;
}

/**
 * One shape for the events of GET /api/events, of the stream and of `eventsFromTracks`:
 * {kind, t_s, text, key, track_ids, e_m, n_m} (e_m/n_m null when not given).
 *
 * `raw` is a stream message or {kind, t_s, event: <body>} (the body's `track_ids`,
 * `sensors`, `p_enu`, `key`), or {kind, t_s, text, track_ids} made up by the page. Without
 * a text (an /api/events body), one is worded from the kind, the tracks and the sensors.
 */
export function normEvent(raw) {
  const body = raw.event || null;
  const trackIds = body?.track_ids ?? raw.track_ids ?? [];
  const p = body?.p_enu;
  const where = body?.sensors?.length ? ` (${body.sensors.join(" → ")})` : "";
  const text = raw.text || `${raw.kind.replace(/[-_]/g, " ")}: track${trackIds.length > 1 ? "s" : ""} ${trackIds.join(", ")}${where}`;
  return {
    kind: raw.kind,
    t_s: raw.t_s ?? body?.t_start_s ?? null,
    text,
    key: body?.key || null,
    track_ids: trackIds,
    e_m: p ? p[0] : null,
    n_m: p ? p[1] : null,
  };
}

/** The event's first track (the one a click selects), else null. */
export function eventTrackId(ev) {
  return ev.track_ids && ev.track_ids.length ? ev.track_ids[0] : null;
}

/** Without GET /api/events: the tracks' confirmations and ends, worded as the stream does,
 * in time order. */
export function eventsFromTracks(tracks) {
  const evs = [];
  for (const tr of tracks) {
    if (!tr.points.length) continue;
    evs.push(normEvent({ kind: KIND.TRACK_CONFIRMED, t_s: firstT(tr), text: `track ${tr.id} (${tr.cls}) confirmed`, track_ids: [tr.id] }));
    if (!tr.live) evs.push(normEvent({ kind: KIND.TRACK_ENDED, t_s: lastT(tr), text: `track ${tr.id} (${tr.cls}) ended`, track_ids: [tr.id] }));
  }
  return evs.sort((a, b) => a.t_s - b.t_s);
}
