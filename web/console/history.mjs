// Camera boxes of a moment older than the page's recent-fixes buffer.
//
// The store keeps the newest fixes of each sensor (store.mjs LIMITS.fixesPerSensor). When
// the timeline shows a time before a sensor's oldest kept fix, the boxes come from the
// API instead: GET /api/detections?t_from=&t_to= (time order) for a chunk of time around
// the shown time, and GET /api/tracks over the same window for the track ids of those
// detections (points carry their detection ids). A chunk serves every frame inside it, so
// playing back from a scrubbed time asks again only when the shown time leaves it.

import * as api from "./api.mjs";

const BEFORE_S = 5; // a chunk starts this long before the box window
const AFTER_S = 10; // and ends this long after the shown time
const LIMIT = 5000; // detections per chunk (the chunk ends earlier when reached)

/** Whether the store's fixes of `sensor` reach back to the box window ending at `t`. */
export function bufferCovers(store, sensor, t, windowS) {
  const list = store.fixes.get(sensor);
  return !!list && list.length > 0 && list[0].t_s <= t - windowS;
}

export class PastBoxes {
  constructor() {
    this.chunk = null; // {t0, t1, bySensor: Map(sensor -> [fix]), trackOf: Map(det -> track)}
    this.inFlight = false;
    this.wantT = null;
    this.requests = 0;
    this.error = null;
    this.retryAt = 0; // after a failure, ask again no sooner than this (ms, performance.now)
    this.onLoad = () => {};
  }

  covers(t, windowS) {
    const c = this.chunk;
    return !!c && c.t0 <= t - windowS && t <= c.t1;
  }

  /**
   * The boxes of `sensor` in (t - windowS, t] from the chunk, or null while no chunk
   * covers `t` (one is then asked for).
   */
  fixesNear(sensor, t, windowS) {
    if (!this.covers(t, windowS)) {
      this.request(t, windowS);
      return null;
    }
    const list = this.chunk.bySensor.get(sensor) || [];
    return list.filter((f) => f.t_s <= t + 1e-6 && f.t_s > t - windowS);
  }

  trackOf(detectionId) {
    return this.chunk ? this.chunk.trackOf.get(detectionId) : undefined;
  }

  request(t, windowS) {
    this.wantT = [t, windowS];
    if (this.inFlight || performance.now() < this.retryAt) return;
    this.load(t, windowS);
  }

  async load(t, windowS) {
    this.inFlight = true;
    this.requests += 1;
    const t0 = t - windowS - BEFORE_S;
    let t1 = t + AFTER_S;
    const q = `t_from=${t0.toFixed(3)}&t_to=${t1.toFixed(3)}`;
    try {
      const [rows, tracks] = await Promise.all([
        api.getJSON(`/api/detections?${q}&limit=${LIMIT}`),
        api.getJSON(`/api/tracks?${q}`),
      ]);
      let kept = rows;
      if (rows.length >= LIMIT) {
        // Truncated: the chunk ends before its newest time (whose rows may be partial).
        t1 = rows[rows.length - 1].t - 1e-6;
        kept = rows.filter((d) => d.t <= t1);
      }
      const bySensor = new Map();
      for (const d of kept) {
        if (!bySensor.has(d.sensor)) bySensor.set(d.sensor, []);
        bySensor.get(d.sensor).push({
          detection_id: d.id, t_s: d.t, sensor: d.sensor, cls: d.class ?? d.cls, bbox: d.bbox, tracked: false,
        });
      }
      const trackOf = new Map();
      for (const tr of tracks.tracks || []) {
        for (const p of tr.points) for (const id of p.detection_ids || []) trackOf.set(id, tr.id);
      }
      this.chunk = { t0, t1, bySensor, trackOf, n: kept.length };
      this.error = null;
    } catch (err) {
      this.error = String(err.message || err);
      this.retryAt = performance.now() + 3000;
    } finally {
      this.inFlight = false;
    }
    this.onLoad();
    const [wt, ww] = this.wantT;
    if (!this.covers(wt, ww) && !this.error) this.load(wt, ww);
  }
}
