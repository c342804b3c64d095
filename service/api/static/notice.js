// The page's notice line: an error (or other message) shown above the current view; authentication failures are
// not shown there, the login form answers them.

import { AuthError } from "./api.js";
import { $, h } from "./dom.js";

export function notice(text, kind) {
  const box = $("notice");
  if (!box) return;
  box.replaceChildren(text ? h("p", { class: kind || "error", role: "alert" }, text) : "");
}

export function reportError(e) {
  if (e instanceof AuthError) return;
  notice(e && e.message ? e.message : String(e));
}
