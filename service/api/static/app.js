// drt job monitor: jobs, one job, the farm. Reads only the public HTTP API (/v1).
//
// Safety: every piece of text from the server (scene names, errors, the renderer's warnings) goes into the page
// through textContent (the h() helper below); nothing is ever parsed as HTML. The page's CSP forbids inline script.
// Live updates: server-sent events read with fetch() (so that the Authorization header can be sent; EventSource
// cannot send headers); while the stream is down the page polls the same data every few seconds.
"use strict";

(() => {
  const TOKEN_KEY = "drt.token";
  const STATES = ["queued", "running", "succeeded", "failed", "canceled"];
  const ACTIVE = new Set(["queued", "running"]);
  const POLL_MS = 3000;

  // ---------------------------------------------------------------------------------------------------- DOM
  function h(tag, attrs, ...children) {
    const el = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (v === null || v === undefined || v === false) continue;
      if (k === "class") el.className = v;
      else if (k === "dataset") Object.assign(el.dataset, v);
      else if (k.startsWith("on")) el.addEventListener(k.slice(2), v);
      else el.setAttribute(k, v === true ? "" : String(v));
    }
    for (const c of children.flat(Infinity)) {
      if (c === null || c === undefined || c === false) continue;
      el.append(c instanceof Node ? c : document.createTextNode(String(c)));
    }
    return el;
  }

  const $ = (id) => document.getElementById(id);
  const main = () => $("main");
  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

  function bar(fraction, label) {
    const pct = Math.max(0, Math.min(100, 100 * (fraction || 0)));
    const fill = h("div", { class: "fill" });
    fill.style.width = pct.toFixed(1) + "%"; // CSSOM, allowed by the CSP (unlike style attributes in markup)
    return h("div", { class: "bar", role: "progressbar", "aria-valuemin": 0, "aria-valuemax": 100,
      "aria-valuenow": Math.round(pct), "aria-label": label || "progress" }, fill);
  }

  function badge(state) {
    return h("span", { class: "badge", dataset: { state } }, state);
  }

  // ------------------------------------------------------------------------------------------------ formats
  function duration(seconds) {
    if (seconds === null || seconds === undefined || !isFinite(seconds) || seconds < 0) return "–";
    const s = Math.round(seconds);
    if (s < 60) return `${s}s`;
    const m = Math.floor(s / 60);
    if (m < 60) return `${m}m ${String(s % 60).padStart(2, "0")}s`;
    return `${Math.floor(m / 60)}h ${String(m % 60).padStart(2, "0")}m`;
  }

  function rate(x) {
    if (!x) return "–";
    for (const [div, unit] of [[1e9, "G"], [1e6, "M"], [1e3, "k"]]) {
      if (x >= div) return `${(x / div).toFixed(2)} ${unit}`;
    }
    return x.toFixed(0);
  }

  function bytes(n) {
    if (n === null || n === undefined) return "–";
    const units = ["B", "KiB", "MiB", "GiB", "TiB"];
    let i = 0;
    while (n >= 1024 && i < units.length - 1) { n /= 1024; i += 1; }
    return `${n.toFixed(i ? 1 : 0)} ${units[i]}`;
  }

  const when = (iso) => (iso ? new Date(iso) : null);

  // Whether job version a is strictly newer than b (every change stamps updated_at; a finished job is final).
  function newer(a, b) {
    const ta = Date.parse(a.updated_at), tb = Date.parse(b.updated_at);
    if (ta !== tb) return ta > tb;
    return !ACTIVE.has(a.state) && ACTIVE.has(b.state);
  }

  function clock(iso) {
    const d = when(iso);
    if (!d) return "–";
    const today = new Date().toDateString() === d.toDateString();
    return today ? d.toLocaleTimeString() : d.toLocaleString();
  }

  function elapsed(job) {
    const start = when(job.started_at);
    if (!start) return null;
    const end = when(job.finished_at) || new Date();
    return (end - start) / 1000;
  }

  function remaining(job) {
    if (job.state !== "running" || !(job.progress > 0)) return null;
    const e = elapsed(job);
    return e === null ? null : (e * (1 - job.progress)) / job.progress;
  }

  const pct = (x) => `${Math.floor(100 * (x || 0))}%`;
  const frameName = (t) => String(t); // JSON numbers: 12.0 arrives as 12, as the API names frames

  // ------------------------------------------------------------------------------------------------ the API
  class AuthError extends Error {}
  class ApiError extends Error {
    constructor(status, detail) { super(detail); this.status = status; }
  }

  function authHeaders(extra) {
    const headers = new Headers(extra || {});
    const token = sessionStorage.getItem(TOKEN_KEY);
    if (token) headers.set("Authorization", `Bearer ${token}`);
    return headers;
  }

  async function api(path, opts = {}) {
    const r = await fetch(path, { ...opts, headers: authHeaders(opts.headers), cache: "no-store" });
    if (r.status === 401) {
      showLogin(sessionStorage.getItem(TOKEN_KEY) ? "The token was not accepted." : "");
      throw new AuthError("unauthorized");
    }
    if (!r.ok) {
      let detail = r.statusText;
      try { detail = (await r.json()).detail || detail; } catch (_) { /* not JSON */ }
      throw new ApiError(r.status, `${r.status}: ${detail}`);
    }
    return r;
  }

  const getJSON = async (path) => (await api(path)).json();

  // An image or file behind the token: fetched with the header, shown through a blob: URL.
  async function blobURL(path) {
    const r = await api(path);
    return URL.createObjectURL(await r.blob());
  }

  async function download(path, filename) {
    const url = await blobURL(path);
    const a = h("a", { href: url, download: filename });
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 60000);
  }

  // ------------------------------------------------------------------------------- live updates (SSE over fetch)
  function setLive(state) {
    const el = $("live");
    el.dataset.state = state;
    el.textContent = { live: "live", polling: "polling", off: "offline" }[state] || state;
  }

  // Reads a text/event-stream and calls onEvent(name, data). While it is down, onDown() is called every POLL_MS
  // (the view's polling fallback). Reconnects with a growing delay.
  class Stream {
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

  // ------------------------------------------------------------------------------------------------ notices
  function notice(text, kind) {
    const box = $("notice");
    if (!box) return;
    box.replaceChildren(text ? h("p", { class: kind || "error", role: "alert" }, text) : "");
  }

  function reportError(e) {
    if (e instanceof AuthError) return;
    notice(e && e.message ? e.message : String(e));
  }

  // ----------------------------------------------------------------------------------------------- job list
  class JobsView {
    constructor(params) {
      this.filter = STATES.includes(params.get("state")) ? params.get("state") : "";
      this.jobs = new Map();
      this.rows = new Map(); // job id -> its <tr>
      this.cursor = null;
      this.tbody = h("tbody");
      this.empty = h("p", { class: "muted empty", hidden: true });
      this.more = h("button", { type: "button", class: "ghost", hidden: true, onclick: () => this.load(true) },
        "Load more");
      const chips = ["", ...STATES].map((s) => h("button", {
        type: "button", class: "chip", "aria-pressed": String(s === this.filter), dataset: { state: s || "all" },
        onclick: () => this.setFilter(s),
      }, s || "all"));
      this.chips = chips;
      main().replaceChildren(
        h("div", { class: "toolbar" }, h("h1", {}, "Jobs"), h("div", { class: "chips", role: "group",
          "aria-label": "filter by state" }, chips)),
        h("div", { id: "notice" }),
        h("table", { class: "jobs" },
          h("thead", {}, h("tr", {}, ["Scene", "State", "Priority", "Progress", "Samples/s", "Submitted",
            "Elapsed", "Remaining"].map((t) => h("th", { scope: "col" }, t)))),
          this.tbody),
        this.empty, this.more);
      this.stream = new Stream("/v1/events", (name, data) => this.onEvent(name, data), () => this.load(false));
      this.ticker = setInterval(() => this.tick(), 1000);
    }

    dispose() { this.stream.stop(); clearInterval(this.ticker); }

    setFilter(state) {
      this.filter = state;
      const url = state ? `/?state=${encodeURIComponent(state)}` : "/";
      history.replaceState(null, "", url);
      for (const c of this.chips) c.setAttribute("aria-pressed", String((c.dataset.state === "all" ? "" : c.dataset.state) === state));
      this.load(false);
    }

    // A snapshot can be older than events that arrive while it is in flight (the stream's first event starts a
    // load; a job submitted meanwhile is announced once and then stays quiet while it waits): the events heard
    // during a load are applied again over its snapshot, unless the snapshot holds a newer version of the job.
    async load(more) {
      const q = new URLSearchParams({ limit: "100" });
      if (this.filter) q.set("state", this.filter);
      if (more && this.cursor) q.set("cursor", this.cursor);
      const seq = (this.loadSeq = (this.loadSeq || 0) + 1);
      this.heard = new Map(); // job id -> its latest event ({deleted: true} for a deletion)
      try {
        const page = await getJSON(`/v1/jobs?${q}`);
        if (seq !== this.loadSeq) return; // a later load replaces this one
        if (!more) this.jobs.clear();
        for (const j of page.items) this.jobs.set(j.id, j);
        for (const [id, msg] of this.heard) {
          const held = this.jobs.get(id);
          if (msg.deleted) this.jobs.delete(id);
          else if (!held || !newer(held, msg)) this.apply(msg);
        }
        this.heard = null;
        this.cursor = page.next_cursor;
        notice("");
        this.render();
      } catch (e) { if (seq === this.loadSeq) this.heard = null; reportError(e); }
    }

    apply(msg) {
      if (!this.filter || msg.state === this.filter) this.jobs.set(msg.id, msg);
      else this.jobs.delete(msg.id);
    }

    onEvent(name, data) {
      if (name === "ready" || name === "resync") { this.load(false); return; }
      const msg = JSON.parse(data);
      if (name === "deleted") {
        this.jobs.delete(msg.id);
        if (this.heard) this.heard.set(msg.id, { deleted: true });
      } else if (name === "job") {
        const held = this.jobs.get(msg.id);
        if (!held || !newer(held, msg)) this.apply(msg);
        if (this.heard) this.heard.set(msg.id, msg);
      }
      this.render();
    }

    // Rows are kept and their cells updated in place (a row rebuilt under the pointer would swallow a click);
    // they are moved only when the order changes.
    render() {
      const jobs = [...this.jobs.values()].sort((a, b) => (a.created_at < b.created_at ? 1 : -1));
      const rows = jobs.map((j) => this.row(j));
      for (const [id, tr] of this.rows) if (!this.jobs.has(id)) { tr.remove(); this.rows.delete(id); }
      const current = [...this.tbody.children];
      if (current.length !== rows.length || rows.some((tr, i) => current[i] !== tr)) this.tbody.replaceChildren(...rows);
      this.empty.hidden = jobs.length > 0;
      this.empty.textContent = this.filter ? `No ${this.filter} jobs.` : "No jobs yet: submit one with drt submit SCENE.";
      this.more.hidden = !this.cursor;
    }

    row(j) {
      let tr = this.rows.get(j.id);
      if (!tr) {
        const cell = (label) => h("td", { dataset: { label } });
        tr = h("tr", { dataset: { id: j.id } }, ["Scene", "State", "Priority", "Progress", "Samples/s", "Submitted",
          "Elapsed", "Remaining"].map(cell));
        tr.cells[0].append(h("a", { href: `/jobs/${encodeURIComponent(j.id)}`, "data-internal": true, class: "scene" },
          j.scene.filename), h("span", { class: "id muted" }, j.id.slice(0, 8)));
        tr.cells[5].append(h("time", { datetime: j.created_at, title: j.created_at }, clock(j.created_at)));
        this.rows.set(j.id, tr);
      }
      if (tr.dataset.version === j.updated_at && tr.dataset.state === j.state) return tr;
      tr.dataset.version = j.updated_at;
      tr.dataset.state = j.state;
      tr.cells[1].replaceChildren(badge(j.state));
      tr.cells[2].textContent = String(j.priority);
      tr.cells[3].replaceChildren(h("div", { class: "progress" }, bar(j.progress, `progress of ${j.scene.filename}`),
        h("span", { class: "pct" }, pct(j.progress))));
      tr.cells[4].textContent = rate(j.samples_per_second);
      tr.cells[6].replaceChildren(h("span", { class: "elapsed" }, duration(elapsed(j))));
      tr.cells[7].replaceChildren(h("span", { class: "remaining" }, duration(remaining(j))));
      return tr;
    }

    tick() {
      for (const tr of this.tbody.children) {
        const j = this.jobs.get(tr.dataset.id);
        if (!j || j.state !== "running") continue;
        tr.querySelector(".elapsed").textContent = duration(elapsed(j));
        tr.querySelector(".remaining").textContent = duration(remaining(j));
      }
    }
  }

  // ------------------------------------------------------------------------------------------------ one job
  class JobView {
    constructor(id) {
      this.id = id;
      this.job = null;
      this.frameIdx = 0;
      this.tiles = null;
      this.previewURL = null;
      this.previewKey = null;
      this.previewBusy = false;
      this.tilesBusy = false;
      this.gone = false;
      main().replaceChildren(h("p", { class: "muted" }, "Loading…"), h("div", { id: "notice" }));
      this.stream = new Stream(`/v1/jobs/${encodeURIComponent(id)}/events`, (n, d) => this.onEvent(n, d),
        () => this.load());
      this.ticker = setInterval(() => this.tick(), 1000);
    }

    dispose() {
      this.stream.stop();
      clearInterval(this.ticker);
      if (this.previewURL) URL.revokeObjectURL(this.previewURL);
    }

    async load() {
      try {
        const job = await getJSON(`/v1/jobs/${encodeURIComponent(this.id)}`);
        if (!this.job || !newer(this.job, job)) this.update(job); // an event may have brought a newer version
      } catch (e) {
        if (e instanceof ApiError && e.status === 404) this.deleted();
        else reportError(e);
      }
    }

    onEvent(name, data) {
      if (name === "job") {
        const job = JSON.parse(data);
        if (!this.job || !newer(this.job, job)) this.update(job);
      }
      else if (name === "deleted") this.deleted();
      else if (name === "resync") this.load();
    }

    deleted() {
      this.gone = true;
      this.stream.stop();
      main().replaceChildren(h("div", { class: "card" }, h("h1", {}, "Job deleted"),
        h("p", {}, "This job no longer exists. ", h("a", { href: "/", "data-internal": true }, "Back to the jobs"))));
    }

    update(job) {
      if (this.gone) return;
      const first = this.job === null;
      this.job = job;
      if (first) this.build();
      this.fill();
      this.refreshTiles();
      this.refreshPreview();
    }

    build() {
      const j = this.job;
      this.el = {
        title: h("h1", { class: "scene" }),
        state: h("span"),
        actions: h("div", { class: "actions" }),
        facts: h("dl", { class: "facts" }),
        error: h("div", { class: "error-box", role: "alert", hidden: true }),
        warnings: h("section", { class: "warnings" }),
        frames: h("tbody"),
        img: h("img", { class: "preview", alt: "preview of the selected frame", hidden: true }),
        grid: h("div", { class: "tilegrid", "aria-hidden": "true" }),
        placeholder: h("p", { class: "muted placeholder" }, "No tiles rendered yet."),
        frameLabel: h("span", { class: "muted" }),
      };
      const e = this.el;
      const stage = h("div", { class: "stage" }, e.img, e.grid, e.placeholder);
      stage.style.aspectRatio = `${j.width} / ${j.height}`;
      main().replaceChildren(
        h("div", { class: "toolbar" }, h("a", { href: "/", "data-internal": true, class: "back" }, "← Jobs"),
          e.title, e.state, h("code", { class: "id muted" }, j.id)),
        h("div", { id: "notice" }),
        e.actions,
        h("div", { class: "job-layout" },
          h("section", { class: "card preview-card" }, h("h2", {}, "Preview ", e.frameLabel), stage),
          h("div", { class: "side" },
            h("section", { class: "card" }, e.facts),
            e.error,
            h("section", { class: "card" }, h("h2", {}, "Frames"),
              h("table", { class: "frames" }, h("thead", {}, h("tr", {},
                ["Frame", "State", "Progress", "Products"].map((t) => h("th", { scope: "col" }, t)))), e.frames)),
            h("section", { class: "card" }, e.warnings))));
    }

    fill() {
      const j = this.job;
      const e = this.el;
      e.title.textContent = j.scene.filename;
      document.title = `${j.scene.filename} · drt`;
      e.state.replaceChildren(badge(j.state));

      // Buttons and frame rows are built once and updated in place: one rebuilt under the pointer (updates
      // arrive several times a second while a job renders) would swallow the click.
      if (!this.btn) {
        const act = (label, cls, fn) => h("button", {
          type: "button", class: cls, dataset: { action: label.toLowerCase().split(" ")[0] },
          onclick: async (ev) => {
            ev.currentTarget.disabled = true;
            try { await fn(); notice(""); } catch (err) { reportError(err); } finally { if (!this.gone) this.fill(); }
          },
        }, label);
        this.btn = {
          cancel: act("Cancel", "danger", () => this.post("cancel")),
          retry: act("Retry", "", () => this.post("retry")),
          delete: act("Delete", "ghost", () => this.remove()),
          download: act("Download EXR", "primary", () => this.downloadFrame(this.frame())),
        };
        e.actions.replaceChildren(...Object.values(this.btn));
      }
      this.btn.cancel.disabled = !ACTIVE.has(j.state);
      this.btn.retry.disabled = !(j.state === "failed" || j.state === "canceled");
      this.btn.delete.disabled = ACTIVE.has(j.state);
      this.btn.download.disabled = !(this.frame() && this.frame().exr_url);

      const s = j.settings;
      const facts = [
        ["Progress", h("div", { class: "progress" }, bar(j.progress, "job progress"), h("span", { class: "pct" }, pct(j.progress)))],
        ["Tiles", `${j.tiles_done} / ${j.tiles_total}`],
        ["Samples/s", rate(j.samples_per_second)],
        ["Resolution", `${j.width} × ${j.height}`],
        ["Samples per pixel", String(s.spp)],
        ["Priority", String(j.priority)],
        ["Submitted", clock(j.created_at)],
        ["Started", clock(j.started_at)],
        ["Elapsed", h("span", { class: "elapsed" }, duration(elapsed(j)))],
        ["Remaining", h("span", { class: "remaining" }, duration(remaining(j)))],
        ["Finished", clock(j.finished_at)],
      ];
      e.facts.replaceChildren(...facts.flatMap(([k, v]) => [h("dt", {}, k), h("dd", { dataset: { fact: k } }, v)]));

      e.error.hidden = !j.error;
      e.error.replaceChildren(j.error ? h("h2", {}, "Error") : "", j.error ? h("p", { class: "error-text" }, j.error) : "");

      const warnings = j.warnings || [];
      e.warnings.replaceChildren(h("h2", {}, `Warnings (${warnings.length})`),
        warnings.length ? h("ul", { class: "warning-list" }, warnings.map((w) => h("li", {}, w)))
          : h("p", { class: "muted" }, "The renderer had nothing to say about this scene."));

      if (e.frames.childElementCount !== j.frames.length) {
        e.frames.replaceChildren(...j.frames.map((f, i) => h("tr", { dataset: { frame: frameName(f.frame) },
          onclick: () => this.select(i) },
        h("td", {}, h("button", { type: "button", class: "link", onclick: () => this.select(i) }, frameName(f.frame))),
        h("td"), h("td"), h("td", { class: "products" }))));
      }
      j.frames.forEach((f, i) => {
        const tr = e.frames.rows[i];
        tr.className = i === this.frameIdx ? "selected" : "";
        if (tr.dataset.key === `${f.state}:${f.progress}`) return;
        tr.dataset.key = `${f.state}:${f.progress}`;
        tr.cells[1].textContent = f.state;
        tr.cells[2].replaceChildren(h("div", { class: "progress" }, bar(f.progress, `frame ${frameName(f.frame)}`),
          h("span", { class: "pct" }, pct(f.progress))));
        tr.cells[3].replaceChildren(...this.productLinks(f));
      });
      e.frameLabel.textContent = j.frames.length > 1 ? `frame ${frameName(this.frame().frame)}` : "";
    }

    frame() { return this.job.frames[Math.min(this.frameIdx, this.job.frames.length - 1)]; }

    select(i) {
      this.frameIdx = i;
      this.previewKey = null;
      this.fill();
      this.drawTiles();
      this.refreshPreview();
    }

    async post(what) {
      this.update(await (await api(`/v1/jobs/${encodeURIComponent(this.id)}/${what}`, { method: "POST" })).json());
    }

    async remove() {
      if (!window.confirm(`Delete job ${this.job.scene.filename} and its files?`)) { this.fill(); return; }
      await api(`/v1/jobs/${encodeURIComponent(this.id)}`, { method: "DELETE" });
      this.deleted();
    }

    downloadFrame(f) {
      return download(f.exr_url, `${this.id}_${frameName(f.frame)}.exr`);
    }

    // A done frame's products by name (its RenderProducts' productNames), each a download of its EXR; a frame
    // written before products were listed has its one EXR.
    productLinks(f) {
      const link = (label, url, filename, name) => h("button", {
        type: "button", class: "link", title: label, dataset: name === undefined ? {} : { product: name },
        onclick: (ev) => { ev.stopPropagation(); download(url, filename).catch(reportError); },
      }, label);
      if (f.products && f.products.length) {
        return f.products.map((p) => link(p.name, p.url, p.name.split("/").pop(), p.name));
      }
      return f.exr_url ? [link("EXR", f.exr_url, `${this.id}_${frameName(f.frame)}.exr`)] : [];
    }

    // The preview is fetched again when the selected frame's progress or state changed, at most once a second.
    async refreshPreview() {
      const f = this.frame();
      const key = `${f.state}:${f.progress}`;
      if (this.previewBusy || key === this.previewKey || f.state === "pending") return;
      this.previewBusy = true;
      try {
        const url = await blobURL(f.preview_url);
        const img = this.el.img;
        await new Promise((resolve) => { img.onload = resolve; img.onerror = resolve; img.src = url; });
        if (this.previewURL) URL.revokeObjectURL(this.previewURL);
        this.previewURL = url;
        img.hidden = false;
        this.el.placeholder.hidden = true;
        this.previewKey = key;
      } catch (e) { reportError(e); } finally {
        await sleep(1000);
        this.previewBusy = false;
      }
      if (!this.gone && `${this.frame().state}:${this.frame().progress}` !== this.previewKey) this.refreshPreview();
    }

    async refreshTiles() {
      if (this.tilesBusy) return;
      this.tilesBusy = true;
      try {
        this.tiles = await getJSON(`/v1/jobs/${encodeURIComponent(this.id)}/tiles`);
        this.drawTiles();
      } catch (e) { reportError(e); } finally {
        this.tilesBusy = false;
      }
    }

    drawTiles() {
      const t = this.tiles;
      if (!t) return;
      const fr = t.frames[Math.min(this.frameIdx, t.frames.length - 1)];
      const done = new Set(fr.done);
      const busy = new Set(fr.rendering);
      const grid = this.el.grid;
      const n = t.columns * t.rows;
      if (grid.childElementCount !== n) {
        grid.style.gridTemplateColumns = `repeat(${t.columns}, 1fr)`;
        grid.style.gridTemplateRows = `repeat(${t.rows}, 1fr)`;
        grid.replaceChildren(...Array.from({ length: n }, () => h("div", { class: "tile" })));
      }
      [...grid.children].forEach((cell, i) => {
        cell.dataset.state = done.has(i) ? "done" : busy.has(i) ? "rendering" : "pending";
      });
      grid.dataset.done = String(done.size);
    }

    tick() {
      if (!this.job || this.gone) return;
      const j = this.job;
      if (j.state === "running") {
        this.el.facts.querySelector(".elapsed").textContent = duration(elapsed(j));
        this.el.facts.querySelector(".remaining").textContent = duration(remaining(j));
        this.refreshTiles(); // which tiles workers hold changes without a database write
      }
    }
  }

  // --------------------------------------------------------------------------------------------------- farm
  class FarmView {
    constructor() {
      this.body = h("div", { class: "farm" });
      main().replaceChildren(h("div", { class: "toolbar" }, h("h1", {}, "Farm")), h("div", { id: "notice" }), this.body);
      this.load();
      this.timer = setInterval(() => this.load(), 2000);
      setLive("polling");
    }

    dispose() { clearInterval(this.timer); }

    async load() {
      try {
        this.render(await getJSON("/v1/farm"));
        notice("");
      } catch (e) { reportError(e); }
    }

    render(f) {
      const threads = f.workers.reduce((n, w) => n + w.nthreads, 0);
      let dash = null;
      try {
        const u = f.dashboard_url ? new URL(f.dashboard_url, location.href) : null;
        if (u && (u.protocol === "http:" || u.protocol === "https:")) {
          dash = h("a", { href: u.href, target: "_blank", rel: "noopener noreferrer" }, "Dask dashboard ↗");
        }
      } catch (_) { /* not a URL: no link */ }
      const summary = h("dl", { class: "facts card" },
        ...[["Workers", String(f.workers.length)], ["Threads", String(threads)],
          ["Tiles/s (1 min)", f.tiles_per_second.toFixed(2)], ["Tasks in flight", String(f.tiles_in_flight)],
          ["Tiles waiting", String(f.tiles_pending)], ["Scheduler", f.scheduler || "unreachable"],
          ["Dashboard", dash || h("span", { class: "muted" }, "not running")]]
          .flatMap(([k, v]) => [h("dt", {}, k), h("dd", {}, v)]));
      const cards = f.workers.map((w) => h("section", { class: "card worker", dataset: { worker: w.name } },
        h("h2", {}, w.name, " ", h("span", { class: "muted" }, w.host)),
        h("p", { class: "muted" }, `${w.nthreads} thread(s) · CPU ${w.cpu === null ? "–" : w.cpu.toFixed(0) + "%"} · `
          + `memory ${bytes(w.memory)} of ${bytes(w.memory_limit)}`),
        w.tasks.length ? h("ul", { class: "tasks" }, w.tasks.map((t) => h("li", {},
          t.kind !== "tile" ? "assembling the EXR"
            : (t.tiles || []).length > 4 ? `${t.tiles.length} tiles from ${t.tiles[0]}`
            : (t.tiles || []).length > 1 ? `tiles ${t.tiles.join(", ")}`
            : `tile ${t.tile}`,
          ` · frame ${t.frame === null ? "#" + t.frame_index : frameName(t.frame)} · job `,
          h("a", { href: `/jobs/${encodeURIComponent(t.job_id)}`, "data-internal": true }, t.job_id.slice(0, 8)))))
          : h("p", { class: "muted" }, "idle"),
        w.other_tasks ? h("p", { class: "muted" }, `${w.other_tasks} other task(s)`) : ""));
      this.body.replaceChildren(summary,
        cards.length ? h("div", { class: "workers" }, cards) : h("p", { class: "muted" }, "No workers connected."));
    }
  }

  // ------------------------------------------------------------------------------------------ login, routing
  let view = null;

  function showLogin(message) {
    if (view) { view.dispose(); view = null; }
    setLive("off");
    main().replaceChildren();
    $("login").hidden = false;
    $("logout").hidden = true;
    $("login-error").textContent = message || "";
    $("token").focus();
  }

  async function signIn(ev) {
    ev.preventDefault();
    const token = $("token").value.trim();
    if (!token) { $("login-error").textContent = "Enter the token."; return; }
    sessionStorage.setItem(TOKEN_KEY, token);
    try {
      await api("/v1/jobs?limit=1");
    } catch (e) {
      sessionStorage.removeItem(TOKEN_KEY);
      if (!(e instanceof AuthError)) $("login-error").textContent = e.message;
      else $("login-error").textContent = "The token was not accepted.";
      return;
    }
    $("token").value = "";
    route();
  }

  function route() {
    if (view) view.dispose();
    view = null;
    $("login").hidden = true;
    $("logout").hidden = !sessionStorage.getItem(TOKEN_KEY);
    const path = location.pathname;
    const m = path.match(/^\/jobs\/([^/]+)\/?$/);
    for (const a of document.querySelectorAll("[data-nav]")) {
      a.setAttribute("aria-current", String((a.dataset.nav === "farm") === (path === "/farm")));
    }
    document.title = "drt monitor";
    if (m) view = new JobView(decodeURIComponent(m[1]));
    else if (path === "/farm") view = new FarmView();
    else view = new JobsView(new URLSearchParams(location.search));
  }

  document.addEventListener("click", (ev) => {
    const a = ev.target.closest && ev.target.closest("a[data-internal]");
    if (!a || ev.ctrlKey || ev.metaKey || ev.shiftKey || ev.button !== 0) return;
    ev.preventDefault();
    history.pushState(null, "", a.getAttribute("href"));
    route();
  });
  window.addEventListener("popstate", route);
  document.addEventListener("DOMContentLoaded", () => {
    $("login-form").addEventListener("submit", signIn);
    $("logout").addEventListener("click", () => { sessionStorage.removeItem(TOKEN_KEY); showLogin(""); });
    route();
  });
})();
