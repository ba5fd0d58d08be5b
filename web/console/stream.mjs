// The live stream: /ws with resume after a drop, reconnecting by itself.
//
// Each stored message has a `seq`; after a drop the client reconnects with `?since=<last
// seq seen>` and the server sends what was missed first, so nothing is lost. If the
// server's newest seq is below ours (a fresh database), the store starts over.
//
// The page connects with `batch=1`: when several messages wait on the server, they come in
// one frame, `{"type": "batch", "messages": [...]}`, and are applied one by one in order,
// exactly as if each had come alone (one `onmessage` event per frame, not per message).

import { wsURL } from "./api.mjs";

const MIN_DELAY_MS = 300;
const MAX_DELAY_MS = 4000;

export class Stream {
  /**
   * @param {object} handlers  onMessage(msg), onStatus(state, detail), onReset(), onHello(msg)
   */
  constructor(handlers) {
    this.h = handlers;
    this.lastSeq = null;
    this.ws = null;
    this.delay = MIN_DELAY_MS;
    this.closed = false;
    this.timer = null;
    this.nReceived = 0; // messages handed on (not frames; repeats of a seq not counted)
    this.nGaps = 0;
    this.nFrames = 0; // WebSocket frames received
  }

  start(since) {
    this.lastSeq = since;
    this.connect();
  }

  connect() {
    if (this.closed) return;
    this.h.onStatus(this.lastSeq === null ? "connecting" : "reconnecting");
    let ws;
    try {
      ws = new WebSocket(wsURL(this.lastSeq, { batch: true }));
    } catch (err) {
      this.retry();
      return;
    }
    this.ws = ws;
    ws.onmessage = (ev) => this.receive(ev.data);
    ws.onclose = (ev) => {
      if (this.ws !== ws) return;
      this.ws = null;
      if (ev.code === 1008) {
        this.h.onStatus("unauthorized", ev.reason);
        return;
      }
      this.retry();
    };
    ws.onerror = () => {
      /* onclose follows */
    };
  }

  retry() {
    if (this.closed) return;
    this.h.onStatus("reconnecting");
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.connect(), this.delay);
    this.delay = Math.min(MAX_DELAY_MS, this.delay * 1.6);
  }

  receive(text) {
    let msg;
    try {
      msg = JSON.parse(text);
    } catch (_) {
      return;
    }
    this.nFrames += 1;
    if (msg.type === "batch") {
      for (const inner of msg.messages || []) {
        try {
          this.apply(inner);
        } catch (err) {
          // one bad message must not cost the rest of the frame; still report it
          setTimeout(() => {
            throw err;
          });
        }
      }
      return;
    }
    this.apply(msg);
  }

  apply(msg) {
    if (msg.type === "hello") {
      this.delay = MIN_DELAY_MS;
      if (this.lastSeq !== null && msg.last_seq < this.lastSeq) {
        // The server forgot what we saw (new database): start over from its state.
        this.lastSeq = msg.last_seq;
        this.h.onReset(msg);
      } else if (this.lastSeq === null) {
        this.lastSeq = msg.last_seq;
      }
      this.h.onHello(msg);
      this.h.onStatus("live");
      return;
    }
    if (typeof msg.seq === "number") {
      if (this.lastSeq !== null && msg.seq <= this.lastSeq) return; // already applied
      if (this.lastSeq !== null && msg.seq > this.lastSeq + 1) this.nGaps += 1;
      this.lastSeq = msg.seq;
    }
    this.nReceived += 1;
    this.h.onMessage(msg);
  }

  /** Close and reopen at once (used after the token changes). */
  restart() {
    if (this.ws) {
      const ws = this.ws;
      this.ws = null;
      ws.close();
    }
    this.delay = MIN_DELAY_MS;
    this.connect();
  }
}
