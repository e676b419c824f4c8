// The page's end of the console protocol (docs/console.md, "Protocol"): one WebSocket, JSON
// messages, `hello` first, request ids answered by `reply` messages.

export const PROTOCOL_VERSION = 1;

export class Link {
  /**
   * @param {string|null} token the control token from the URL, or null (read-only)
   * @param {object} handlers type -> function(message), plus onOpen/onClose(reason, final)
   */
  constructor(token, handlers) {
    this.token = token;
    this.handlers = handlers;
    this.ws = null;
    this.nextId = 1;
    this.pending = new Map();
    this.final = false;
    this.retry = 500;
  }

  connect() {
    const ws = new WebSocket(`ws://${location.host}/ws`);
    this.ws = ws;
    ws.onopen = () => {
      this.retry = 500;
      const hello = { type: "hello", v: PROTOCOL_VERSION };
      if (this.token) hello.token = this.token;
      ws.send(JSON.stringify(hello));
      this.handlers.onOpen && this.handlers.onOpen();
    };
    ws.onmessage = (ev) => {
      let msg;
      try { msg = JSON.parse(ev.data); } catch (e) { return; }
      if (msg.type === "reply") {
        const done = this.pending.get(msg.id);
        if (done) { this.pending.delete(msg.id); done(msg); }
        return;
      }
      if (msg.type === "bye") { this.final = true; }
      const handler = this.handlers[msg.type];
      if (handler) handler(msg);
    };
    ws.onclose = (ev) => {
      for (const done of this.pending.values()) done({ ok: false, reason: "the connection closed" });
      this.pending.clear();
      const reason = ev.reason || (this.final ? "the console closed" : "the connection to the console was lost");
      this.handlers.onClose && this.handlers.onClose(reason, this.final || ev.code === 1008 || ev.code === 1009);
      if (!this.final && ev.code !== 1008 && ev.code !== 1009) {
        setTimeout(() => this.connect(), this.retry);
        this.retry = Math.min(this.retry * 2, 8000);
      }
    };
  }

  get open() { return this.ws && this.ws.readyState === WebSocket.OPEN; }

  /** Send a message that gets no reply (``painted``). */
  notify(type, fields = {}) {
    if (this.open) this.ws.send(JSON.stringify({ type, ...fields }));
  }

  /** Send a request; resolves with the server's reply ({ok, reason, ...}). */
  request(type, fields = {}) {
    return new Promise((resolve) => {
      if (!this.open) { resolve({ ok: false, reason: "not connected to the console" }); return; }
      const id = this.nextId++;
      this.pending.set(id, resolve);
      this.ws.send(JSON.stringify({ type, id, ...fields }));
    });
  }
}

/** GET/POST the console's JSON API with the token header. */
export async function api(path, token, { method = "GET", body = null, text = false } = {}) {
  const headers = {};
  if (token) headers["X-Petrobot-Token"] = token;
  if (body !== null) headers["Content-Type"] = "application/json";
  const res = await fetch(path, { method, headers, body: body === null ? null : JSON.stringify(body),
                                  cache: "no-store", credentials: "omit" });
  if (text) {
    const t = await res.text();
    if (!res.ok) { let why = t; try { why = JSON.parse(t).error; } catch (e) { /* plain text */ } throw new Error(why); }
    return t;
  }
  const data = await res.json();
  if (!res.ok) throw new Error(data.error || `HTTP ${res.status}`);
  return data;
}
