// What the page knows: tracks (with their points and hand-off gaps), recent fixes per
// sensor, events and sensor status. Every collection is bounded so an hour of replay at
// 10x with 20 tracks keeps a flat memory footprint.

export const LIMITS = {
  pointsPerTrack: 6000, // oldest points of a long track are dropped beyond this
  tracks: 400, // ended tracks beyond this are forgotten, oldest first
  totalPoints: 300000, // and beyond this many points in all
  fixesPerSensor: 400,
  events: 300,
  detToTrack: 50000,
};

/** Linear interpolation of a track's position at `t` (null outside its span). */
export function positionAt(track, t) {
  const pts = track.points;
  if (!pts.length || t < pts[0].t_s || t > pts[pts.length - 1].t_s) return null;
  let lo = 0;
  let hi = pts.length - 1;
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (pts[mid].t_s <= t) lo = mid;
    else hi = mid;
  }
  const a = pts[lo];
  const b = pts[hi];
  const f = b.t_s > a.t_s ? (t - a.t_s) / (b.t_s - a.t_s) : 0;
  return {
    e_m: a.e_m + f * (b.e_m - a.e_m),
    n_m: a.n_m + f * (b.n_m - a.n_m),
    u_m: a.u_m + f * (b.u_m - a.u_m),
    sensors: f < 0.5 ? a.sensors : b.sensors,
    index: lo,
  };
}

/** Index of the last point with t_s <= t (-1 if none). */
export function lastIndexAtOrBefore(pts, t) {
  let lo = 0;
  let hi = pts.length;
  while (lo < hi) {
    const mid = (lo + hi) >> 1;
    if (pts[mid].t_s <= t) lo = mid + 1;
    else hi = mid;
  }
  return lo - 1;
}

/** Whether the step between two consecutive points crosses one of the track's gaps. */
export function inGap(track, ta, tb) {
  for (const [g0, g1] of track.gaps || []) {
    if (g0 >= ta - 1e-6 && g1 <= tb + 1e-6) return true;
  }
  return false;
}

/** A track (or its clip) as synopsis parts: runs of points, split where a gap is crossed. */
export function trackParts(track) {
  const pts = track.points;
  const parts = [];
  let part = null;
  for (let i = 1; i < pts.length; i += 1) {
    const gap = inGap(track, pts[i - 1].t_s, pts[i].t_s);
    if (!part || part.gap !== gap) {
      part = { gap, coords: [[pts[i - 1].e_m, pts[i - 1].n_m]] };
      parts.push(part);
    }
    part.coords.push([pts[i].e_m, pts[i].n_m]);
  }
  return parts;
}

export class Store {
  constructor() {
    this.tracks = new Map(); // id -> {id, cls, sensors, gaps, live, base, points, n_points}
    this.fixes = new Map(); // sensor -> [fix, ...] (newest last)
    this.events = []; // newest last
    this.sensorStatus = new Map();
    this.sensorPose = new Map(); // sensor -> its newest sensor_pose message
    this.detToTrack = new Map();
    this.tMin = null;
    this.tMax = null;
    this.version = 0; // bumped on every change (redraw when it moves)
  }

  clear() {
    this.tracks.clear();
    this.fixes.clear();
    this.events = [];
    this.sensorStatus.clear();
    this.sensorPose.clear();
    this.detToTrack.clear();
    this.tMin = null;
    this.tMax = null;
    this.version += 1;
  }

  seeTime(t) {
    if (t === null || t === undefined || !Number.isFinite(t)) return;
    this.tMin = this.tMin === null ? t : Math.min(this.tMin, t);
    this.tMax = this.tMax === null ? t : Math.max(this.tMax, t);
  }

  /** A track body from GET /api/tracks or a track_update message. */
  applyTrack(body) {
    let tr = this.tracks.get(body.id);
    if (!tr) {
      tr = { id: body.id, cls: body.cls, base: 0, points: [], updated: 0 };
      this.tracks.set(body.id, tr);
    }
    tr.cls = body.cls;
    tr.sensors = body.sensors;
    tr.gaps = body.gaps;
    tr.live = body.live;
    tr.n_points = body.n_points;
    // Replace from first_index (absolute) on; `base` is the absolute index of points[0].
    const keep = Math.max(0, Math.min(tr.points.length, body.first_index - tr.base));
    if (body.first_index < tr.base) {
      tr.points = body.points.slice(tr.base - body.first_index);
    } else {
      tr.points = tr.points.slice(0, keep).concat(body.points);
    }
    const extra = tr.points.length - LIMITS.pointsPerTrack;
    if (extra > 0) {
      tr.points = tr.points.slice(extra);
      tr.base += extra;
    }
    for (const p of body.points) {
      for (const d of p.detection_ids || []) this.detToTrack.set(d, body.id);
    }
    if (this.detToTrack.size > LIMITS.detToTrack) {
      const drop = this.detToTrack.size - LIMITS.detToTrack;
      let k = 0;
      for (const key of this.detToTrack.keys()) {
        if (k++ >= drop) break;
        this.detToTrack.delete(key);
      }
    }
    if (tr.points.length) {
      this.seeTime(tr.points[0].t_s);
      this.seeTime(tr.points[tr.points.length - 1].t_s);
    }
    tr.updated = ++this.version;
    this.trimTracks();
  }

  trimTracks() {
    // Cheap test first: this runs on every track update.
    if (this.tracks.size <= LIMITS.tracks && (this.tracks.size * LIMITS.pointsPerTrack <= LIMITS.totalPoints || this.nPoints() <= LIMITS.totalPoints)) return;
    const ended = [...this.tracks.values()]
      .filter((t) => !t.live)
      .sort((a, b) => lastT(a) - lastT(b));
    let total = this.nPoints();
    while ((this.tracks.size > LIMITS.tracks || total > LIMITS.totalPoints) && ended.length) {
      const gone = ended.shift();
      total -= gone.points.length;
      this.tracks.delete(gone.id);
    }
  }

  applyFix(fix) {
    let list = this.fixes.get(fix.sensor);
    if (!list) {
      list = [];
      this.fixes.set(fix.sensor, list);
    }
    list.push(fix);
    if (list.length > LIMITS.fixesPerSensor) list.splice(0, list.length - LIMITS.fixesPerSensor);
    this.seeTime(fix.t_s);
    this.version += 1;
  }

  /** A normalised event (events.mjs `normEvent`); an episode's later states replace it. */
  applyEvent(ev) {
    const k = ev.key ? this.events.findIndex((e) => e.key === ev.key) : -1;
    if (k >= 0) {
      this.events[k] = ev;
      this.version += 1;
      return;
    }
    this.events.push(ev);
    if (this.events.length > LIMITS.events) this.events.splice(0, this.events.length - LIMITS.events);
    this.seeTime(ev.t_s);
    this.version += 1;
  }

  /** Fixes of `sensor` with t in (t - window, t]. */
  fixesNear(sensor, t, windowS) {
    const list = this.fixes.get(sensor) || [];
    return list.filter((f) => f.t_s <= t + 1e-6 && f.t_s > t - windowS);
  }

  trackOfDetection(id) {
    return this.detToTrack.get(id);
  }

  nPoints() {
    let n = 0;
    for (const t of this.tracks.values()) n += t.points.length;
    return n;
  }
}

export function lastT(track) {
  return track.points.length ? track.points[track.points.length - 1].t_s : -Infinity;
}

export function firstT(track) {
  return track.points.length ? track.points[0].t_s : Infinity;
}
