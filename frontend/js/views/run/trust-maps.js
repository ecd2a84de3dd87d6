/**
 * How far to trust a run's map, cell by cell: which cells the data reached, the hits per cell
 * (a heatmap beside the variances) and, on a simulated dataset, the map's error against its
 * truth ("estimated − true", a diverging scale centred on zero).
 *
 * Cell states (frame.cellState, drawn by MapPlot.overlay and named in the hover):
 *   0 learned    visits ≥ 1: at least one sample's worth of interpolation weight (the
 *                coverage metric's threshold, estimation/metrics.py map_metrics);
 *   1 unvisited  visits < 1: the value is the prior (or barely moved), not learned;
 *   2 filled     visits = 0 and the value differs from the run's start θ0: set without a
 *                sample of its own (spread by the filter's covariance, or an observer's fill;
 *                the LPV observer reports no fill mask, so it is derived this way).
 * visits are the per-cell Σ of the accepted samples' interpolation weights
 * (app/runs/results.py), sent with every frame and version. The hits card switches to the
 * rejections per cell (Hits | Rejections): Σ over the reasons of the rejected samples'
 * interpolation weights (a version's cell_rejections; live, the latest version's, from
 * GET /api/runs/{id}/cells).
 */
import { api } from "../../api.js";
import { RUN_ACTIVE } from "../../constants.js";
import { card, flatten, h, withUnit } from "../../dom.js";
import { cellEdges } from "../../grid-math.js";
import { MapPlot } from "../../map-plot.js";
import { theme, withAlpha } from "../../plot.js";

/** Trace names of the overlays (what tests and hover look for). */
export const OVERLAY = Object.freeze({
  unvisited: "unvisited cells",
  filled: "filled cells",
});
/** Cell states of frame.cellState. */
export const CELL = Object.freeze({ learned: 0, unvisited: 1, filled: 2 });
/** The hits and error maps redraw at most this often (trailing: the last frame is drawn), so
 * their two extra Plotly renders never crowd out the live map's 20 frames/s (frames.js). */
const TRUST_INTERVAL_MS = 400;
/** While the run goes, the rejections map refetches the latest version's counts at most this often. */
const REJECTIONS_REFRESH_MS = 2000;
/** Visits below this count as unvisited: one sample's worth of weight (coverage's threshold). */
const MIN_VISITS = 1;

/** {name, unit} of a run's map values when it has no output column (quantity.js). */
export { mapQuantity } from "../../quantity.js";

/**
 * Per-cell states (nested like values): see the module docstring. start: the run's θ0 (a
 * number, or nested like values); tolerance relative to the value's size.
 */
export function cellStates(values, visits, start) {
  if (!values || !visits) return null;
  const at = (m, path) => path.reduce((x, k) => (Array.isArray(x) ? x[k] : x), m);
  const walk = (v, n, path) => {
    if (Array.isArray(v)) return v.map((x, k) => walk(x, n?.[k], [...path, k]));
    if (n === null || n === undefined || n >= MIN_VISITS) return CELL.learned;
    const s0 = typeof start === "number" ? start : at(start, path);
    const moved =
      typeof v === "number" &&
      typeof s0 === "number" &&
      Math.abs(v - s0) > 1e-9 * Math.max(1, Math.abs(s0));
    return n <= 0 && moved ? CELL.filled : CELL.unvisited;
  };
  return walk(values, visits, []);
}

/**
 * Heatmap overlays (MapPlot.overlay): the unvisited cells greyed and hatched by one path
 * shape (one SVG path over the plot, the cheapest mark per live frame: an extra trace
 * doubles a frame's cost), filled cells marked with a diamond (a trace, only when there are
 * any). The shape's `cells` lists the [i, j] it covers.
 */
export function trustOverlay(frame, x, y) {
  const states = frame.cellState;
  if (!states || !Array.isArray(states[0])) return {};
  const t = theme();
  const grey = t.dark ? "#1f2430" : "#d4d4d8";
  const path = [];
  const cells = [];
  const fx = [];
  const fy = [];
  x.forEach((xv, i) =>
    y.forEach((yv, j) => {
      const s = states[i]?.[j];
      if (s === CELL.learned || s === undefined) return;
      const [x0, x1] = cellEdges(x, i);
      const [y0, y1] = cellEdges(y, j);
      // The brick (filled grey) and its diagonal (the hatch, stroked).
      path.push(`M${x0},${y0}H${x1}V${y1}H${x0}Z`, `M${x0},${y0}L${x1},${y1}`);
      cells.push([i, j]);
      if (s === CELL.filled) {
        fx.push(xv);
        fy.push(yv);
      }
    }),
  );
  const shapes = path.length
    ? [
        {
          type: "path",
          name: OVERLAY.unvisited,
          path: path.join(""),
          xref: "x",
          yref: "y",
          layer: "above",
          fillcolor: withAlpha(grey, 0.72),
          line: { color: withAlpha(t.dark ? "#9ca3af" : "#52525b", 0.45), width: 1 },
          cells,
        },
      ]
    : [];
  const traces = fx.length
    ? [
        {
          type: "scatter",
          mode: "markers",
          name: OVERLAY.filled,
          x: fx,
          y: fy,
          hoverinfo: "skip",
          showlegend: false,
          marker: { symbol: "diamond-open", size: 9, color: t.text, line: { width: 1.8 } },
        },
      ]
    : [];
  return { traces, shapes };
}

/** The legend of the overlays, placed under a map. */
export function trustLegend() {
  const swatch = (style) =>
    h("span", {
      "aria-hidden": "true",
      style: {
        display: "inline-block",
        width: "14px",
        height: "12px",
        marginRight: "6px",
        verticalAlign: "-2px",
        border: "1px solid var(--text-3)",
        ...style,
      },
    });
  const item = (mark, text, title) =>
    h("span", { style: { marginRight: "18px", whiteSpace: "nowrap" }, title }, mark, text);
  return h(
    "div",
    { class: "help", "data-map-legend": "", style: { padding: "2px 12px 8px", margin: 0 } },
    item(
      swatch({
        background: "repeating-linear-gradient(45deg, #d4d4d8 0 3px, #71717a 3px 4px)",
      }),
      "unvisited (< 1 sample): prior value, not learned",
      "Accumulated interpolation weight of the accepted samples below 1",
    ),
    item(
      h("span", { "aria-hidden": "true", style: { marginRight: "6px" } }, "◇"),
      "filled: changed without samples of its own",
      "No sample weight at all, yet the value moved from the start θ0 " +
        "(spread from neighbouring cells, or filled by the observer)",
    ),
  );
}

/**
 * The hit-count and error cards and what they draw: draw(frame) after each map frame;
 * states(frame) gives the cell states the value map's overlay uses.
 */
export function trustMaps(v, { slices }) {
  const { outputName, outputUnit, run } = v;
  const unit = outputUnit || "-";
  const hitsEl = h("div", {
    class: "plot map",
    "data-plot": "hits",
    role: "img",
    "aria-label": "Hits per cell: samples weighted onto each cell",
  });
  const errorEl = h("div", {
    class: "plot map",
    "data-plot": "error",
    role: "img",
    "aria-label": `Estimated minus true ${withUnit(outputName, outputUnit)}, diverging colour scale centred on zero`,
  });
  const common = { unit: outputUnit, label: outputName, gaps: false, slices };
  const hitsPlot = new MapPlot(hitsEl, { kind: "visits", ...common });
  const errorPlot = new MapPlot(errorEl, { kind: "diff", ...common });
  errorPlot.barLabel = "estimated − true";
  errorPlot.hoverName = `estimated − true ${outputName}`;
  errorPlot.overlay = trustOverlay;
  const rejEl = h("div", {
    class: "plot map",
    "data-plot": "rejections",
    role: "img",
    "aria-label": "Rejected samples per cell: rejected samples weighted onto each cell",
  });
  const rejPlot = new MapPlot(rejEl, {
    kind: "value",
    unit: "samples",
    label: "rejected",
    gaps: false,
    slices,
  });
  rejPlot.barLabel = "rejected";
  // Each plot in its own box: the colour bar wraps the plot, and hides with its box.
  const hitsBox = h("div", { "data-hits-box": "hits" }, hitsEl);
  const rejBox = h("div", { "data-hits-box": "rejections" }, rejEl);
  rejBox.hidden = true;
  const HINTS = {
    hits: "samples weighted onto each cell",
    rejections: "rejected samples weighted onto each cell, all reasons",
  };
  let view = "hits";
  const viewButtons = ["hits", "rejections"].map((m) =>
    h(
      "button",
      {
        type: "button",
        "aria-pressed": String(m === view),
        "data-hits-view": m,
        onclick: () => setView(m),
      },
      m === "hits" ? "Hits" : "Rejections",
    ),
  );
  const hitsCard = card({
    title: "Hits",
    hint: HINTS.hits,
    actions: [
      h("div", { class: "seg", role: "group", "aria-label": "Per-cell count" }, viewButtons),
    ],
    body: [hitsBox, rejBox],
    bodyCls: "tight",
  });
  const errorCard = card({
    title: "Estimated − true",
    hint: `${withUnit(outputName, unit)}, on the simulated truth; 0 is white`,
    body: [errorEl, trustLegend()],
    bodyCls: "tight",
  });
  errorCard.hidden = true;
  errorCard.dataset.errorMap = "";
  const start = startValues(run);
  let truth = null;

  /** Fetch the dataset's true map on the run's grid (simulated datasets only). */
  async function loadTruth(signal) {
    if (!v.producesMap || !v.dataset?.has_truth) return;
    try {
      const body = await api.get(`/api/runs/${v.id}/truth-map`, { signal });
      if (!body?.values) return;
      truth = body;
      errorCard.hidden = false;
      v.s.dirtyMap = true;
      if (v.maps?.lastFrame) draw({ ...v.maps.lastFrame });
    } catch {
      /* no truth on this grid: no error map */
    }
  }

  const states = (frame) => cellStates(frame.values, frame.visits, start);

  // Trailing throttle: the newest frame waits for the interval, then is drawn.
  let pending = null;
  let timer = 0;
  let last = -Infinity;
  function flush() {
    clearTimeout(timer);
    timer = 0;
    last = performance.now();
    const frame = pending;
    pending = null;
    if (frame) drawNow(frame);
  }
  function draw(frame) {
    pending = frame;
    const wait = TRUST_INTERVAL_MS - (performance.now() - last);
    if (wait <= 0) flush();
    else if (!timer) timer = setTimeout(flush, wait);
  }

  function setView(m) {
    view = m;
    for (const b of viewButtons) b.setAttribute("aria-pressed", String(b.dataset.hitsView === m));
    hitsBox.hidden = m !== "hits";
    rejBox.hidden = m !== "rejections";
    hitsCard
      .querySelector("h2")
      .replaceChildren(
        m === "hits" ? "Hits" : "Rejections",
        h("span", { class: "hint" }, ` · ${HINTS[m]}`),
      );
    if (shown) drawNow(shown);
  }

  // The latest version's rejections per cell while live (frames carry none): refetched when
  // the run's status changed, and while it runs at most every REJECTIONS_REFRESH_MS.
  let fetched = null; // {status, at, cells}
  let loading = false;
  function loadRejections() {
    const status = v.s?.run?.status ?? v.run?.status;
    const active = RUN_ACTIVE.has(status);
    if (loading) return;
    if (fetched && fetched.status === status) {
      if (!active || performance.now() - fetched.at < REJECTIONS_REFRESH_MS) return;
    }
    loading = true;
    api
      .get(`/api/runs/${v.id}/cells`)
      .then((body) => {
        fetched = { status, at: performance.now(), cells: body?.rejected ?? {} };
        if (view === "rejections" && shown) drawRejections(shown);
      })
      .catch(() => {
        fetched = { status, at: performance.now(), cells: fetched?.cells ?? {} };
      })
      .finally(() => {
        loading = false;
      });
  }

  function drawRejections(frame) {
    // A stored version brings its own; the live view uses the latest version's.
    const cells = frame.cellRejections ?? fetched?.cells;
    if (!frame.cellRejections) loadRejections();
    if (!cells) return;
    const values = sumNested(Object.values(cells), frame.values);
    if (!values) return;
    // Counts from zero: the lightest cell reads as "fewest", not as some offset.
    rejPlot.setRange([0, Math.max(1, ...flatten([values]))]);
    rejPlot.render({ axes: frame.axes, values, visits: frame.visits });
  }

  let shown = null;
  function drawNow(frame) {
    shown = frame;
    if (view === "rejections") drawRejections(frame);
    else if (frame.visits) hitsPlot.render(frame);
    if (!truth || !sameShape(frame.values, truth.values)) return;
    const cellState = frame.cellState ?? states(frame);
    const error = subtract(frame.values, truth.values);
    // Symmetric about zero, sized by the learned cells: the prior's error saturates (▲▼).
    const m = maxAbs(error, cellState);
    errorPlot.setRange(m > 0 ? [-m, m] : null);
    errorPlot.render({ ...frame, values: error, cellState });
  }

  return {
    hitsCard,
    errorCard,
    hitsPlot,
    rejPlot,
    loadTruth,
    states,
    draw,
    destroy: () => {
      clearTimeout(timer);
      pending = null;
      shown = null; // a rejections fetch still out draws nothing
      hitsPlot.destroy();
      rejPlot.destroy();
      errorPlot.destroy();
    },
  };
}

/** The run's start θ0 (a number or nested like values); 0 when the estimator starts at zero. */
function startValues(run) {
  const theta0 = run.estimator_config?.theta0 ?? run.config?.theta0 ?? 0;
  return typeof theta0 === "number" || Array.isArray(theta0) ? theta0 : 0;
}

/** Element-wise Σ of nested grids shaped like `like` (null entries count 0); zeros when none. */
function sumNested(grids, like) {
  const walk = (shape, parts) =>
    Array.isArray(shape)
      ? shape.map((x, k) =>
          walk(
            x,
            parts.map((p) => (Array.isArray(p) ? p[k] : null)),
          ),
        )
      : parts.reduce((acc, p) => acc + (typeof p === "number" && Number.isFinite(p) ? p : 0), 0);
  return like ? walk(like, grids) : null;
}

function subtract(a, b) {
  if (Array.isArray(a)) return a.map((x, k) => subtract(x, b?.[k]));
  return typeof a === "number" && typeof b === "number" ? a - b : null;
}

/** max |e| over the learned cells (all cells when none is learned yet). */
function maxAbs(error, states) {
  const e = flatten([error]);
  const st = flatten([states ?? []]);
  let learned = 0;
  let all = 0;
  e.forEach((x, k) => {
    if (typeof x !== "number" || !Number.isFinite(x)) return;
    all = Math.max(all, Math.abs(x));
    if (st[k] === CELL.learned) learned = Math.max(learned, Math.abs(x));
  });
  return learned || all;
}

function sameShape(a, b) {
  return flatten([a]).length === flatten([b]).length;
}
