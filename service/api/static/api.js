// The API client: every request to /v1 goes through api(), which sends the tab's bearer token, turns a 401 into
// the login form (through the handler the entry point registers) and other failures into an ApiError. Images and
// files behind the token are fetched here and handed out as blob: URLs.

import { h } from "./dom.js";

export const TOKEN_KEY = "drt.token";

// What a 401 does (the entry point shows the login form): api.js cannot import the entry point, which imports it.
let unauthorized = () => {};
export function onUnauthorized(handler) { unauthorized = handler; }

export class AuthError extends Error {}
export class ApiError extends Error {
  constructor(status, detail) { super(detail); this.status = status; }
}

function authHeaders(extra) {
  const headers = new Headers(extra || {});
  const token = sessionStorage.getItem(TOKEN_KEY);
  if (token) headers.set("Authorization", `Bearer ${token}`);
  return headers;
}

export async function api(path, opts = {}) {
  const r = await fetch(path, { ...opts, headers: authHeaders(opts.headers), cache: "no-store" });
  if (r.status === 401) {
    unauthorized(sessionStorage.getItem(TOKEN_KEY) ? "The token was not accepted." : "");
    throw new AuthError("unauthorized");
  }
  if (!r.ok) {
    let detail = r.statusText;
    try { detail = (await r.json()).detail || detail; } catch (_) { /* not JSON */ }
    throw new ApiError(r.status, `${r.status}: ${detail}`);
  }
  return r;
}

export const getJSON = async (path) => (await api(path)).json();

// An image or file behind the token: fetched with the header, shown through a blob: URL.
export async function blobURL(path) {
  const r = await api(path);
  return URL.createObjectURL(await r.blob());
}

export async function download(path, filename) {
  const url = await blobURL(path);
  const a = h("a", { href: url, download: filename });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 60000);
}
