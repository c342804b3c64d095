// Live updates: server-sent events read with fetch() (so that the Authorization header can be sent; EventSource
// cannot send headers), with a polling fallback while the stream is down, and the live/polling/offline indicator.

import { ApiError, AuthError, api } from "./api.js";
import { $, sleep } from "./dom.js";

const POLL_MS = 3000;

export function setLive(state) {
  const el = $("live");
  el.dataset.state = state;
  el.textContent = { live: "live", polling: "polling", off: "offline" }[state] || state;
}

// Reads a text/event-stream and calls onEvent(name, data). While it is down, onDown() is called every POLL_MS
// (the view's polling fallback). Reconnects with a growing delay.
export class Stream {
  constructor(path, onEvent, onDown) {
    this.path = path;
    this.onEvent = onEvent;
    this.onDown = onDown;
    this.stopped = false;
    this.ctrl = null;
    this.pollTimer = null;
    this.run();
  }

  stop() {
    this.stopped = true;
    if (this.ctrl) this.ctrl.abort();
    this.poll(false);
  }

  poll(on) {
    if (on && !this.pollTimer && !this.stopped) {
      setLive("polling");
      this.pollTimer = setInterval(() => this.onDown(), POLL_MS);
    } else if (!on && this.pollTimer) {
      clearInterval(this.pollTimer);
      this.pollTimer = null;
    }
  }

  async run() {
    let delay = 1000;
    const streaming = typeof ReadableStream !== "undefined" && typeof TextDecoderStream !== "undefined";
    while (!this.stopped) {
      if (!streaming) { this.poll(true); return; }
      try {
        this.ctrl = new AbortController();
        const r = await api(this.path, { signal: this.ctrl.signal, headers: { Accept: "text/event-stream" } });
        this.poll(false);
        setLive("live");
        delay = 1000;
        await this.read(r.body.pipeThrough(new TextDecoderStream()).getReader());
      } catch (e) {
        if (this.stopped || e instanceof AuthError) return;
        if (e instanceof ApiError && e.status === 404) { this.onEvent("deleted", "{}"); return; }
      }
      if (this.stopped) return;
      this.poll(true);
      this.onDown();
      await sleep(delay);
      delay = Math.min(2 * delay, 15000);
    }
  }

  async read(reader) {
    let buf = "";
    for (;;) {
      const { value, done } = await reader.read();
      if (done) return;
      buf += value.replace(/\r\n?/g, "\n");
      let i;
      while ((i = buf.indexOf("\n\n")) >= 0) {
        const block = buf.slice(0, i);
        buf = buf.slice(i + 2);
        let name = "message";
        const data = [];
        for (const line of block.split("\n")) {
          if (line.startsWith(":")) continue;
          const colon = line.indexOf(":");
          const field = colon < 0 ? line : line.slice(0, colon);
          const val = colon < 0 ? "" : line.slice(colon + 1).replace(/^ /, "");
          if (field === "event") name = val;
          else if (field === "data") data.push(val);
        }
        if (data.length && !this.stopped) this.onEvent(name, data.join("\n"));
      }
    }
  }
}
