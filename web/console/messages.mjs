// What the live stream's messages do to the page: fixes, track updates, events and sensor
// status go into the store (or the camera panels); a sensor's new pose moves its footprint
// and field-of-view wedge on the map and its panel's pan/tilt/zoom; a reset reloads the
// tracks.

import * as api from "./api.mjs";
import { applyPrediction, isPrediction, KIND, normEvent } from "./events.mjs";
import { onMarkerMessage } from "./markers.mjs";
import { store, ui } from "./state.mjs";
import { fmtClock, zoneLabel } from "./clock.mjs";

/** One stream message (stream.mjs hands them on one by one, in order). */
export function onMessage(msg) {
  if (msg.type === "fix") store.applyFix(msg.fix);
  else if (msg.type === "track_update") store.applyTrack(msg.track);
  else if (msg.type === "event") {
    // `ingest` (a batch accepted) is the server's bookkeeping, not an operator's event.
    if (isPrediction(msg)) applyPrediction(msg); // a track's annotation, not an event (events.mjs)
    else if (msg.kind !== KIND.INGEST) store.applyEvent(normEvent(msg));
  }
  else if (msg.type === "marker") onMarkerMessage(msg); // markers.mjs
  else if (msg.type === "sensor_pose") {
    store.sensorPose.set(msg.sensor, msg);
    ui.map?.setSensorPose(msg); // map.mjs: footprint and wedge at the new pose
    ui.cams?.get(msg.sensor)?.setPose(msg); // cameras.mjs: pan / tilt / hfov readout
  }
  else if (msg.type === "sensor_status") {
    store.sensorStatus.set(msg.sensor, msg);
    const p = ui.cams.get(msg.sensor);
    if (p) p.status.textContent = `${msg.n_detections} detections · last ${fmtClock(msg.last_t_s, { digits: 0 })} ${zoneLabel(msg.last_t_s)}`;
  }
  ui.dirty = true;
}

/** The server's stream started over (a new database): the store reloads its tracks. */
export async function onReset() {
  store.clear();
  const r = await api.getJSON("/api/tracks");
  r.tracks.forEach((t) => store.applyTrack(t));
  ui.dirty = true;
}
