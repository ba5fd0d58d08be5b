// The 3D scene follows the selected track: PUT /api/scene3d/follow {track_id, session} when
// the selection changes (null when it is cleared). The scene then points the cameras of
// this page's viser clients at the track's newest position and keeps following it as new
// fixes arrive; other operators' 3D views are left alone.
//
// The page's follow session is a random id made up at load. Its viser client (the 3D
// tab's iframe) joins it by connecting its WebSocket on /follow/<session>: viser's client
// takes the WebSocket URL from its `?websocket=` URL parameter (viserFrameUrl), and the
// scene reads the path of each connection (server/scene3d.py).
//
// One request in flight; the newest choice wins (a quick re-selection sends only the
// last one once the first answer is in). Failures are shown, never thrown: the 3D view is
// an extra, the map keeps working without it.

import * as api from "./api.mjs";

/** A new follow session id: 32 hex digits (crypto.getRandomValues works over plain http). */
export function newSession() {
  const b = new Uint8Array(16);
  crypto.getRandomValues(b);
  return [...b].map((x) => x.toString(16).padStart(2, "0")).join("");
}

/**
 * The URL of viser's client for the 3D tab: the scene's page, told (viser's `?websocket=`
 * parameter) to connect on ws://<its host:port>/follow/<session>.
 */
export function viserFrameUrl(viserUrl, session) {
  const page = new URL(viserUrl, window.location.href);
  const ws = new URL(`follow/${session}`, page); // beside the page (the scene's root)
  ws.protocol = page.protocol === "https:" ? "wss:" : "ws:";
  page.search = `?websocket=${encodeURIComponent(ws.href)}`;
  return page.href;
}

export class SceneFollow {
  /**
   * @param {boolean} enabled  whether the server runs a 3D scene
   * @param {(state: object) => void} onChange  called with {trackId, pending, error, answer}
   * @param {string} session  this page's follow session (default: a new one)
   */
  constructor(enabled, onChange = () => {}, session = newSession()) {
    this.enabled = enabled;
    this.onChange = onChange;
    this.session = session;
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
      this.answer = await api.putJSON("/api/scene3d/follow", { track_id: id, session: this.session });
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
