/**
 * Live run stream: a WebSocket client that reconnects with exponential backoff and resyncs
 * from the `full` frame the server sends first on every connection. Deltas that arrive
 * before a full frame (or out of order) are dropped, so the view never applies a delta to
 * stale state. It asks for the binary encoding (frame-codec.js: the maps and series as
 * float32/float64 blocks, one encoding on the server shared by every viewer) and decodes each
 * message into the object a JSON frame parses to; a text message is still read as JSON.
 */
import { BACKOFF } from "./constants.js";
import { wsUrl } from "./api.js";
import { decodeFrame } from "./frame-codec.js";

/** Close codes after which reconnecting cannot help (not found, auth, policy). */
const FINAL_CLOSE = new Set([1008, 4001, 4003, 4004, 4401, 4403, 4404]);

export class LiveStream {
  /**
   * @param {string} path  e.g. "/api/runs/7/stream"
   * @param {{onFull?, onDelta?, onStatus?, onConnection?}} handlers
   *   onConnection(state, detail): state ∈ "connecting" | "open" | "reconnecting" | "closed"
   */
  constructor(path, handlers = {}) {
    this.path = path;
    this.handlers = handlers;
    this.socket = null;
    this.delay = BACKOFF.initialMs;
    this.timer = 0;
    this.closed = false;
    this.synced = false;
    this.lastSample = -1;
    this.attempt = 0;
  }

  start() {
    this.closed = false;
    this.connect();
    return this;
  }

  close() {
    this.closed = true;
    clearTimeout(this.timer);
    if (this.socket) {
      this.socket.onclose = null;
      this.socket.onerror = null;
      this.socket.onmessage = null;
      try {
        this.socket.close(1000, "view closed");
      } catch {
        /* already closed */
      }
    }
    this.socket = null;
    this.emitConnection("closed", {});
  }

  connect() {
    if (this.closed) return;
    this.synced = false;
    this.attempt += 1;
    this.emitConnection("connecting", { attempt: this.attempt });
    let socket;
    try {
      const url = new URL(wsUrl(this.path));
      url.searchParams.set("encoding", "binary");
      socket = new WebSocket(url);
      socket.binaryType = "arraybuffer";
    } catch (err) {
      this.scheduleReconnect(String(err));
      return;
    }
    this.socket = socket;
    socket.onopen = () => this.emitConnection("open", {});
    socket.onmessage = (event) => this.receive(event.data);
    socket.onerror = () => {
      /* onclose follows and decides */
    };
    socket.onclose = (event) => {
      this.socket = null;
      if (this.closed) return;
      if (FINAL_CLOSE.has(event.code)) {
        this.closed = true;
        this.emitConnection("closed", {
          code: event.code,
          reason: event.reason || "stream refused",
        });
        return;
      }
      this.scheduleReconnect(event.reason || `connection lost (${event.code})`);
    };
  }

  scheduleReconnect(reason) {
    if (this.closed) return;
    const jitter = 0.8 + Math.random() * 0.4;
    const wait = Math.min(BACKOFF.maxMs, this.delay) * jitter;
    this.delay = Math.min(BACKOFF.maxMs, this.delay * BACKOFF.factor);
    this.emitConnection("reconnecting", { inMs: wait, reason });
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.connect(), wait);
  }

  receive(raw) {
    let msg;
    try {
      msg = raw instanceof ArrayBuffer ? decodeFrame(raw) : JSON.parse(raw);
    } catch {
      return;
    }
    switch (msg.type) {
      case "full":
        this.synced = true;
        this.delay = BACKOFF.initialMs;
        this.attempt = 0;
        this.lastSample = msg.sample ?? -1;
        this.handlers.onFull?.(msg);
        break;
      case "delta":
        if (!this.synced) return;
        if (typeof msg.sample === "number" && msg.sample < this.lastSample) return;
        this.lastSample = msg.sample ?? this.lastSample;
        this.handlers.onDelta?.(msg);
        break;
      case "status":
        this.handlers.onStatus?.(msg);
        break;
      default:
        break;
    }
  }

  emitConnection(state, detail) {
    this.handlers.onConnection?.(state, detail);
  }
}
