/**
 * One look-up table drawn with Plotly: heatmap (or 3-D surface) of the values, of the
 * variances (diag P, log colour scale) or of a difference, with the operating-point trail
 * and the active cell over it. Tables of three (or more) axes are shown as a 2-D slice with a
 * slider per further axis, labelled with that axis' name, breakpoint value and unit; plots in
 * one SliceGroup follow each other's slice. Colour ranges are fixed per plot: pinned with
 * setRange (cells beyond it saturate at the ends of the scale), or else seeded from the first
 * frame on "nice" bounds and widened only when a value leaves them, in quarter-span steps, so
 * the same values always give the same range and successive frames stay comparable.
 * A "deviation" plot shows standardised deviations z on a diverging scale, with the cells
 * listed in frame.outlines (e.g. |z| > 3) outlined.
 */
import { ColorBar } from "./color-bar.js";
import { fmt, h, withUnit } from "./dom.js";
import {
  cellEdges,
  finiteExtent,
  interp1,
  interp2,
  logNested,
  nearestIndex,
  niceRange,
  outerEdges,
  padRange,
  sliceNested,
  transpose,
  widenRange,
} from "./grid-math.js";
import {
  axis,
  baseLayout,
  decadeTicks,
  hasWebGL,
  purge,
  react,
  SCALE_DIFF,
  SCALE_VALUE,
  SCALE_VARIANCE,
  SCALE_VIRIDIS,
  theme,
  withAlpha,
} from "./plot.js";

/** Trace names (also what tests and hover look for). */
export const TRACE = Object.freeze({
  trail: "trail",
  point: "operating point",
  active: "active cell",
  outlines: "outlined cells",
});
/** Kinds drawn on the diverging scale, symmetric about zero. */
const DIVERGING = new Set(["diff", "deviation"]);
let uid = 0;

/**
 * Plots that follow each other's slice (by breakpoint value of the axis with the same name);
 * it remembers the last value per axis, so plots drawn anew (a re-rendered view) keep it.
 */
export class SliceGroup {
  constructor() {
    this.plots = new Set();
    this.values = new Map();
  }

  moved(from, name, value) {
    this.values.set(name, value);
    for (const p of this.plots) if (p !== from) p.showSliceValue(name, value);
  }
}

export class MapPlot {
  /**
   * @param {HTMLElement} el
   * @param {{kind?: "value"|"variance"|"visits"|"diff"|"deviation", unit?: string, label?: string, mode?: "heatmap"|"surface",
   *   gaps?: boolean, slices?: SliceGroup}} opts
   */
  constructor(
    el,
    {
      kind = "value",
      unit = "",
      label = "value",
      mode = "heatmap",
      gaps = true,
      slices = null,
    } = {},
  ) {
    this.el = el;
    this.kind = kind;
    this.unit = unit;
    this.label = label;
    this.mode = mode;
    this.gaps = gaps;
    this.range = null;
    this.fixed = false;
    this.extremes = null;
    this.last = null;
    this.bar = null;
    this.slices = slices;
    slices?.plots.add(this);
    this.slice = { key: "", axes: [], index: [], inputs: [], labels: [], host: null };
    /** Marks over a heatmap's cells: (frame2d, x, y) => {traces?, shapes?} (trust-maps.js). */
    this.overlay = null;
  }

  /** Pin the colour range (e.g. shared by several maps, or fixed per run); null returns to widen-only. */
  setRange(range) {
    this.range = range ? [...range] : null;
    this.fixed = Boolean(range);
  }

  setMode(mode) {
    this.mode = mode === "surface" && hasWebGL() ? "surface" : "heatmap";
    if (this.last) this.render(this.last);
  }

  /** Remove the drawing (the plot can render again later). */
  clear() {
    purge(this.el);
    this.bar?.clear();
    this.slice.host?.replaceChildren();
    this.slice = { ...this.slice, key: "", axes: [], index: [], inputs: [], labels: [] };
  }

  destroy() {
    this.clear();
    this.slices?.plots.delete(this);
  }

  /**
   * @param {{axes, values, variances?, visits?, weights?, trail?: {x: number[], y: number[]}, activeCell?: number[]|null,
   *   outlines?: number[][]}} frame  outlines: index tuples (one index per axis) of cells to outline
   */
  render(frame) {
    this.last = frame;
    const { axes, values } = frame;
    if (!axes?.length || !values) return null;
    if (!this.bar && this.el.parentElement) this.bar = new ColorBar(this.el, this.kind); // before Plotly sizes the plot
    const full =
      this.kind === "variance"
        ? logNested(frame.variances ?? values)
        : this.kind === "visits"
          ? (frame.visits ?? values)
          : values;
    this.widen(full);
    this.syncSlicer(axes);
    const shown = axes.length > 2 ? this.sliced(frame) : frame;
    const z = axes.length > 2 ? sliceNested(full, this.slice.index) : full;
    if (shown.axes.length === 1) {
      this.bar?.clear();
      return react(this.el, ...this.figure1d(shown, z));
    }
    if (this.mode === "surface" && this.kind === "value") {
      this.bar?.clear();
      return react(this.el, ...this.surface(shown, z));
    }
    const drawn = react(this.el, ...this.heatmap(shown, z));
    this.drawBar();
    // A plot drawn later (Plotly.js still loading) sizes its colour bar once it is there.
    if (!this.el._fullLayout) Promise.resolve(drawn).then(() => this.drawBar());
    return drawn;
  }

  /* ---------- slices of 3-D (and higher) tables ---------- */

  /** One slider per axis beyond the second; rebuilt only when those axes change. */
  syncSlicer(axes) {
    const extra = axes.slice(2);
    const key = JSON.stringify(extra.map((a) => [a.name, a.unit ?? "", a.breakpoints]));
    if (key === this.slice.key) return;
    const old = this.slice;
    const index = extra.map((a) => {
      const k = old.axes.findIndex((o) => o.name === a.name);
      if (k >= 0) return nearestIndex(a.breakpoints, old.axes[k].breakpoints[old.index[k]]);
      const remembered = this.slices?.values.get(a.name);
      return remembered === undefined ? 0 : nearestIndex(a.breakpoints, remembered);
    });
    if (!this.slice.host && extra.length) {
      this.slice.host = h("div", { class: "slice-pickers", "data-slice-pickers": "" });
      const anchor = this.bar?.wrap ?? this.el;
      anchor.parentElement?.insertBefore(this.slice.host, anchor);
    }
    this.slice = { ...this.slice, key, axes: extra, index, inputs: [], labels: [] };
    const pickers = extra.map((a, k) => {
      uid += 1;
      const id = `slice-${uid}`;
      const input = h("input", {
        type: "range",
        id,
        min: "0",
        max: String(a.breakpoints.length - 1),
        step: "1",
        value: String(index[k]),
        "data-slice-axis": a.name,
      });
      const label = h("label", { for: id, class: "slice-label" });
      input.addEventListener("input", () => {
        this.slice.index[k] = Number(input.value);
        this.describeSlice(k);
        if (this.last) this.render(this.last);
        this.slices?.moved(this, a.name, a.breakpoints[this.slice.index[k]]);
      });
      this.slice.inputs.push(input);
      this.slice.labels.push(label);
      return h("div", { class: "slice-picker", "data-slice-picker": a.name }, label, input);
    });
    this.slice.host?.replaceChildren(...pickers);
    extra.forEach((_, k) => this.describeSlice(k));
  }

  describeSlice(k) {
    const a = this.slice.axes[k];
    const text = `${a.name} = ${fmt(a.breakpoints[this.slice.index[k]])}${a.unit ? ` ${a.unit}` : ""}`;
    this.slice.labels[k].textContent = `Slice at ${text}`;
    this.slice.inputs[k].setAttribute("aria-valuetext", text);
  }

  /** Another plot of the group moved to `value` of axis `name`: show the nearest breakpoint. */
  showSliceValue(name, value) {
    const k = this.slice.axes.findIndex((a) => a.name === name);
    if (k < 0) return;
    const i = nearestIndex(this.slice.axes[k].breakpoints, value);
    if (i === this.slice.index[k]) return;
    this.slice.index[k] = i;
    this.slice.inputs[k].value = String(i);
    this.describeSlice(k);
    if (this.last) this.render(this.last);
  }

  /** The 2-D frame of the chosen slice; the active cell only when it lies in that slice. */
  sliced(frame) {
    const idx = this.slice.index;
    const cut = (m) => (m ? sliceNested(m, idx) : m);
    const cell = frame.activeCell;
    const inSlice = (c) =>
      Array.isArray(c) && c.length === frame.axes.length && idx.every((k, n) => c[n + 2] === k);
    return {
      ...frame,
      axes: frame.axes.slice(0, 2),
      values: cut(frame.values),
      variances: cut(frame.variances),
      visits: cut(frame.visits),
      weights: cut(frame.weights),
      cellState: cut(frame.cellState),
      activeCell: inSlice(cell) ? cell.slice(0, 2) : null,
      outlines: frame.outlines?.filter(inSlice).map((c) => c.slice(0, 2)),
      sliceText: this.slice.axes
        .map((a, k) => `${a.name} = ${fmt(a.breakpoints[idx[k]])} ${a.unit ?? ""}`)
        .join("<br>"),
    };
  }

  /**
   * The heatmap's colour bar is plain HTML beside the plot: Plotly would redraw its own on
   * every frame (half the cost of a live frame); this one changes only with the range.
   */
  drawBar() {
    if (!this.bar) return;
    const size = this.el._fullLayout?._size;
    const [lo, hi] = this.extremes ?? [null, null];
    this.bar.draw({
      scale: this.scale(),
      range: this.range,
      log: this.kind === "variance",
      title: this.barTitle(),
      top: size?.t ?? 8,
      height: size?.h ?? null,
      clipped: {
        lo: this.range !== null && lo < this.range[0],
        hi: this.range !== null && hi > this.range[1],
      },
    });
  }

  /** What the colour scale measures, with its unit (the output's, squared for variances). */
  barTitle() {
    const u = this.unit || "-";
    if (this.kind === "variance") return `variance [${squared(u)}]`;
    if (this.kind === "visits") return "hits [samples]";
    if (this.kind === "deviation") return "z [σ]";
    // Value and difference maps: "name [unit]" where the view names the quantity (barLabel).
    return this.barLabel ? `${this.barLabel} [${u}]` : this.unit;
  }

  /** The colour range for values z: fixed, symmetric (diverging kinds), seeded or widened. */
  widen(z) {
    const extent = finiteExtent(z);
    if (!extent) return;
    const [lo, hi] = extent;
    this.extremes = extent;
    if (this.fixed && this.range) return;
    if (DIVERGING.has(this.kind)) {
      const m = Math.max(Math.abs(lo), Math.abs(hi)) || 1;
      this.range = [-m, m];
      return;
    }
    this.range = this.range
      ? widenRange(this.range, lo, hi)
      : niceRange(lo, hi, { log: this.kind === "variance" });
  }

  colorbar() {
    const t = theme();
    const base = {
      thickness: 12,
      outlinewidth: 0,
      len: 0.95,
      x: 1.01,
      xpad: 6,
      tickfont: { size: 11, color: t.text3 },
      title: {
        text: this.barTitle(),
        side: "right",
        font: { size: 11.5, color: t.text2 },
      },
    };
    if (this.kind === "variance" && this.range)
      Object.assign(base, decadeTicks(...this.range), { tickmode: "array" });
    return base;
  }

  scale() {
    if (this.kind === "variance") return SCALE_VARIANCE;
    if (this.kind === "visits") return SCALE_VALUE;
    if (DIVERGING.has(this.kind)) return SCALE_DIFF;
    return SCALE_VIRIDIS;
  }

  hover(axes, sliceText = "") {
    const [a0, a1] = axes;
    const head =
      `${a0.name} = %{x} ${a0.unit ?? ""}` +
      (a1 ? `<br>${a1.name} = %{y} ${a1.unit ?? ""}` : "") +
      (sliceText ? `<br>${sliceText}` : "");
    if (this.kind === "deviation") {
      return `${head}<br><b>z = %{customdata[0]}</b><br>weight in the merge = %{customdata[1]}<extra></extra>`;
    }
    const name = this.kind === "diff" ? (this.hoverName ?? `Δ ${this.label}`) : this.label;
    const u = this.unit || "-";
    const value = `${name} = %{customdata[0]} ${u}`;
    const lines =
      this.kind === "visits"
        ? [`<b>hits = %{customdata[2]} samples</b>`, value]
        : [`<b>${value}</b>`, `visits = %{customdata[2]} samples`];
    // Observers without a covariance (LPV) have no variance to show.
    if (this.last?.weights) lines.push("weight in the merge = %{customdata[1]}");
    else if (this.last?.variances) lines.push(`variance = %{customdata[1]} ${squared(u)}`);
    return `${head}<br>${lines.join("<br>")}%{customdata[3]}<extra></extra>`;
  }

  heatmap(frame, z) {
    const t = theme();
    const [a0, a1] = frame.axes;
    const x = a0.breakpoints;
    const y = a1.breakpoints;
    const data = [
      {
        type: "heatmap",
        x,
        y,
        z: transpose(z),
        customdata: cellText(frame),
        hovertemplate: this.hover(frame.axes, frame.sliceText),
        colorscale: this.scale(),
        zmin: this.range?.[0],
        zmax: this.range?.[1],
        zauto: false,
        showscale: false,
        xgap: this.gaps && x.length * y.length <= 400 ? 1 : 0,
        ygap: this.gaps && x.length * y.length <= 400 ? 1 : 0,
      },
    ];
    const over = this.overlay?.(frame, x, y) ?? {};
    if (over.traces) data.push(...over.traces);
    const trail = frame.trail;
    if (trail?.x?.length) {
      data.push(
        {
          type: "scatter",
          mode: "lines",
          name: TRACE.trail,
          x: trail.x,
          y: trail.y,
          hoverinfo: "skip",
          showlegend: false,
          line: { color: withAlpha(t.trail, 0.85), width: 1.5 },
        },
        {
          type: "scatter",
          mode: "markers",
          name: TRACE.point,
          x: [trail.x.at(-1)],
          y: [trail.y.at(-1)],
          showlegend: false,
          hovertemplate: `operating point<br>${a0.name} = %{x:.4g}<br>${a1.name} = %{y:.4g}<extra></extra>`,
          marker: { size: 11, color: t.trail, line: { color: t.trailEdge, width: 2 } },
        },
      );
    }
    const cell = frame.activeCell;
    if (cell && cell.length >= 2) {
      // The active cell is the table entry with the largest interpolation weight: its brick.
      const [x0, x1] = cellEdges(x, cell[0]);
      const [y0, y1] = cellEdges(y, cell[1]);
      data.push({
        type: "scatter",
        mode: "lines",
        name: TRACE.active,
        x: [x0, x1, x1, x0, x0],
        y: [y0, y0, y1, y1, y0],
        hoverinfo: "skip",
        showlegend: false,
        line: { color: t.activeCell, width: 2.5 },
      });
    }
    if (frame.outlines) {
      // One trace for every outlined cell: a closed brick each, separated by gaps (null).
      const ox = [];
      const oy = [];
      for (const [i, j] of frame.outlines) {
        const [x0, x1] = cellEdges(x, i);
        const [y0, y1] = cellEdges(y, j);
        ox.push(x0, x1, x1, x0, x0, null);
        oy.push(y0, y0, y1, y1, y0, null);
      }
      data.push({
        type: "scatter",
        mode: "lines",
        name: TRACE.outlines,
        x: ox,
        y: oy,
        hoverinfo: "skip",
        showlegend: false,
        connectgaps: false,
        line: { color: t.outline, width: 2.5 },
      });
    }
    const layout = baseLayout({
      xaxis: axis(withUnit(a0.name, a0.unit), {
        range: outerEdges(x),
        autorange: false,
        showgrid: false,
        zeroline: false,
      }),
      yaxis: axis(withUnit(a1.name, a1.unit), {
        range: outerEdges(y),
        autorange: false,
        showgrid: false,
        zeroline: false,
      }),
      margin: { l: 62, r: 8, t: 10, b: 46 },
      font: { family: t.font, size: 12, color: t.text2 },
      ...(over.shapes ? { shapes: over.shapes } : {}),
    });
    return [data, layout];
  }

  surface(frame, z) {
    const t = theme();
    const [a0, a1] = frame.axes;
    const data = [
      {
        type: "surface",
        x: a0.breakpoints,
        y: a1.breakpoints,
        z: transpose(z),
        customdata: cellText(frame),
        hovertemplate: this.hover(frame.axes, frame.sliceText),
        colorscale: this.scale(),
        cmin: this.range?.[0],
        cmax: this.range?.[1],
        cauto: false,
        colorbar: this.colorbar(),
        contours: { z: { show: false } },
        lighting: { ambient: 0.75, diffuse: 0.6, roughness: 0.6, specular: 0.15 },
      },
    ];
    const trail = frame.trail;
    if (trail?.x?.length) {
      const zs = trail.x.map((xv, k) => interp2(frame.axes, frame.values, xv, trail.y[k]));
      data.push({
        type: "scatter3d",
        mode: "lines",
        name: TRACE.trail,
        x: trail.x,
        y: trail.y,
        z: zs,
        hoverinfo: "skip",
        showlegend: false,
        line: { color: t.trail, width: 3 },
      });
      data.push({
        type: "scatter3d",
        mode: "markers",
        name: TRACE.point,
        x: [trail.x.at(-1)],
        y: [trail.y.at(-1)],
        z: [zs.at(-1)],
        showlegend: false,
        hoverinfo: "skip",
        marker: { size: 5, color: t.trail, line: { color: t.trailEdge, width: 1 } },
      });
    }
    const cell = frame.activeCell;
    if (cell && cell.length >= 2) {
      // The active cell's brick outlined on the surface, lifted a little so it stays visible.
      const [x0, x1] = cellEdges(a0.breakpoints, cell[0]);
      const [y0, y1] = cellEdges(a1.breakpoints, cell[1]);
      const lift = this.range ? (this.range[1] - this.range[0]) * 0.01 : 0;
      const xs = [];
      const ys = [];
      for (const [xa, ya, xb, yb] of [
        [x0, y0, x1, y0],
        [x1, y0, x1, y1],
        [x1, y1, x0, y1],
        [x0, y1, x0, y0],
      ]) {
        for (let k = 0; k <= 6; k += 1) {
          xs.push(xa + ((xb - xa) * k) / 6);
          ys.push(ya + ((yb - ya) * k) / 6);
        }
      }
      const zs = xs.map((xv, k) => interp2(frame.axes, frame.values, xv, ys[k]) + lift);
      data.push({
        type: "scatter3d",
        mode: "lines",
        name: TRACE.active,
        x: xs,
        y: ys,
        z: zs,
        hoverinfo: "skip",
        showlegend: false,
        line: { color: t.activeCell, width: 6 },
      });
    }
    const sceneAxis = (title) => ({
      title: { text: title, font: { size: 11, color: t.text2 } },
      gridcolor: t.grid,
      zerolinecolor: t.line,
      backgroundcolor: "rgba(0,0,0,0)",
      showbackground: false,
      tickfont: { size: 10, color: t.text3 },
    });
    const layout = baseLayout({
      margin: { l: 0, r: 0, t: 0, b: 0 },
      scene: {
        xaxis: sceneAxis(withUnit(a0.name, a0.unit)),
        yaxis: sceneAxis(withUnit(a1.name, a1.unit)),
        zaxis: { ...sceneAxis(withUnit(this.label, this.unit)), range: this.range ?? undefined },
        camera: { eye: { x: 1.55, y: -1.55, z: 0.95 } },
        aspectmode: "manual",
        aspectratio: { x: 1, y: 1, z: 0.6 },
      },
    });
    return [data, layout];
  }

  figure1d(frame, z) {
    const t = theme();
    const [a0] = frame.axes;
    const x = a0.breakpoints;
    const data = [];
    if (this.kind === "value" && frame.variances) {
      const sd = frame.variances.map((v) => (v === null ? null : Math.sqrt(Math.max(v, 0))));
      data.push(
        {
          x,
          y: z.map((v, k) => (v === null || sd[k] === null ? null : v + 2 * sd[k])),
          mode: "lines",
          line: { width: 0 },
          hoverinfo: "skip",
          showlegend: false,
        },
        {
          x,
          y: z.map((v, k) => (v === null || sd[k] === null ? null : v - 2 * sd[k])),
          mode: "lines",
          line: { width: 0 },
          fill: "tonexty",
          fillcolor: withAlpha(t.accent, 0.18),
          hoverinfo: "skip",
          name: "±2σ",
        },
      );
    }
    data.push({
      x,
      y: this.kind === "variance" ? (frame.variances ?? []) : z,
      mode: "lines+markers",
      name: this.label,
      customdata: cellText(frame),
      hovertemplate: this.hover(frame.axes),
      line: { color: DIVERGING.has(this.kind) ? t.danger : t.accent, width: 2 },
      marker: { size: 6 },
      type: DIVERGING.has(this.kind) ? "bar" : "scatter",
    });
    const trail = frame.trail;
    if (trail?.x?.length && this.kind === "value") {
      const xv = trail.x.at(-1);
      data.push({
        x: [xv],
        y: [interp1(x, z, xv)],
        mode: "markers",
        name: TRACE.point,
        showlegend: false,
        hoverinfo: "skip",
        marker: { size: 11, color: t.activeCell, line: { color: t.trailEdge, width: 2 } },
      });
    }
    // The y axis says what a 2-D map's colour bar would: hits, variance [unit²], z [σ].
    const yTitle =
      this.kind === "value" || this.kind === "diff"
        ? withUnit(this.barLabel ?? this.label, this.unit)
        : this.barTitle();
    const layout = baseLayout({
      xaxis: axis(withUnit(a0.name, a0.unit)),
      yaxis: axis(
        yTitle,
        this.kind === "variance"
          ? { type: "log" }
          : this.range
            ? { range: padRange(this.range) }
            : {},
      ),
      showlegend: false,
    });
    return [data, layout];
  }
}

/* ---------- helpers ---------- */

/** Hover text per cell: [value, variance, visits], already formatted, laid out like the z grid. */
function cellText(frame) {
  const { values, visits } = frame;
  // The second entry: a cell's weight in a merge where there are weights, else its variance.
  const variances = frame.weights ?? frame.variances;
  const cell = (i, j) => {
    const pick = (m) => (m ? (j === undefined ? m[i] : m[i]?.[j]) : null);
    const v = pick(values);
    const p = pick(variances);
    const n = pick(visits);
    const state = STATE_TEXT[pick(frame.cellState) ?? 0] ?? "";
    return [
      quick(v, 4),
      quick(p, 3),
      n === null || n === undefined ? "–" : String(Number(n.toPrecision(4))),
      state,
    ];
  };
  if (!Array.isArray(values[0])) return values.map((_, i) => cell(i));
  return values[0].map((_, j) => values.map((__, i) => cell(i, j)));
}

/** Hover line per cell state (frame.cellState, see views/run/trust-maps.js): 0 learned. */
const STATE_TEXT = [
  "",
  "<br><i>unvisited: not learned from data</i>",
  "<br><i>filled: changed without samples of its own</i>",
];

/** A unit squared: "ppm²", "(kg/s)²"; "-" stays "-". */
export function squared(unit) {
  if (!unit || unit === "-") return "-";
  return /[/·*\s]/.test(unit) ? `(${unit})²` : `${unit}²`;
}

/** Hover numbers, built for every cell of every frame: toPrecision, not the slow Intl path. */
function quick(v, digits) {
  if (v === null || v === undefined || Number.isNaN(v)) return "–";
  const abs = Math.abs(v);
  if (abs !== 0 && (abs >= 1e6 || abs < 1e-3)) return v.toExponential(digits - 1);
  return String(Number(v.toPrecision(digits)));
}
