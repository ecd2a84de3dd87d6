/** Small DOM and formatting helpers; never builds HTML from strings, so data stays text. */
import { SEL } from "./constants.js";

/**
 * Create an element: h("button", {class: "primary", onclick}, "Start").
 * Attributes starting with "on" become listeners; `dataset`/`style` objects are merged;
 * `false`/`null` attributes are skipped; children may be nested arrays, strings or nodes.
 */
export function h(tag, attrs = {}, ...children) {
  const el = tag.includes(":")
    ? document.createElementNS("http://www.w3.org/2000/svg", tag.split(":")[1])
    : document.createElement(tag);
  for (const [key, value] of Object.entries(attrs ?? {})) {
    if (value === false || value === null || value === undefined) continue;
    if (key.startsWith("on") && typeof value === "function") {
      el.addEventListener(key.slice(2), value);
    } else if (key === "dataset") {
      Object.assign(el.dataset, value);
    } else if (key === "style" && typeof value === "object") {
      Object.assign(el.style, value);
    } else if (key === "value" && "value" in el) {
      el.value = value;
    } else if (
      key === "checked" ||
      key === "selected" ||
      key === "disabled" ||
      key === "indeterminate"
    ) {
      el[key] = Boolean(value);
    } else {
      el.setAttribute(key, value === true ? "" : String(value));
    }
  }
  append(el, children);
  return el;
}

function append(el, children) {
  for (const child of children) {
    if (child === null || child === undefined || child === false) continue;
    if (Array.isArray(child)) append(el, child);
    else el.append(child instanceof Node ? child : String(child));
  }
}

/** Replace el's children; like h(), skips null/false and flattens arrays. */
export function fill(el, ...children) {
  el.replaceChildren();
  append(el, children);
  return el;
}

export function clear(el) {
  el.replaceChildren();
  return el;
}

export function qs(sel, root = document) {
  return root.querySelector(sel);
}

export function qsa(sel, root = document) {
  return [...root.querySelectorAll(sel)];
}

/** An inline SVG icon from a path list (stroke icons, 24×24). */
export function icon(paths, { filled = false } = {}) {
  const svg = h("svg:svg", {
    viewBox: "0 0 24 24",
    "aria-hidden": "true",
    class: filled ? "filled" : null,
  });
  for (const d of [].concat(paths)) svg.append(h("svg:path", { d }));
  return svg;
}

export const ICONS = Object.freeze({
  play: "M7 4.5v15l13-7.5z",
  pause: ["M7 5h3.5v14H7z", "M13.5 5H17v14h-3.5z"],
  stop: "M6 6h12v12H6z",
  resume: ["M4 12a8 8 0 1 0 2.3-5.6", "M4 4v4.5h4.5"],
  download: ["M12 4v11", "M7 10.5l5 5 5-5", "M5 20h14"],
  upload: ["M12 16V5", "M7 9.5l5-5 5 5", "M5 20h14"],
  trash: ["M4 7h16", "M9 7V4.5h6V7", "M6.5 7l1 13h9l1-13"],
  plus: ["M12 5v14", "M5 12h14"],
  x: ["M6 6l12 12", "M18 6L6 18"],
  compare: ["M4 20V10", "M10 20V4", "M16 20v-7", "M22 20H2"],
  versions: ["M6 3.5v17", "M6 8c6 0 10 1 12 4", "M6 16c6 0 10-1 12-4"],
  cube: ["M12 3l8 4.5v9L12 21l-8-4.5v-9z", "M12 12l8-4.5", "M12 12v9", "M12 12L4 7.5"],
  grid: ["M4 4h16v16H4z", "M4 10h16", "M4 15h16", "M10 4v16", "M15 4v16"],
  flask: ["M9 3h6", "M10 3v6L4.5 18.5A1.7 1.7 0 0 0 6 21h12a1.7 1.7 0 0 0 1.5-2.5L14 9V3"],
  tag: ["M3.5 12.5l8-8H20v8.5l-8 8z", "M16 8h.01"],
  chevron: "M6 9l6 6 6-6",
});

/** A number for humans: 4 significant digits, thousands grouped, no "-0". */
export function fmt(value, digits = 4) {
  if (value === null || value === undefined || Number.isNaN(value)) return "–";
  if (typeof value !== "number") return String(value);
  if (value === 0) return "0";
  const abs = Math.abs(value);
  if (abs >= 1e6 || abs < 1e-3)
    return value.toExponential(Math.max(0, digits - 2)).replace("e+", "e");
  const decimals = Math.max(0, digits - 1 - Math.floor(Math.log10(abs)));
  return value.toLocaleString("en-US", {
    maximumFractionDigits: decimals,
    minimumFractionDigits: 0,
  });
}

export function fmtInt(value) {
  return value === null || value === undefined ? "–" : Math.round(value).toLocaleString("en-US");
}

export function fmtDuration(seconds) {
  if (seconds === null || seconds === undefined || !Number.isFinite(seconds)) return "–";
  if (seconds < 60) return `${fmt(seconds, 3)} s`;
  const m = Math.floor(seconds / 60);
  const s = Math.round(seconds % 60);
  if (m < 60) return `${m} min ${s} s`;
  return `${Math.floor(m / 60)} h ${m % 60} min`;
}

export function fmtDate(iso) {
  if (!iso) return "–";
  const d = new Date(iso);
  if (Number.isNaN(d.getTime())) return iso;
  const sameYear = d.getFullYear() === new Date().getFullYear();
  return d.toLocaleString(undefined, {
    day: "numeric",
    month: "short",
    year: sameYear ? undefined : "numeric",
    hour: "2-digit",
    minute: "2-digit",
  });
}

export function fmtBytes(n) {
  if (n < 1024) return `${n} B`;
  if (n < 1024 ** 2) return `${(n / 1024).toFixed(1)} kB`;
  return `${(n / 1024 ** 2).toFixed(1)} MB`;
}

/** "speed_rpm [rpm]" style label: name plus unit when there is one. */
export function withUnit(name, unit) {
  return unit ? `${name} [${unit}]` : name;
}

/** Metric keys as people say them. */
export function metricLabel(key) {
  const known = {
    rmse: "RMSE",
    map_rmse: "Map RMSE",
    output_rmse: "Output RMSE",
    max_abs_error: "Max |error|",
    mean_relative_error: "Mean rel. error",
    coverage: "Coverage",
    ise: "ISE",
    mae: "Max |e|", // TQ (61): the torque paper's "MAE" is max |τ − τ̂|
    sd: "SD",
    samples_per_s: "Samples/s",
    estimate_s: "Compute time",
    run_s: "Compute time",
    "holdout:rmse": "Held-out RMSE",
    "holdout:mae": "Held-out mean |e|",
    "holdout:max_abs_error": "Held-out max |e|",
    "holdout:base_rmse": "Base map held-out RMSE",
    "holdout:base_mae": "Base map held-out mean |e|",
    "holdout:base_max_abs_error": "Base map held-out max |e|",
    "holdout:samples": "Held-out samples",
    "nis:mean": "Mean NIS",
    "nis:in_band": "NIS in 95 % band",
    "nis:innovation_mean": "Innovation mean",
    "nis:mean_band_low": "Mean NIS band, low",
    "nis:mean_band_high": "Mean NIS band, high",
    "residual:mean": "Residual mean",
    "residual:rms": "Residual RMS",
    "residual:mean_over_rms": "Residual mean / RMS",
    "residual:autocorr_lag1": "Residual autocorr. (lag 1)",
    "residual:autocorr_band": "Residual autocorr. band",
  };
  if (known[key]) return known[key];
  // Truth-free checks an estimator has no honest form of (estimation/holdout.py), and the
  // per-output held-out error and NIS of the observers (estimation/holdout_observers.py).
  const na = /^(holdout|nis):not_applicable:(.+)$/.exec(key);
  if (na) {
    const what = na[1] === "holdout" ? "Held-out error" : "NIS";
    return `${what}: n/a (${na[2].replaceAll("_", " ")})`;
  }
  const other = /^(holdout|nis):(.+)_(rmse|mean)$/.exec(key);
  if (other) {
    return other[1] === "holdout" ? `Held-out RMSE, ${other[2]}` : `Mean NIS, ${other[2]}`;
  }
  return key.replaceAll("_", " ").replace(/^\w/, (c) => c.toUpperCase());
}

export function debounce(fn, ms) {
  let timer = 0;
  return (...args) => {
    clearTimeout(timer);
    timer = setTimeout(() => fn(...args), ms);
  };
}

/** A status pill for a run. */
export function statusBadge(status) {
  return h("span", { class: "badge", dataset: { status } }, status);
}

/** Toast message in the shared live region. */
export function toast(message, { error = false, ms = 4000 } = {}) {
  const host = document.querySelector(SEL.toasts);
  if (!host) return;
  const el = h("div", { class: `toast${error ? " error" : ""}` }, message);
  host.append(el);
  setTimeout(() => el.remove(), ms);
}

/**
 * The bar of an upload or simulate form (role=progressbar, 0-100 in aria-valuenow, named by
 * `label`): `el` goes in the form; `start()` shows it empty, `set(f)` fills fraction f, `finish(ok)` ends it full and
 * green or red.
 */
export function uploadProgress({ label = "Upload progress" } = {}) {
  const bar = h("span");
  const el = h(
    "div",
    {
      class: "progress",
      hidden: true,
      role: "progressbar",
      "aria-label": label,
      "aria-valuemin": "0",
      "aria-valuemax": "100",
      "aria-valuenow": "0",
    },
    bar,
  );
  const set = (f) => {
    bar.style.width = `${Math.round(f * 100)}%`;
    el.setAttribute("aria-valuenow", String(Math.round(f * 100)));
  };
  return {
    el,
    set,
    start() {
      el.hidden = false;
      el.classList.remove("ok", "bad");
      set(0);
    },
    finish(ok) {
      if (ok) set(1);
      el.classList.add(ok ? "ok" : "bad");
    },
  };
}

/** Page header used by every view. */
export function pageHead({ title, sub, crumbs, actions = [] }) {
  return h(
    "header",
    { class: "page-head" },
    h(
      "div",
      {},
      crumbs ? h("div", { class: "crumbs" }, crumbs) : null,
      h("h1", { tabindex: "-1", "data-page-title": "" }, title),
      sub ? h("div", { class: "sub" }, sub) : null,
    ),
    h("div", { class: "actions" }, actions),
  );
}

export function card({ title, hint, actions = [], body, foot, cls = "", bodyCls = "", label }) {
  const id = title ? `card-${Math.random().toString(36).slice(2, 9)}` : null;
  return h(
    "section",
    { class: `card ${cls}`, "aria-labelledby": id, "aria-label": id ? null : label },
    title
      ? h(
          "div",
          { class: "card-head" },
          h("h2", { id }, title, hint ? h("span", { class: "hint" }, ` · ${hint}`) : null),
          h("div", { class: "row" }, actions),
        )
      : null,
    h("div", { class: `card-body ${bodyCls}` }, body),
    foot ? h("div", { class: "card-foot" }, foot) : null,
  );
}

/** Quantile of a numeric array (ignores null/NaN); q in [0, 1]. */
export function quantile(values, q) {
  const xs = values.filter((v) => v !== null && Number.isFinite(v)).sort((a, b) => a - b);
  if (!xs.length) return null;
  const pos = (xs.length - 1) * q;
  const lo = Math.floor(pos);
  const hi = Math.ceil(pos);
  return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo);
}

export function flatten(nested) {
  return Array.isArray(nested) ? nested.flat(Infinity) : [];
}

/** Evenly spaced "nice" breakpoints covering [lo, hi] with n points. */
export function niceBreakpoints(lo, hi, n) {
  if (!(Number.isFinite(lo) && Number.isFinite(hi)) || n < 2) return [];
  if (hi <= lo) hi = lo + 1;
  const raw = (hi - lo) / (n - 1);
  const mag = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => s >= raw) ?? raw;
  const start = Math.floor(lo / step) * step;
  const out = [];
  for (let i = 0; i < n; i += 1) out.push(Number((start + i * step).toPrecision(10)));
  return out;
}

/** "0, 500, 1000" → [0, 500, 1000]; throws a message naming the bad token. */
export function parseNumberList(text) {
  const parts = String(text)
    .split(/[\s,;]+/)
    .filter(Boolean);
  return parts.map((p) => {
    const v = Number(p);
    if (!Number.isFinite(v)) throw new Error(`"${p}" is not a number`);
    return v;
  });
}

/** A modal confirmation (native <dialog>); resolves true when confirmed. */
export function confirmDialog(
  message,
  { title = "Are you sure?", confirmLabel = "Confirm", danger = false } = {},
) {
  return new Promise((resolve) => {
    const id = `dlg-${Math.random().toString(36).slice(2, 8)}`;
    const dialog = h(
      "dialog",
      { "aria-labelledby": id, "data-confirm": "" },
      h(
        "form",
        { method: "dialog" },
        h("h2", { id, style: { marginBottom: "8px" } }, title),
        h("p", { style: { color: "var(--text-2)" } }, message),
        h(
          "div",
          { class: "row end", style: { marginTop: "16px" } },
          h("button", { value: "cancel", type: "submit" }, "Cancel"),
          h(
            "button",
            {
              value: "ok",
              type: "submit",
              class: danger ? "danger" : "primary",
              "data-confirm-ok": "",
            },
            confirmLabel,
          ),
        ),
      ),
    );
    dialog.addEventListener("close", () => {
      resolve(dialog.returnValue === "ok");
      dialog.remove();
    });
    document.body.append(dialog);
    dialog.showModal();
  });
}

/** Split "nox_ppm [ppm]" into name and unit (the CSV header convention). */
export function splitHeader(text) {
  const m = /^\s*(.*?)\s*\[([^\]]*)\]\s*$/.exec(text);
  return m ? { name: m[1], unit: m[2] } : { name: text.trim(), unit: "" };
}
