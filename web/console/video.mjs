// Live video in the camera panels: the newest frame the server holds for each camera.
//
// The page polls GET /api/frames (every camera's newest frame tag and time, one request for
// all panels) every POLL_MS (5 a second) with If-None-Match: the server answers 304 with no
// body while no frame changed; while it holds no frame at all the page asks every IDLE_MS.
// A camera whose tag changed has its GET /api/sensors/{id}/frame.jpg fetched (with its own
// If-None-Match, so a frame is never fetched twice). A new frame is shown over the
// camera's still (an <img> of a blob: URL: the token stays in the request headers, never in an
// image URL or a server log), and the boxes and track ids are drawn over it as over the still,
// but at the frame's own time (frame.mjs reads `panel.videoT`, `panel.videoWindowS`), so a box
// sits on the object it belongs to. A label in the picture's corner says "video HH:MM:SS.s
// UTC" with the frame's clock time; when no new frame came for STALE_MS (5 s), or the timeline is not live (the
// frame is the newest, not the moment shown), the panel falls back to the still and says
// "still".
//
// Polling rather than the MJPEG (multipart/x-mixed-replace) stream: an <img> stream cannot
// send the Authorization header (the token would go into its URL), it holds a connection
// and a server task per camera per client for as long as the page is open, and a client that
// falls behind gets frames it no longer wants; a poll costs a 304 when nothing changed, is
// paced by the page (and stops when the tab is hidden), and always fetches the newest frame.
// `window.demtrack.video` exposes the state for tests.

import * as api from "./api.mjs";
import { fmtClock, zoneLabel } from "./clock.mjs";
import { timeline, ui } from "./state.mjs";
import { el } from "./util.mjs";

export const POLL_MS = 200;
export const IDLE_MS = 2000;
export const STALE_MS = 5000;
/** Boxes drawn over a video frame: the fixes of the frame's own moment (s). */
const FRAME_WINDOW_S = 0.01;

export const video = { feeds: new Map(), indexTag: null, anyFrames: false };

class Feed {
  constructor(panel) {
    this.panel = panel;
    this.path = `/api/sensors/${encodeURIComponent(panel.sensor.id)}/frame.jpg`;
    this.etag = null;
    this.url = null; // blob: URL of the frame shown
    this.t_s = null; // the frame's UTC (UNIX s)
    this.newMs = -Infinity; // performance.now() of the last new frame
    this.nFrames = 0;
    this.img = el("img", { class: "cam-video", alt: `${panel.sensor.id} video`, draggable: "false" });
    Object.assign(this.img.style, { position: "absolute", inset: "0", width: "100%", height: "100%", display: "none" });
    panel.canvas.before(this.img);
    // In the picture's corner, as a camera's on-screen clock (the header has no room left).
    this.label = el("span", { class: "cam-feed", text: "still", title: "no live video from this camera" });
    Object.assign(this.label.style, {
      position: "absolute", left: "4px", bottom: "4px", padding: "1px 5px", borderRadius: "3px",
      background: "rgba(0,0,0,0.6)", color: "#fff", font: "11px system-ui, sans-serif",
      fontVariantNumeric: "tabular-nums", pointerEvents: "none",
    });
    panel.wrap.append(this.label);
    this.state = null;
    this.show();
  }

  /** Fetch the newest frame (when its tag is not the one shown). */
  async fetchFrame() {
    const headers = { Authorization: `Bearer ${api.token() || ""}` };
    if (this.etag) headers["If-None-Match"] = this.etag;
    const resp = await fetch(this.path, { headers, cache: "no-store" });
    if (resp.status === 304 || !resp.ok) return;
    const tag = resp.headers.get("ETag");
    const t = Number(resp.headers.get("X-Frame-Time-S"));
    const url = URL.createObjectURL(await resp.blob());
    const next = new Image();
    next.src = url;
    try {
      await next.decode(); // swap once decoded: no blank panel between two frames
    } catch {
      URL.revokeObjectURL(url);
      return;
    }
    const old = this.url;
    this.img.src = url;
    if (old) URL.revokeObjectURL(old);
    this.url = url;
    this.etag = tag;
    this.t_s = Number.isFinite(t) ? t : null;
    this.newMs = performance.now();
    this.nFrames += 1;
  }

  /** Video while fresh and live, else the still; the label says which. */
  show() {
    const fresh = this.url !== null && performance.now() - this.newMs <= STALE_MS && timeline.live;
    const p = this.panel;
    const state = fresh ? "video" : "still";
    this.img.style.display = fresh ? "block" : "none";
    p.videoT = fresh ? this.t_s : null;
    p.videoWindowS = fresh ? FRAME_WINDOW_S : null;
    p.root.dataset.feed = state;
    if (fresh) {
      this.label.textContent = `video ${fmtClock(this.t_s, { digits: 1 })} ${zoneLabel(this.t_s)}`;
      this.label.title = "live video: the newest frame from the camera, with its capture time";
      this.label.style.opacity = "1";
    } else {
      this.label.textContent = "still";
      this.label.title = this.url ? "video stopped (no new frame for 5 s) or the timeline is not live: the camera's still" : "no live video from this camera: its still";
      this.label.style.opacity = "0.7";
    }
    if (state !== this.state || fresh) ui.dirty = true; // redraw the boxes at the frame's time
    this.state = state;
  }
}

/** One poll of /api/frames (and of the frames that changed); the delay to the next (ms). */
async function tick() {
  if (document.hidden) return IDLE_MS;
  const headers = { Authorization: `Bearer ${api.token() || ""}` };
  if (video.indexTag) headers["If-None-Match"] = video.indexTag;
  let wait = IDLE_MS;
  try {
    const resp = await fetch("/api/frames", { headers, cache: "no-store" });
    if (resp.status === 304) wait = video.anyFrames ? POLL_MS : IDLE_MS;
    else if (resp.ok) {
      const frames = (await resp.json()).frames || {};
      video.indexTag = resp.headers.get("ETag");
      video.anyFrames = Object.keys(frames).length > 0;
      const changed = [...video.feeds].filter(([sid, f]) => frames[sid] && frames[sid].etag !== f.etag);
      await Promise.all(changed.map(([, f]) => f.fetchFrame().catch(() => {})));
      wait = video.anyFrames ? POLL_MS : IDLE_MS;
    }
  } catch {
    wait = IDLE_MS; // the server is away: the stills come back after STALE_MS
  }
  for (const f of video.feeds.values()) f.show();
  return wait;
}

async function loop() {
  for (;;) {
    const wait = await tick();
    await new Promise((r) => setTimeout(r, wait));
  }
}

/** Starts a feed for every camera panel and the poll (once, after the panels are built). */
export function installVideo() {
  window.demtrack.video = video;
  for (const [sid, panel] of ui.cams) video.feeds.set(sid, new Feed(panel));
  loop();
}
