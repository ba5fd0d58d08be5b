// The 3D scene follows the selected track: PUT /api/scene3d/follow {track_id, session} when
// the selection changes (null when it is cleared). The scene then points the cameras of
// this page's viser clients at the track's newest position and keeps following it as new
// fixes arrive; other operators' 3D views are left alone.
//
// The page's follow session is a random id made up at load. Its viser client (the 3D
// tab's iframe) joins it by connecting its WebSocket on /follow/<session>: viser's client
// takes the WebSocket URL from its `?websocket=` URL parameter (viserFrameUrl), and the
// scene reads the path of each connection (server/scene3d/connections.py).
//
// The session is also the page's ticket into the scene: the scene admits only viser
// clients of a session registered with the operator token (`register`, PUT
// /api/scene3d/session), so the 3D tab loads its iframe after that answer.
//
// One request in flight; the newest choice wins (a quick re-selection sends only the
// last one once the first answer is in). A request that fails on the way (no answer, a
// dropped connection, a 5xx from a busy or restarting server) is sent again after a growing
// pause, up to RETRY_DELAYS_MS.length times; a refusal (4xx, e.g. a track the server does not
// have) is final. Failures are shown, never thrown: the 3D view is an extra, the map keeps
// working without it.

import * as api from "./api.mjs";

/** Pauses before each resend of a request that failed on the way (ms). */
export const RETRY_DELAYS_MS = [250, 500, 1000, 2000, 4000, 8000];

/** A request with no answer after this long is given up and sent again (ms). */
export const REQUEST_TIMEOUT_MS = 10000;

/** Whether a failed request is worth sending again: no answer (or none in time), or a 5xx. */
export function isTransient(err) {
  return (
    err instanceof TypeError ||
    err?.name === "TimeoutError" ||
    (typeof err?.status === "number" && err.status >= 500)
  );
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

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
   * @param {(state: object) => void} onChange  called with {trackId, pending, error, retrying, answer}
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
    this.requests = 0; // PUTs sent, resends included
    this.retries = 0; // resends after a failure on the way
    this.retrying = false; // waiting to send again after a failure on the way
    this.registered = null; // the registration's promise (register)
    this.admitted = false; // whether the scene admitted this page's session
  }

  /** Admit this page's viser client into the scene (once; failures on the way retried). */
  register() {
    if (!this.enabled) return Promise.resolve(null);
    this.registered ||= (async () => {
      for (let attempt = 0; ; attempt += 1) {
        try {
          const answer = await api.putJSON("/api/scene3d/session", { session: this.session }, { signal: AbortSignal.timeout(REQUEST_TIMEOUT_MS) });
          this.admitted = true;
          return answer;
        } catch (err) {
          if (!isTransient(err) || attempt >= RETRY_DELAYS_MS.length) {
            this.registered = null; // the next 3D tab visit tries again
            throw err;
          }
          await sleep(RETRY_DELAYS_MS[attempt]);
        }
      }
    })();
    return this.registered;
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
    let settled = false; // answered, refused, or out of tries (not overtaken by a newer choice)
    this.notify();
    for (let attempt = 0; ; attempt += 1) {
      this.requests += 1;
      try {
        this.answer = await api.putJSON(
          "/api/scene3d/follow",
          { track_id: id, session: this.session },
          { signal: AbortSignal.timeout(REQUEST_TIMEOUT_MS) },
        );
        this.error = null;
        settled = true;
        break;
      } catch (err) {
        this.error = String(err.message || err);
        if (!isTransient(err) || attempt >= RETRY_DELAYS_MS.length) {
          settled = true;
          break;
        }
        this.retries += 1;
        this.retrying = true;
        this.notify();
        await sleep(RETRY_DELAYS_MS[attempt]);
        this.retrying = false;
        if (this.want !== id) break; // a newer choice goes instead
      }
    }
    // After a final failure too: no loop; the operator's next choice tries again.
    this.sent = settled ? id : undefined;
    this.inFlight = false;
    this.notify();
    if (this.want !== this.sent) this.pump();
  }

  notify() {
    this.onChange({
      trackId: this.want,
      pending: this.inFlight,
      error: this.error,
      retrying: this.retrying,
      answer: this.answer,
    });
  }
}
