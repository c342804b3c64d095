// Formatting helpers and the job facts they show: durations, rates, sizes, clock times, percentages and frame
// names as the pages print them; a job's states, its elapsed and remaining time, and which of two versions of a
// job is newer.

export const STATES = ["queued", "running", "succeeded", "failed", "canceled"];
export const ACTIVE = new Set(["queued", "running"]);

export function duration(seconds) {
  if (seconds === null || seconds === undefined || !isFinite(seconds) || seconds < 0) return "–";
  const s = Math.round(seconds);
  if (s < 60) return `${s}s`;
  const m = Math.floor(s / 60);
  if (m < 60) return `${m}m ${String(s % 60).padStart(2, "0")}s`;
  return `${Math.floor(m / 60)}h ${String(m % 60).padStart(2, "0")}m`;
}

export function rate(x) {
  if (!x) return "–";
  for (const [div, unit] of [[1e9, "G"], [1e6, "M"], [1e3, "k"]]) {
    if (x >= div) return `${(x / div).toFixed(2)} ${unit}`;
  }
  return x.toFixed(0);
}

export function bytes(n) {
  if (n === null || n === undefined) return "–";
  const units = ["B", "KiB", "MiB", "GiB", "TiB"];
  let i = 0;
  while (n >= 1024 && i < units.length - 1) { n /= 1024; i += 1; }
  return `${n.toFixed(i ? 1 : 0)} ${units[i]}`;
}

const when = (iso) => (iso ? new Date(iso) : null);

// Whether job version a is strictly newer than b (every change stamps updated_at; a finished job is final).
export function newer(a, b) {
  const ta = Date.parse(a.updated_at), tb = Date.parse(b.updated_at);
  if (ta !== tb) return ta > tb;
  return !ACTIVE.has(a.state) && ACTIVE.has(b.state);
}

export function clock(iso) {
  const d = when(iso);
  if (!d) return "–";
  const today = new Date().toDateString() === d.toDateString();
  return today ? d.toLocaleTimeString() : d.toLocaleString();
}

export function elapsed(job) {
  const start = when(job.started_at);
  if (!start) return null;
  const end = when(job.finished_at) || new Date();
  return (end - start) / 1000;
}

export function remaining(job) {
  if (job.state !== "running" || !(job.progress > 0)) return null;
  const e = elapsed(job);
  return e === null ? null : (e * (1 - job.progress)) / job.progress;
}

export const pct = (x) => `${Math.floor(100 * (x || 0))}%`;
export const frameName = (t) => String(t); // JSON numbers: 12.0 arrives as 12, as the API names frames
