// The timeline: the displayed time, live following, play/pause, speed and the scrubber.
//
// `live`: the shown time follows the newest data. Otherwise the shown time is `t`, which
// advances at `speed` times real time while playing; playing into the newest data goes
// live again. The label shows clock time with the date (UTC, or local time with its
// offset after the UTC/local toggle; times inside are UNIX seconds), the scrubber's
// tooltip the clock time under it.

import { clockMode, fmtClock, onClockChange, setLocalClock, zoneLabel } from "./clock.mjs";
import { $ } from "./util.mjs";

const PLAY_SVG = '<svg viewBox="0 0 16 16" width="14" height="14" aria-label="play"><polygon points="3,2 14,8 3,14" fill="currentColor"/></svg>';
const PAUSE_SVG = '<svg viewBox="0 0 16 16" width="14" height="14" aria-label="pause"><rect x="3" y="2" width="4" height="12" fill="currentColor"/><rect x="9" y="2" width="4" height="12" fill="currentColor"/></svg>';

export class Timeline {
  constructor(store, onChange) {
    this.store = store;
    this.onChange = onChange;
    this.live = true;
    this.playing = true;
    this.speed = 1;
    this.t = 0;
    this.lastFrame = null;
    this.scrubbing = false;
    this.play = $("#play");
    this.scrub = $("#scrub");
    this.label = $("#t-label");
    this.clockText = $("#t-clock");
    this.dateText = $("#t-date");
    this.liveBtn = $("#go-live");
    this.zoneBtn = $("#clock-zone");
    this.zoneBtn.addEventListener("click", () => setLocalClock(!clockMode.local));
    onClockChange(() => {
      this.sync();
      this.onChange();
    });
    this.play.addEventListener("click", () => this.toggle());
    this.liveBtn.addEventListener("click", () => this.goLive());
    $("#speed").addEventListener("change", (e) => {
      this.speed = Number(e.target.value);
    });
    this.scrub.addEventListener("input", () => {
      this.scrubbing = true;
      this.seek(Number(this.scrub.value));
    });
    this.scrub.addEventListener("change", () => {
      this.scrubbing = false;
    });
    this.sync();
  }

  range() {
    const s = this.store;
    if (s.tMin === null) return [0, 1];
    return [s.tMin, Math.max(s.tMax, s.tMin + 1)];
  }

  /** The displayed time. */
  now() {
    return this.live && this.store.tMax !== null ? this.store.tMax : this.t;
  }

  toggle() {
    if (this.live || this.playing) this.pause();
    else this.resume();
  }

  pause() {
    this.t = this.now();
    this.live = false;
    this.playing = false;
    this.sync();
    this.onChange();
  }

  resume() {
    this.playing = true;
    this.lastFrame = null;
    this.sync();
  }

  goLive() {
    this.live = true;
    this.playing = true;
    this.sync();
    this.onChange();
  }

  seek(t) {
    const [a, b] = this.range();
    this.t = Math.min(b, Math.max(a, t));
    this.live = false;
    this.sync();
    this.onChange();
  }

  step(dt) {
    const wasPlaying = this.playing && !this.live;
    this.seek(this.now() + dt);
    this.playing = wasPlaying;
    this.sync();
  }

  /** Advance with the animation frame clock; true when the shown time moved. */
  tick(nowMs) {
    const dtS = this.lastFrame === null ? 0 : (nowMs - this.lastFrame) / 1000;
    this.lastFrame = nowMs;
    if (this.live || !this.playing || this.scrubbing) return false;
    const [, b] = this.range();
    this.t += Math.min(dtS, 0.25) * this.speed;
    if (this.t >= b) {
      this.t = b;
      this.live = true;
    }
    return dtS > 0;
  }

  sync() {
    const [a, b] = this.range();
    this.scrub.min = String(a);
    this.scrub.max = String(b);
    const t = this.now();
    if (!this.scrubbing) this.scrub.value = String(t);
    // clock time with its date, never session seconds (the end: the newest data)
    // Two lines: the shown clock time and its zone; the date and the newest data's time.
    this.clockText.textContent = `${fmtClock(t)} ${clockMode.local ? "local" : "UTC"}`;
    this.dateText.textContent = `${fmtClock(t, { date: true }).slice(0, 10)} · newest ${fmtClock(b, { digits: 0 })}`;
    this.label.title = `shown ${fmtClock(t, { date: true, digits: 3 })} ${zoneLabel(t)}; newest data ${fmtClock(b, { date: true })}`;
    this.scrub.title = `${fmtClock(t, { date: true })} ${zoneLabel(t)} (from ${fmtClock(a, { date: true, digits: 0 })})`;
    this.zoneBtn.textContent = clockMode.local ? "local" : "UTC";
    this.zoneBtn.classList.toggle("on", clockMode.local);
    const on = this.live || this.playing;
    if (this.play.dataset.on !== String(on)) {
      this.play.dataset.on = String(on);
      this.play.innerHTML = on ? PAUSE_SVG : PLAY_SVG;
    }
    this.play.title = `${this.live || this.playing ? "pause" : "play"} (space)`;
    this.liveBtn.classList.toggle("on", this.live);
  }
}
