/**
 * What the caller may do (GET /api/me): "read", "run" (upload, start, cancel, resume, label)
 * and "admin" (delete, base maps). The shell writes them on <html data-scopes="…">; CSS hides
 * every element whose data-needs names a scope the caller lacks. The server enforces the same
 * rule (403 insufficient_scope): hiding only spares the user a button that cannot work.
 */
import { api } from "./api.js";

export const SCOPE = Object.freeze({ read: "read", run: "run", admin: "admin" });

/** Mark an element as needing a scope; returns it (for use inside h(...) trees). */
export function needs(scope, el) {
  el.dataset.needs = scope;
  return el;
}

/** Ask the server once per page; until it answers nothing is hidden. */
export async function loadScopes() {
  try {
    const me = await api.get("/api/me");
    document.documentElement.dataset.scopes = me.scopes.join(" ");
  } catch {
    /* 401: the token prompt follows; offline: the health indicator says so */
  }
}
