// The jobs list (/ and /?state=...): a table of jobs filtered by state, kept live from /v1/events (or polled),
// with rows updated in place and elapsed/remaining times ticking each second.

import { getJSON } from "./api.js";
import { badge, bar, h, main } from "./dom.js";
import { STATES, clock, duration, elapsed, newer, pct, rate, remaining } from "./format.js";
import { notice, reportError } from "./notice.js";
import { Stream } from "./stream.js";

export class JobsView {
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
