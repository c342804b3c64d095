// DOM and page helpers for every view: h() builds elements (text from the server only ever becomes text nodes,
// never HTML), $() and main() find the page's fixed elements, bar() and badge() are the progress bar and state
// badge, sleep() waits.

export function h(tag, attrs, ...children) {
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

export const $ = (id) => document.getElementById(id);
export const main = () => $("main");
export const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

export function bar(fraction, label) {
  const pct = Math.max(0, Math.min(100, 100 * (fraction || 0)));
  const fill = h("div", { class: "fill" });
  fill.style.width = pct.toFixed(1) + "%"; // CSSOM, allowed by the CSP (unlike style attributes in markup)
  return h("div", { class: "bar", role: "progressbar", "aria-valuemin": 0, "aria-valuemax": 100,
    "aria-valuenow": Math.round(pct), "aria-label": label || "progress" }, fill);
}

export function badge(state) {
  return h("span", { class: "badge", dataset: { state } }, state);
}
