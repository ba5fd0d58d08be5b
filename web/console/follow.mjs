// The 3D scene follows the selected track: PUT /api/scene3d/follow {track_id} when the
// selection changes (null when it is cleared). The scene then points every viser client's
// camera at the track's newest position and keeps following it as new fixes arrive.
//
// One request in flight; the newest choice wins (a quick re-selection sends only the
// last one once the first answer is in). Failures are shown, never thrown: the 3D view is
// an extra, the map keeps working without it.

import * as api from "./api.mjs";

export class SceneFollow {
  /**
   * @param {boolean} enabled  whether the server runs a 3D scene
   * @param {(state: object) => void} onChange  called with {trackId, pending, error, answer}
   */
  constructor(enabled, onChange = () => {}) {
    this.enabled = enabled;
    this.onChange = onChange;
    this.want = null; // track id the operator chose (null: none)
    this.sent = null; // what the server last accepted
    this.inFlight = false;
    this.error = null;
    this.answer = null; // the server's last answer (track_id, look_at_enu, clients)
    this.requests = 0;
  }

  /** Follow `trackId` (null stops following). */
  set(trackId) {
    if (!this.enabled) return;
    this.want = trackId;
    this.pump();
  }

  async pump() {
    if (this.inFlight || this.want === this.sent) return;
    this.inFlight = true;
    const id = this.want;
    this.requests += 1;
    this.notify();
    try {
      this.answer = await api.putJSON("/api/scene3d/follow", { track_id: id });
      this.error = null;
    } catch (err) {
      this.error = String(err.message || err);
    } finally {
      this.sent = id; // also after a failure: do not retry in a loop
      this.inFlight = false;
    }
    this.notify();
    if (this.want !== this.sent) this.pump();
  }

  notify() {
    this.onChange({ trackId: this.want, pending: this.inFlight, error: this.error, answer: this.answer });
  }
}
