// One job (/jobs/{id}): its preview and tile grid, facts, error, warnings, frames with their products, and the
// Cancel/Retry/Delete/Download actions, kept live from the job's event stream (or polled).

import { ApiError, api, blobURL, download, getJSON } from "./api.js";
import { badge, bar, h, main, sleep } from "./dom.js";
import { ACTIVE, clock, duration, elapsed, frameName, newer, pct, rate, remaining } from "./format.js";
import { notice, reportError } from "./notice.js";
import { Stream } from "./stream.js";

export class JobView {
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
