// The live stream: /ws with resume after a drop, reconnecting by itself.
//
// Each stored message has a `seq`; after a drop the client reconnects with `?since=<last
// seq seen>&store=<the store id of its hello>` and the server sends what was missed first,
// so nothing is lost. Sequence numbers belong to one store (database): when the hello
// names another store than ours, says `start_over` (our `since` cannot be resumed), or its
// newest seq is below ours, the page's store starts over from the server's state.
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
    this.storeId = null; // the store our seqs belong to (from the first hello)
    this.nResets = 0; // times the page started over (a new store)
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
      let url = wsURL(this.lastSeq, { batch: true });
      if (this.lastSeq !== null && this.storeId !== null) {
        url += `&store=${encodeURIComponent(this.storeId)}`;
      }
      ws = new WebSocket(url);
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
      const otherStore =
        this.storeId !== null && msg.store_id !== undefined && msg.store_id !== this.storeId;
      if (
        this.lastSeq !== null &&
        (msg.start_over || otherStore || msg.last_seq < this.lastSeq)
      ) {
        // Our seqs mean nothing here (a new database): start over from the server's state;
        // it sends what comes after its newest message.
        this.lastSeq = msg.last_seq;
        this.nResets += 1;
        this.h.onReset(msg);
      } else if (this.lastSeq === null) {
        this.lastSeq = msg.last_seq;
      }
      if (msg.store_id !== undefined) this.storeId = msg.store_id;
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
