// Browser client of the hub (docs/protocol.md): one WebSocket, the same envelope as every
// other client, reconnect with exponential back-off and jitter, subscriptions sent again after
// each reconnect, heartbeats, request/reply. Status changes are events a page shows.
// Messages are typed by web/lib/messages.d.ts (generated from guidebot/payloads).

/** @typedef {import("/lib/messages.js").MessageType} MessageType */
/** @typedef {import("/lib/messages.js").Pattern} Pattern */
/** @typedef {import("/lib/messages.js").Payloads} Payloads */
/**
 * @template {MessageType} [T=MessageType]
 * @typedef {import("/lib/messages.js").Message<T>} Message
 */

const FINAL_CODES = new Map([
  [4000, "replaced by a newer connection with the same name"],
  [4001, "the hub does not accept this token (wrong or expired)"],
  [4003, "this token may not use that name"],
]);

let counter = 0;
const prefix = Math.random().toString(36).slice(2, 8);

/** A new message id: random page prefix + counter, as the Python client does. */
export function newId() {
  counter += 1;
  return `w${prefix}-${counter}`;
}

/** True when a shell-style pattern (`*`, `?`) matches a message type. */
export function matches(pattern, type) {
  if (pattern === "*" || pattern === type) return true;
  const re = new RegExp(
    "^" + pattern.replace(/[.+^${}()|[\]\\]/g, "\\$&").replace(/\*/g, ".*").replace(/\?/g, ".") + "$",
  );
  return re.test(type);
}

export class HubClient extends EventTarget {
  /**
   * @param {{url?: string, token: string | null, backoffInitial?: number, backoffMax?: number,
   *          heartbeatInterval?: number, heartbeatTimeout?: number}} options
   */
  constructor(options) {
    super();
    const scheme = location.protocol === "https:" ? "wss:" : "ws:";
    this.url = options.url ?? `${scheme}//${location.host}/ws`;
    this.token = options.token;
    this.backoffInitial = options.backoffInitial ?? 0.5;
    this.backoffMax = options.backoffMax ?? 10;
    this.heartbeatInterval = options.heartbeatInterval ?? 5;
    this.heartbeatTimeout = options.heartbeatTimeout ?? 15;
    /** "connecting" | "open" | "reconnecting" | "refused" | "stopped" */
    this.status = "connecting";
    this.reason = "";
    this.name = null;
    this.role = null;
    this.patterns = new Set();
    this.handlers = [];
    this.pending = new Map();
    this.ws = null;
    this.attempt = 0;
    this.lastFrame = 0;
    this.timer = null;
    this.heartbeat = null;
    this.stopped = false;
  }

  start() {
    this.stopped = false;
    this.#connect();
    return this;
  }

  stop() {
    this.stopped = true;
    clearTimeout(this.timer);
    clearInterval(this.heartbeat);
    if (this.ws) this.ws.close(1000, "page closed");
    this.#setStatus("stopped", "");
  }

  /**
   * @template {MessageType} T
   * @overload
   * @param {T} pattern one message type: the handler gets its payload's type
   * @param {(message: Message<T>) => void} handler
   * @returns {() => void}
   */
  /**
   * @overload
   * @param {import("/lib/messages.js").Wildcard} pattern
   * @param {(message: Message) => void} handler
   * @returns {() => void}
   */
  /**
   * Receive messages whose type matches `pattern`; returns the function that stops it.
   * @param {Pattern} pattern
   * @param {(message: Message) => void} handler
   * @returns {() => void}
   */
  on(pattern, handler) {
    const entry = { pattern, handler };
    this.handlers.push(entry);
    return () => {
      this.handlers = this.handlers.filter((e) => e !== entry);
    };
  }

  /**
   * Ask the hub for these message types (kept and sent again after every reconnect).
   * @param {...Pattern} patterns
   */
  subscribe(...patterns) {
    const fresh = patterns.filter((p) => !this.patterns.has(p));
    fresh.forEach((p) => this.patterns.add(p));
    if (fresh.length) this.#sendNow({ type: "subscribe", payload: { patterns: fresh } });
  }

  /** @param {...Pattern} patterns */
  unsubscribe(...patterns) {
    const known = patterns.filter((p) => this.patterns.delete(p));
    if (known.length) this.#sendNow({ type: "unsubscribe", payload: { patterns: known } });
  }

  /**
   * Publish (or send, with a destination); returns the message id. Dropped while offline.
   * @template {MessageType} T
   * @param {T} type
   * @param {Payloads[T]} payload
   * @param {string | null} [destination]
   * @returns {string}
   */
  publish(type, payload, destination = null) {
    const message = { type, id: newId(), timestamp: Date.now() / 1000, payload };
    if (destination) message.destination = destination;
    this.#sendNow(message);
    return message.id;
  }

  /**
   * Request/reply: resolves with the reply message, rejects on error or time-out.
   * @template {MessageType} T
   * @param {T} type
   * @param {Payloads[T]} payload
   * @param {string | null} [destination]
   * @param {number} [timeoutS]
   * @returns {Promise<Message>}
   */
  request(type, payload, destination = null, timeoutS = 5) {
    return new Promise((resolve, reject) => {
      if (this.status !== "open") {
        reject(new Error("not connected to the hub"));
        return;
      }
      const id = this.publish(type, payload, destination);
      const timer = setTimeout(() => {
        this.pending.delete(id);
        reject(new Error(`no answer to ${type} within ${timeoutS} s`));
      }, timeoutS * 1000);
      this.pending.set(id, { resolve, reject, timer });
    });
  }

  #sendNow(message) {
    if (this.ws && this.ws.readyState === WebSocket.OPEN) this.ws.send(JSON.stringify(message));
  }

  #setStatus(status, reason) {
    if (status === this.status && reason === this.reason) return;
    this.status = status;
    this.reason = reason;
    this.dispatchEvent(new CustomEvent("status", { detail: { status, reason } }));
  }

  #connect() {
    // No token: a person's page, signed in by its session cookie (docs/security.md).
    const query = this.token ? `?token=${encodeURIComponent(this.token)}` : "";
    const ws = new WebSocket(`${this.url}${query}`);
    this.ws = ws;
    ws.onopen = () => {
      this.attempt = 0;
      this.lastFrame = performance.now();
      if (this.patterns.size) {
        ws.send(JSON.stringify({ type: "subscribe", id: newId(), payload: { patterns: [...this.patterns] } }));
      }
      clearInterval(this.heartbeat);
      this.heartbeat = setInterval(() => this.#beat(), this.heartbeatInterval * 1000);
    };
    ws.onmessage = (event) => {
      this.lastFrame = performance.now();
      let data;
      try {
        data = JSON.parse(event.data);
      } catch {
        return;
      }
      for (const message of Array.isArray(data) ? data : [data]) this.#dispatch(message);
    };
    ws.onclose = (event) => {
      if (this.ws !== ws) return;
      clearInterval(this.heartbeat);
      for (const [id, p] of this.pending) {
        clearTimeout(p.timer);
        p.reject(new Error("connection lost"));
        this.pending.delete(id);
      }
      if (this.stopped) return;
      const final = FINAL_CODES.get(event.code);
      if (final) {
        this.#setStatus("refused", event.reason || final); // the server's reason says more
        return;
      }
      this.#setStatus("reconnecting", event.reason || "connection lost");
      this.#retry();
    };
  }

  #retry() {
    const base = Math.min(this.backoffMax, this.backoffInitial * 2 ** this.attempt);
    this.attempt += 1;
    const delay = base * (0.8 + Math.random() * 0.4);
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.#connect(), delay * 1000);
  }

  #beat() {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return;
    if (performance.now() - this.lastFrame > this.heartbeatTimeout * 1000) {
      this.ws.close(4100, "no heartbeat");
      return;
    }
    this.#sendNow({ type: "ping", id: newId(), destination: "hub", payload: {} });
  }

  /** @param {Message} message */
  #dispatch(message) {
    if (message.type === "welcome") {
      this.name = message.payload.name;
      this.role = message.payload.role;
      this.#setStatus("open", "");
      this.dispatchEvent(new CustomEvent("connect", { detail: message.payload }));
      return;
    }
    if (message.type === "pong") return;
    const waiting = message.correlation_id && this.pending.get(message.correlation_id);
    if (waiting) {
      this.pending.delete(message.correlation_id);
      clearTimeout(waiting.timer);
      if (message.type === "error") waiting.reject(new Error(message.payload.reason ?? "refused"));
      else waiting.resolve(message);
      return;
    }
    for (const { pattern, handler } of this.handlers) {
      if (matches(pattern, message.type)) {
        try {
          handler(message);
        } catch (err) {
          console.error(`hub handler for ${message.type} failed`, err);
        }
      }
    }
  }
}
