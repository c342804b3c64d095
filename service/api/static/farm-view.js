// The farm (/farm): the cluster's summary and each Dask worker with the tiles it holds, polled every 2 s.

import { getJSON } from "./api.js";
import { h, main } from "./dom.js";
import { bytes, frameName } from "./format.js";
import { reportError, notice } from "./notice.js";
import { setLive } from "./stream.js";

export class FarmView {
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
