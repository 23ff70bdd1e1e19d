// One WebSocket stream of a session: subscribe, receive msgpack messages, reconnect when dropped.
import { decode } from "@msgpack/msgpack";

const FATAL = new Map([
  [4400, "the server refused a message"],
  [4401, "the token was refused"],
  [4404, "no such session for this token"],
  [1009, "message too large"],
]);

export class Stream {
  // handlers: onMessage(msg), onStatus(text, isError), onOpen()
  constructor(url, subscription, handlers) {
    this.url = url;
    this.subscription = subscription;
    this.handlers = handlers;
    this.ws = null;
    this.closed = false;
    this.retryMs = 500;
    this.timer = null;
    this.droppedBefore = 0; // frames dropped on earlier connections
    this.dropped = 0;
    this.connections = 0;
  }

  get open() { return this.ws !== null && this.ws.readyState === WebSocket.OPEN; }
  get totalDropped() { return this.droppedBefore + this.dropped; }

  connect() {
    if (this.closed) return;
    const ws = new WebSocket(this.url);
    ws.binaryType = "arraybuffer";
    this.ws = ws;
    ws.onopen = () => {
      this.retryMs = 500;
      this.connections += 1;
      this.send({ type: "subscribe", ...this.subscription });
      if (this.handlers.onOpen) this.handlers.onOpen(this.connections > 1);
    };
    ws.onmessage = (ev) => {
      if (!(ev.data instanceof ArrayBuffer)) return;
      const msg = decode(new Uint8Array(ev.data));
      if (msg.type === "frame") this.dropped = msg.dropped;
      this.handlers.onMessage(msg, ev.data.byteLength);
    };
    ws.onclose = (ev) => {
      if (this.ws !== ws) return;
      this.ws = null;
      this.droppedBefore += this.dropped;
      this.dropped = 0;
      if (this.closed) return;
      if (FATAL.has(ev.code)) {
        this.closed = true;
        this.handlers.onStatus(`stream closed: ${FATAL.get(ev.code)} ${ev.reason || ""}`, true);
        return;
      }
      const wait = this.retryMs;
      this.retryMs = Math.min(this.retryMs * 2, 5000);
      this.handlers.onStatus(`connection lost; reconnecting in ${(wait / 1000).toFixed(1)} s`, true);
      this.timer = setTimeout(() => this.connect(), wait);
    };
  }

  send(msg) {
    if (!this.open) return false;
    this.ws.send(JSON.stringify(msg));
    return true;
  }

  resubscribe(subscription) {
    this.subscription = subscription;
    this.send({ type: "subscribe", ...subscription });
  }

  close() {
    this.closed = true;
    clearTimeout(this.timer);
    if (this.ws) this.ws.close(1000);
    this.ws = null;
  }
}
