/**
 * REST client for the mapwise API. Every failure becomes an ApiError carrying the API's
 * {"error": {code, message, field}}; showError() puts the message next to the field concerned.
 */
import { SEL, SELECT, STORAGE } from "./constants.js";
import { h } from "./dom.js";

export class ApiError extends Error {
  constructor(status, { code = "error", message = "Request failed", field = null } = {}) {
    super(message);
    this.name = "ApiError";
    this.status = status;
    this.code = code;
    this.field = field;
  }
}

let unauthorizedHandler = null;

/** The shell registers what to do on 401 (ask for a token). */
export function onUnauthorized(handler) {
  unauthorizedHandler = handler;
}

export function token() {
  return localStorage.getItem(STORAGE.token) || "";
}

export function setToken(value) {
  if (value) localStorage.setItem(STORAGE.token, value);
  else localStorage.removeItem(STORAGE.token);
}

function authHeaders() {
  const t = token();
  return t ? { Authorization: `Bearer ${t}` } : {};
}

export function url(path, query) {
  const u = new URL(path, window.location.origin);
  for (const [k, v] of Object.entries(query ?? {})) {
    if (v !== undefined && v !== null && v !== "") u.searchParams.set(k, v);
  }
  return u.pathname + u.search;
}

async function errorFrom(response) {
  let detail = {};
  try {
    const body = await response.json();
    detail = body?.error ?? { message: typeof body?.detail === "string" ? body.detail : undefined };
  } catch {
    detail = {};
  }
  if (!detail.message) detail.message = `${response.status} ${response.statusText || "error"}`;
  if (response.status === 401 && unauthorizedHandler) unauthorizedHandler();
  return new ApiError(response.status, detail);
}

/** fetch() with JSON in and out; resolves to the parsed body (null for 204). */
export async function request(method, path, { body, query, signal, headers } = {}) {
  const init = {
    method,
    signal,
    headers: { Accept: "application/json", ...authHeaders(), ...headers },
  };
  if (body instanceof FormData) init.body = body;
  else if (body !== undefined) {
    init.body = JSON.stringify(body);
    init.headers["Content-Type"] = "application/json";
  }
  let response;
  try {
    response = await fetch(url(path, query), init);
  } catch (err) {
    if (err.name === "AbortError") throw err;
    throw new ApiError(0, { code: "network", message: "The server cannot be reached." });
  }
  if (!response.ok) throw await errorFrom(response);
  if (response.status === 204) return null;
  const type = response.headers.get("Content-Type") || "";
  return type.includes("json") ? response.json() : response.text();
}

export const api = {
  get: (path, opts) => request("GET", path, opts),
  post: (path, body, opts) => request("POST", path, { ...opts, body }),
  patch: (path, body, opts) => request("PATCH", path, { ...opts, body }),
  del: (path, opts) => request("DELETE", path, opts),

  /** Every page of a paginated list. */
  async all(path, { query, signal, limit = 200 } = {}) {
    const items = [];
    for (let offset = 0; ; offset += limit) {
      const page = await request("GET", path, { query: { ...query, limit, offset }, signal });
      const batch = Array.isArray(page) ? page : (page.items ?? []);
      items.push(...batch);
      if (Array.isArray(page) || batch.length < limit || items.length >= (page.total ?? 0)) break;
    }
    return items;
  },

  /**
   * Multipart upload with progress (fetch cannot report upload progress, XHR can).
   * onProgress(fraction) is called as bytes leave the browser.
   */
  upload(path, formData, { onProgress, signal } = {}) {
    return new Promise((resolve, reject) => {
      const xhr = new XMLHttpRequest();
      xhr.open("POST", url(path));
      xhr.setRequestHeader("Accept", "application/json");
      for (const [k, v] of Object.entries(authHeaders())) xhr.setRequestHeader(k, v);
      xhr.upload.onprogress = (e) => {
        if (e.lengthComputable && onProgress) onProgress(e.loaded / e.total);
      };
      xhr.onload = () => {
        let body = null;
        try {
          body = xhr.responseText ? JSON.parse(xhr.responseText) : null;
        } catch {
          body = null;
        }
        if (xhr.status >= 200 && xhr.status < 300) resolve(body);
        else {
          if (xhr.status === 401 && unauthorizedHandler) unauthorizedHandler();
          reject(
            new ApiError(xhr.status, body?.error ?? { message: `${xhr.status} ${xhr.statusText}` }),
          );
        }
      };
      xhr.onerror = () =>
        reject(
          new ApiError(0, {
            code: "network",
            message: "Upload failed: the server cannot be reached.",
          }),
        );
      xhr.onabort = () => reject(new DOMException("Upload cancelled", "AbortError"));
      signal?.addEventListener("abort", () => xhr.abort());
      xhr.send(formData);
    });
  },

  /**
   * POST `body` to a route answering newline-delimited JSON (application/x-ndjson): calls
   * onLine(doc) for each line as it arrives and resolves to the last one. A line
   * {error, status} (the route failed after its stream began) rejects as an ApiError.
   */
  async stream(path, body, { onLine, signal } = {}) {
    const response = await fetch(url(path), {
      method: "POST",
      signal,
      headers: {
        Accept: "application/x-ndjson",
        "Content-Type": "application/json",
        ...authHeaders(),
      },
      body: JSON.stringify(body),
    }).catch((err) => {
      if (err.name === "AbortError") throw err;
      throw new ApiError(0, { code: "network", message: "The server cannot be reached." });
    });
    if (!response.ok) throw await errorFrom(response);
    const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
    let buffered = "";
    let last = null;
    for (;;) {
      const { value, done } = await reader.read();
      if (value) buffered += value;
      const lines = buffered.split("\n");
      buffered = done ? "" : lines.pop();
      for (const line of lines) {
        if (!line.trim()) continue;
        last = JSON.parse(line);
        if (last.error) throw new ApiError(last.status ?? 500, last.error);
        onLine?.(last);
      }
      if (done) return last;
    }
  },

  /** Fetch a file (with auth) and hand it to the browser as a download. */
  async download(path, query, fallbackName = "download") {
    const response = await fetch(url(path, query), { headers: authHeaders() });
    if (!response.ok) throw await errorFrom(response);
    const blob = await response.blob();
    const disposition = response.headers.get("Content-Disposition") || "";
    const match = /filename\*?=(?:UTF-8'')?"?([^";]+)"?/i.exec(disposition);
    const name = match ? decodeURIComponent(match[1]) : fallbackName;
    const href = URL.createObjectURL(blob);
    const a = h("a", { href, download: name, hidden: true });
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(href), 30000);
    return name;
  },
};

/* ---------- cached catalogs ---------- */
const cache = new Map();

function cached(key, load) {
  if (!cache.has(key)) {
    const promise = load().catch((err) => {
      cache.delete(key);
      throw err;
    });
    cache.set(key, promise);
  }
  return cache.get(key);
}

export function estimators() {
  return cached("estimators", async () => {
    const body = await api.get("/api/estimators");
    return Array.isArray(body) ? body : body.items;
  });
}

export function scenarios() {
  return cached("scenarios", async () => {
    const body = await api.get("/api/scenarios");
    return Array.isArray(body) ? body : body.items;
  });
}

/* ---------- errors next to the fields they concern ---------- */

/** Remove every error message shown inside `container`. */
export function clearErrors(container) {
  for (const el of container.querySelectorAll(SEL.fieldError)) el.remove();
  for (const el of container.querySelectorAll(SEL.invalid)) {
    el.removeAttribute("aria-invalid");
    const ids = (el.getAttribute("aria-describedby") || "")
      .split(" ")
      .filter((id) => !id.startsWith("err-"));
    if (ids.length) el.setAttribute("aria-describedby", ids.join(" "));
    else el.removeAttribute("aria-describedby");
  }
  for (const el of container.querySelectorAll(SEL.formError)) {
    el.hidden = true;
    el.textContent = "";
  }
}

/** The control that names `field` ("config.sigma_w" → [name="config.sigma_w"]), trying parents too. */
function controlFor(container, field) {
  if (!field) return null;
  const parts = String(field)
    .split(/[.[\]]+/)
    .filter(Boolean);
  for (let n = parts.length; n > 0; n -= 1) {
    const key = parts.slice(0, n).join(".");
    const el =
      container.querySelector(SELECT.dataField(key)) || container.querySelector(SELECT.name(key));
    if (el) return el;
  }
  return null;
}

/**
 * Show an error where it belongs: next to the control for err.field when there is one,
 * else in the container's [data-form-error] banner (or as a toast). Returns the element used.
 */
export function showError(container, err, { prefix = "" } = {}) {
  if (err?.name === "AbortError") return null;
  const message = err?.message || String(err);
  const control =
    controlFor(container, err?.field ? `${prefix}${err.field}` : null) ||
    controlFor(container, err?.field);
  if (control) {
    const id = `err-${Math.random().toString(36).slice(2, 9)}`;
    const note = h("div", { class: "field-error", id, role: "alert" }, message);
    const host = control.closest(SEL.field) || control.parentElement;
    host.append(note);
    control.setAttribute("aria-invalid", "true");
    const described = control.getAttribute("aria-describedby");
    control.setAttribute("aria-describedby", described ? `${described} ${id}` : id);
    // The field and its message mid-screen: a sticky action bar may cover the page's bottom.
    if (typeof control.focus === "function") control.focus({ preventScroll: true });
    host.scrollIntoView({ block: "center" });
    return note;
  }
  const banner = container.querySelector(SEL.formError);
  const text = err?.field ? `${err.field}: ${message}` : message;
  if (banner) {
    banner.textContent = text;
    banner.hidden = false;
    banner.setAttribute("role", "alert");
    return banner;
  }
  const host = document.querySelector(SEL.toasts);
  host?.append(h("div", { class: "toast error" }, text));
  setTimeout(() => host?.lastChild?.remove(), 6000);
  return null;
}

/** Build the WebSocket URL of a path (ws: or wss:), with the token when there is one. */
export function wsUrl(path) {
  const u = new URL(path, window.location.origin);
  u.protocol = u.protocol === "https:" ? "wss:" : "ws:";
  const t = token();
  if (t) u.searchParams.set("token", t);
  return u.toString();
}
