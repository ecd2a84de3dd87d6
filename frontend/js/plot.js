/**
 * Plotly access and the house look of every chart. Plotly.js is the vendored UMD build
 * (served from the installed `plotly` Python package); it is read here once, so no other
 * module touches the global.
 *
 * Plotly.js is 4.8 MB: evaluating it takes about a second on a cold cache, so the page does
 * not wait for it. index.html preloads the file (the download overlaps the page's own), and
 * main.js runs the script once the first view has rendered (loadPlotly). Until then react()
 * keeps the latest figure per element and draws it as soon as Plotly is there.
 */
import { SEL } from "./constants.js";

const PLOTLY_URL = "/static/vendor/plotly.min.js";
let loading = null;
let markLoaded;
/** Resolves when Plotly.js has run (started by loadPlotly, never by a plot being drawn). */
const loaded = new Promise((resolve) => {
  markLoaded = resolve;
});

export function plotly() {
  const P = globalThis.Plotly;
  if (!P) throw new Error(`Plotly.js did not load (${PLOTLY_URL})`);
  return P;
}

/** Run Plotly.js (from the preloaded, content-versioned URL); resolves to the Plotly object. */
export function loadPlotly() {
  if (globalThis.Plotly) return Promise.resolve(globalThis.Plotly);
  if (!loading) {
    loading = new Promise((resolve, reject) => {
      const script = document.createElement("script");
      script.src = document.querySelector(SEL.plotlyPreload)?.href || PLOTLY_URL;
      script.onload = () => {
        markLoaded();
        resolve(plotly());
      };
      script.onerror = () => {
        loading = null;
        reject(new Error(`Plotly.js did not load (${script.src})`));
      };
      document.head.append(script);
    });
  }
  return loading;
}

export const CONFIG = Object.freeze({
  displaylogo: false,
  responsive: true,
  scrollZoom: false,
  modeBarButtonsToRemove: [
    "lasso2d",
    "select2d",
    "autoScale2d",
    "toggleSpikelines",
    "sendDataToCloud",
  ],
  toImageButtonOptions: { format: "png", scale: 2 },
});

export const STATIC_CONFIG = Object.freeze({ ...CONFIG, displayModeBar: false, staticPlot: false });

function cssVar(name) {
  return getComputedStyle(document.documentElement).getPropertyValue(name).trim();
}

/** Colours of the current theme, read from the CSS custom properties. */
export function theme() {
  return {
    text: cssVar("--text"),
    text2: cssVar("--text-2"),
    text3: cssVar("--text-3"),
    grid: cssVar("--plot-grid"),
    line: cssVar("--plot-line"),
    surface: cssVar("--surface"),
    accent: cssVar("--accent"),
    ok: cssVar("--ok"),
    warn: cssVar("--warn"),
    danger: cssVar("--danger"),
    info: cssVar("--info"),
    trail: cssVar("--trail"),
    trailEdge: cssVar("--trail-edge"),
    activeCell: cssVar("--active-cell"),
    outline: cssVar("--outline-cell"),
    font: cssVar("--font"),
    dark: document.documentElement.dataset.theme === "dark",
  };
}

/** "#rrggbb" (or "#rgb") with an opacity, as Plotly's rgba(); other colours are returned as they are. */
export function withAlpha(color, alpha) {
  const m = /^#([0-9a-f]{3}|[0-9a-f]{6})$/i.exec(String(color).trim());
  if (!m) return color;
  const hex = m[1].length === 3 ? [...m[1]].map((c) => c + c).join("") : m[1];
  const [r, g, b] = [0, 2, 4].map((i) => parseInt(hex.slice(i, i + 2), 16));
  return `rgba(${r},${g},${b},${alpha})`;
}

/** Series colours that stay distinguishable on both themes. */
export const SERIES_COLORS = [
  "#3b82f6",
  "#f59e0b",
  "#10b981",
  "#ef4444",
  "#8b5cf6",
  "#06b6d4",
  "#ec4899",
  "#84cc16",
];

export function axis(title, extra = {}) {
  const t = theme();
  return {
    title: { text: title, font: { size: 12, color: t.text2 }, standoff: 8 },
    gridcolor: t.grid,
    zerolinecolor: t.line,
    linecolor: t.line,
    tickfont: { size: 11, color: t.text3 },
    automargin: true,
    ...extra,
  };
}

export function baseLayout(extra = {}) {
  const t = theme();
  return {
    paper_bgcolor: "rgba(0,0,0,0)",
    plot_bgcolor: "rgba(0,0,0,0)",
    font: { family: t.font, size: 12, color: t.text2 },
    margin: { l: 56, r: 16, t: 12, b: 44 },
    hoverlabel: {
      font: { family: t.font, size: 12, color: t.text },
      bgcolor: t.surface,
      bordercolor: t.line,
    },
    legend: {
      orientation: "h",
      x: 0,
      y: 1.02,
      yanchor: "bottom",
      font: { size: 11.5 },
      bgcolor: "rgba(0,0,0,0)",
    },
    uirevision: "keep",
    ...extra,
  };
}

let revision = 0;

/**
 * Plotly.react with the house config: updates traces in place, no re-layout per frame.
 * Plotly only notices new data through new array references or a new `datarevision`;
 * live series grow in place, so every call carries a fresh revision.
 */
export function react(el, data, layout, config = CONFIG) {
  revision += 1;
  layout = { ...layout, datarevision: revision };
  if (globalThis.Plotly && el.isConnected && !waiting.has(el))
    return globalThis.Plotly.react(el, data, layout, config);
  return later(el, [data, layout, config]);
}

/** Figures waiting for Plotly.js or for their element to be in the page: the latest one wins. */
const waiting = new Map();

function later(el, args) {
  const queued = waiting.get(el);
  if (queued) {
    queued.args = args;
    return queued.promise;
  }
  const entry = { args, cancelled: false };
  entry.promise = (globalThis.Plotly ? Promise.resolve() : loaded)
    .then(() => connected(el))
    .then((ok) => {
      if (waiting.get(el) === entry) waiting.delete(el);
      return ok && !entry.cancelled ? plotly().react(el, ...entry.args) : null;
    })
    .catch((err) => {
      waiting.delete(el);
      console.error(err);
      return null;
    });
  waiting.set(el, entry);
  return entry.promise;
}

/** Plotly sizes a plot from its element, so drawing waits until the element is in the page. */
function connected(el, frames = 120) {
  return new Promise((resolve) => {
    const tick = (left) => {
      if (el.isConnected) resolve(true);
      else if (left > 0) requestAnimationFrame(() => tick(left - 1));
      else resolve(false);
    };
    tick(frames);
  });
}

export function purge(el) {
  const queued = waiting.get(el);
  if (queued) {
    queued.cancelled = true;
    waiting.delete(el);
  }
  try {
    plotly().purge(el);
  } catch {
    /* never plotted */
  }
}

export function resize(el) {
  try {
    plotly().Plots.resize(el);
  } catch {
    /* not a plot */
  }
}

let webgl = null;
/** Whether WebGL (needed by the 3-D surface) works in this browser. */
export function hasWebGL() {
  if (webgl === null) {
    try {
      const c = document.createElement("canvas");
      webgl = Boolean(c.getContext("webgl2") || c.getContext("webgl"));
    } catch {
      webgl = false;
    }
  }
  return webgl;
}

/* ---------- colour scales ---------- */
export const SCALE_VALUE = [
  [0, "#0d0887"],
  [0.13, "#41049d"],
  [0.25, "#6a00a8"],
  [0.38, "#8f0da4"],
  [0.5, "#b12a90"],
  [0.63, "#cc4778"],
  [0.75, "#e16462"],
  [0.88, "#f2844b"],
  [1, "#fcce25"],
];
export const SCALE_VIRIDIS = [
  [0, "#440154"],
  [0.13, "#482878"],
  [0.25, "#3e4989"],
  [0.38, "#31688e"],
  [0.5, "#26828e"],
  [0.63, "#1f9e89"],
  [0.75, "#35b779"],
  [0.88, "#6ece58"],
  [1, "#fde725"],
];
export const SCALE_VARIANCE = [
  [0, "#000004"],
  [0.13, "#1c1044"],
  [0.25, "#4f127b"],
  [0.38, "#812581"],
  [0.5, "#b5367a"],
  [0.63, "#e55064"],
  [0.75, "#fb8761"],
  [0.88, "#fec287"],
  [1, "#fcfdbf"],
];
export const SCALE_DIFF = [
  [0, "#2166ac"],
  [0.2, "#4393c3"],
  [0.35, "#92c5de"],
  [0.5, "#f7f7f7"],
  [0.65, "#f4a582"],
  [0.8, "#d6604d"],
  [1, "#b2182b"],
];

/** Colour-bar ticks for log10-coded z: one per decade, labelled 1e-3 … */
export function decadeTicks(lo, hi) {
  const a = Math.floor(lo);
  const b = Math.ceil(hi);
  const step = Math.max(1, Math.ceil((b - a) / 6));
  const vals = [];
  for (let k = a; k <= b; k += step) vals.push(k);
  return { tickvals: vals, ticktext: vals.map((k) => (k === 0 ? "1" : `1e${k}`)) };
}
