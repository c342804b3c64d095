// drt job monitor: jobs, one job, the farm. Reads only the public HTTP API (/v1). This is the entry point: the
// token login, the router (which view a URL shows) and in-page navigation; each view lives in its own module.
//
// Safety: every piece of text from the server (scene names, errors, the renderer's warnings) goes into the page
// through textContent (the h() helper in dom.js); nothing is ever parsed as HTML. The page's CSP forbids inline
// script.

import { AuthError, TOKEN_KEY, api, onUnauthorized } from "./api.js";
import { $, main } from "./dom.js";
import { FarmView } from "./farm-view.js";
import { JobView } from "./job-view.js";
import { JobsView } from "./jobs-view.js";
import { setLive } from "./stream.js";

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
onUnauthorized(showLogin);

// A module script runs once the document is parsed (it is deferred), before DOMContentLoaded.
function start() {
  $("login-form").addEventListener("submit", signIn);
  $("logout").addEventListener("click", () => { sessionStorage.removeItem(TOKEN_KEY); showLogin(""); });
  route();
}
if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start);
else start();
