/**
 * History-API router: every view has its own URL and a reload lands on the same view.
 * A view module exports `title` and `mount(root, ctx)`; mount may return a cleanup function.
 * ctx = {params, query, signal, navigate}; `signal` aborts when the view is left.
 */
import { MARK, SEL } from "./constants.js";

export class Router {
  /** @param {{path: RegExp, keys?: string[], view?: object, redirect?: string}[]} routes */
  constructor(routes, root, { onChange } = {}) {
    this.routes = routes;
    this.root = root;
    this.onChange = onChange;
    this.cleanup = null;
    this.controller = null;
    this.current = null;
    this.settled = false; // a view has finished mounting
  }

  start() {
    window.addEventListener("popstate", () => this.render({ focus: true }));
    document.addEventListener("click", (event) => this.intercept(event));
    return this.render({ focus: false });
  }

  /** Follow same-origin links to app routes without a page load. */
  intercept(event) {
    if (event.defaultPrevented || event.button !== 0) return;
    if (event.metaKey || event.ctrlKey || event.shiftKey || event.altKey) return;
    const a = event.target.closest?.(SEL.link);
    if (!a || a.target || a.hasAttribute("download")) return;
    const dest = new URL(a.href, window.location.href);
    if (
      dest.origin !== window.location.origin ||
      dest.pathname.startsWith("/api/") ||
      dest.pathname.startsWith("/static/")
    )
      return;
    if (!this.match(dest.pathname)) return;
    event.preventDefault();
    this.navigate(dest.pathname + dest.search);
  }

  match(pathname) {
    for (const route of this.routes) {
      const m = route.path.exec(pathname);
      if (m) {
        const params = Object.fromEntries(
          (route.keys ?? []).map((k, i) => [k, decodeURIComponent(m[i + 1])]),
        );
        return { route, params };
      }
    }
    return null;
  }

  /**
   * Go to `to` (path + query). replace=true rewrites the current history entry. The new
   * page's heading takes the focus (`focus`), except after a redirect while the first page
   * is still loading, which is part of that load.
   */
  navigate(to, { replace = false, focus } = {}) {
    const current = window.location.pathname + window.location.search;
    if (to !== current) {
      if (replace) history.replaceState(null, "", to);
      else history.pushState(null, "", to);
    }
    return this.render({ focus: focus ?? (this.settled || !replace) });
  }

  /** Update the query string of the current view without re-mounting it. */
  setQuery(query, { replace = true } = {}) {
    const params = new URLSearchParams();
    for (const [k, v] of Object.entries(query)) {
      if (v !== undefined && v !== null && v !== "") params.set(k, v);
    }
    const search = params.toString();
    const to =
      window.location.pathname +
      (search ? `?${search.replaceAll("%2C", ",").replaceAll("%3A", ":")}` : "");
    if (replace) history.replaceState(null, "", to);
    else history.pushState(null, "", to);
  }

  /** Mount the view of the current URL; `focus`: move the focus to its heading after. */
  async render({ focus = true } = {}) {
    const { pathname, search } = window.location;
    const found = this.match(pathname);
    if (found?.route.redirect) return this.navigate(found.route.redirect, { replace: true, focus });

    this.controller?.abort();
    try {
      this.cleanup?.();
    } catch (err) {
      console.warn("view cleanup failed", err);
    }
    this.cleanup = null;
    this.controller = new AbortController();
    this.root.replaceChildren();

    const view = found?.route.view ?? notFound;
    this.current = { view, params: found?.params ?? {}, path: pathname };
    document.title = `${view.title ?? "mapwise"} · mapwise`;
    this.onChange?.(found?.route.section ?? null, this.current);
    const ctx = {
      params: found?.params ?? {},
      query: new URLSearchParams(search),
      signal: this.controller.signal,
      navigate: (to, opts) => this.navigate(to, opts),
      setQuery: (q, opts) => this.setQuery(q, opts),
    };
    try {
      const cleanup = await view.mount(this.root, ctx);
      if (ctx.signal.aborted) cleanup?.();
      else this.cleanup = cleanup ?? null;
    } catch (err) {
      if (err?.name === "AbortError") return;
      console.warn(err);
      this.root.replaceChildren(errorPanel(err));
    }
    if (ctx.signal.aborted) return;
    this.settled = true;
    performance.mark(MARK.viewMounted, { detail: { path: pathname } });
    // Move focus to the new page's heading after in-app navigation (not on first load,
    // where the browser's own start of the page is right for keyboard and screen readers),
    // also when the user navigated before the first page had finished loading.
    if (focus) {
      const heading = this.root.querySelector(SEL.pageTitle) || document.querySelector(SEL.main);
      heading?.focus({ preventScroll: true });
    }
  }
}

/** A view that could not load: a heading (focused like any page's), why, and a way on. */
function errorPanel(err) {
  const missing = err?.status === 404;
  const h1 = document.createElement("h1");
  h1.textContent = missing ? "Not found" : "Something went wrong";
  h1.tabIndex = -1;
  h1.dataset.pageTitle = "";
  const p = document.createElement("div");
  p.className = "banner error";
  p.setAttribute("role", "alert");
  p.textContent = missing ? `Not found: ${err.message}` : `${err?.message ?? err}`;
  const on = document.createElement("p");
  on.innerHTML = 'Go to the <a href="/compare">runs</a> or the <a href="/datasets">datasets</a>.';
  const panel = document.createDocumentFragment();
  panel.append(h1, p, on);
  return panel;
}

const notFound = {
  title: "Not found",
  mount(root) {
    const h1 = document.createElement("h1");
    h1.textContent = "Page not found";
    h1.tabIndex = -1;
    h1.dataset.pageTitle = "";
    const p = document.createElement("p");
    p.innerHTML = 'Nothing lives at this address. Go to <a href="/datasets">Datasets</a>.';
    root.append(h1, p);
  },
};
