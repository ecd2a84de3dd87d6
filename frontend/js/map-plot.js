/**
 * One look-up table drawn with Plotly: heatmap (or 3-D surface) of the values, of the
 * variances (diag P, log colour scale) or of a difference, with the operating-point trail
 * and the active cell over it. Colour ranges are fixed per plot (they only widen when a value
 * leaves them), so successive frames of a run are comparable.
 */
import { fmt, h, withUnit } from "./dom.js";
import {
  axis, baseLayout, decadeTicks, hasWebGL, purge, react, SCALE_DIFF, SCALE_VALUE, SCALE_VARIANCE, SCALE_VIRIDIS, theme,
} from "./plot.js";

const TINY = 1e-300;

export class MapPlot {
  /**
   * @param {HTMLElement} el
   * @param {{kind?: "value"|"variance"|"visits"|"diff", unit?: string, label?: string, mode?: "heatmap"|"surface"}} opts
   */
  constructor(el, { kind = "value", unit = "", label = "value", mode = "heatmap", gaps = true } = {}) {
    this.el = el;
    this.kind = kind;
    this.unit = unit;
    this.label = label;
    this.mode = mode;
    this.gaps = gaps;
    this.range = null;
    this.fixed = false;
    this.last = null;
    this.bar = null;
  }

  /** Pin the colour range (e.g. shared by several maps); null returns to widen-only. */
  setRange(range) {
    this.range = range ? [...range] : null;
    this.fixed = Boolean(range);
  }

  setMode(mode) {
    this.mode = mode === "surface" && hasWebGL() ? "surface" : "heatmap";
    if (this.last) this.render(this.last);
  }

  destroy() {
    purge(this.el);
    this.bar?.clear();
  }

  /**
   * @param {{axes, values, variances?, visits?, trail?: {x: number[], y: number[]}, activeCell?: number[]|null}} frame
   */
  render(frame) {
    this.last = frame;
    const { axes, values } = frame;
    if (!axes?.length || !values) return null;
    if (!this.bar && this.el.parentElement) this.bar = new ColorBar(this.el, this.kind); // before Plotly sizes the plot
    const z = this.kind === "variance" ? logNested(frame.variances ?? values)
      : this.kind === "visits" ? (frame.visits ?? values) : values;
    this.widen(z);
    if (axes.length === 1) {
      this.bar?.clear();
      return react(this.el, ...this.figure1d(frame, z));
    }
    if (this.mode === "surface" && this.kind === "value") {
      this.bar?.clear();
      return react(this.el, ...this.surface(frame, z));
    }
    const drawn = react(this.el, ...this.heatmap(frame, z));
    this.drawBar();
    return drawn;
  }

  /**
   * The heatmap's colour bar is plain HTML beside the plot: Plotly would redraw its own on
   * every frame (half the cost of a live frame); this one changes only with the range.
   */
  drawBar() {
    if (!this.bar) return;
    const size = this.el._fullLayout?._size;
    this.bar.draw({
      scale: this.scale(),
      range: this.range,
      log: this.kind === "variance",
      title: this.kind === "variance" || this.kind === "visits" ? this.kind : this.unit,
      top: size?.t ?? 8,
      height: size?.h ?? null,
    });
  }

  widen(z) {
    const flat = z.flat(Infinity).filter((v) => v !== null && Number.isFinite(v));
    if (!flat.length) return;
    let lo = Math.min(...flat);
    let hi = Math.max(...flat);
    if (this.kind === "diff") {
      if (this.fixed && this.range) return;
      const m = Math.max(Math.abs(lo), Math.abs(hi)) || 1;
      this.range = [-m, m];
      return;
    }
    if (this.fixed && this.range) return;
    if (hi === lo) {
      const pad = Math.abs(hi) * 0.05 || (this.kind === "variance" ? 0.5 : 1);
      lo -= pad;
      hi += pad;
    }
    if (!this.range) this.range = [lo, hi];
    else this.range = [Math.min(this.range[0], lo), Math.max(this.range[1], hi)];
  }

  colorbar() {
    const t = theme();
    const base = {
      thickness: 12, outlinewidth: 0, len: 0.95, x: 1.01, xpad: 6,
      tickfont: { size: 11, color: t.text3 },
      title: { text: this.kind === "variance" ? "variance" : this.unit || "", side: "right", font: { size: 11.5, color: t.text2 } },
    };
    if (this.kind === "variance" && this.range) Object.assign(base, decadeTicks(...this.range), { tickmode: "array" });
    return base;
  }

  scale() {
    if (this.kind === "variance") return SCALE_VARIANCE;
    if (this.kind === "visits") return SCALE_VALUE;
    if (this.kind === "diff") return SCALE_DIFF;
    return SCALE_VIRIDIS;
  }

  hover(axes) {
    const [a0, a1] = axes;
    const head = `${a0.name} = %{x} ${a0.unit ?? ""}` + (a1 ? `<br>${a1.name} = %{y} ${a1.unit ?? ""}` : "");
    const name = this.kind === "diff" ? `Δ ${this.label}` : this.label;
    return `${head}<br><b>${name} = %{customdata[0]} ${this.unit}</b><br>variance = %{customdata[1]}<br>visits = %{customdata[2]}<extra></extra>`;
  }

  heatmap(frame, z) {
    const t = theme();
    const [a0, a1] = frame.axes;
    const x = a0.breakpoints;
    const y = a1.breakpoints;
    const data = [
      {
        type: "heatmap",
        x, y,
        z: transpose(z),
        customdata: cellText(frame),
        hovertemplate: this.hover(frame.axes),
        colorscale: this.scale(),
        zmin: this.range?.[0], zmax: this.range?.[1],
        zauto: false,
        showscale: false,
        xgap: this.gaps && x.length * y.length <= 400 ? 1 : 0,
        ygap: this.gaps && x.length * y.length <= 400 ? 1 : 0,
      },
    ];
    const trail = frame.trail;
    if (trail?.x?.length) {
      data.push(
        { type: "scatter", mode: "lines", x: trail.x, y: trail.y, hoverinfo: "skip", showlegend: false,
          line: { color: "rgba(255,255,255,0.85)", width: 1.5 } },
        { type: "scatter", mode: "markers", x: [trail.x.at(-1)], y: [trail.y.at(-1)], showlegend: false,
          hovertemplate: `operating point<br>${a0.name} = %{x:.4g}<br>${a1.name} = %{y:.4g}<extra></extra>`,
          marker: { size: 11, color: "#ffffff", line: { color: "#0b0e13", width: 2 } } },
      );
    }
    const cell = frame.activeCell;
    if (cell && cell.length >= 2) {
      // The active cell is the table entry with the largest interpolation weight: its brick.
      const [x0, x1] = brick(x, cell[0]);
      const [y0, y1] = brick(y, cell[1]);
      data.push({ type: "scatter", mode: "lines", x: [x0, x1, x1, x0, x0], y: [y0, y0, y1, y1, y0],
        hoverinfo: "skip", showlegend: false, line: { color: "#22d3ee", width: 2.5 } });
    }
    const layout = baseLayout({
      xaxis: axis(withUnit(a0.name, a0.unit), { range: edges(x), autorange: false, showgrid: false, zeroline: false }),
      yaxis: axis(withUnit(a1.name, a1.unit), { range: edges(y), autorange: false, showgrid: false, zeroline: false }),
      margin: { l: 62, r: 8, t: 10, b: 46 },
      font: { family: t.font, size: 12, color: t.text2 },
    });
    return [data, layout];
  }

  surface(frame, z) {
    const t = theme();
    const [a0, a1] = frame.axes;
    const data = [
      {
        type: "surface",
        x: a0.breakpoints, y: a1.breakpoints, z: transpose(z),
        customdata: cellText(frame),
        hovertemplate: this.hover(frame.axes),
        colorscale: this.scale(), cmin: this.range?.[0], cmax: this.range?.[1], cauto: false,
        colorbar: this.colorbar(),
        contours: { z: { show: false } },
        lighting: { ambient: 0.75, diffuse: 0.6, roughness: 0.6, specular: 0.15 },
      },
    ];
    const trail = frame.trail;
    if (trail?.x?.length) {
      const zs = trail.x.map((xv, k) => interp2(frame.axes, frame.values, xv, trail.y[k]));
      data.push({ type: "scatter3d", mode: "lines", x: trail.x, y: trail.y, z: zs, hoverinfo: "skip", showlegend: false,
        line: { color: "#ffffff", width: 3 } });
      data.push({ type: "scatter3d", mode: "markers", x: [trail.x.at(-1)], y: [trail.y.at(-1)], z: [zs.at(-1)],
        showlegend: false, hoverinfo: "skip", marker: { size: 5, color: "#22d3ee" } });
    }
    const sceneAxis = (title) => ({
      title: { text: title, font: { size: 11, color: t.text2 } }, gridcolor: t.grid, zerolinecolor: t.line,
      backgroundcolor: "rgba(0,0,0,0)", showbackground: false, tickfont: { size: 10, color: t.text3 },
    });
    const layout = baseLayout({
      margin: { l: 0, r: 0, t: 0, b: 0 },
      scene: {
        xaxis: sceneAxis(withUnit(a0.name, a0.unit)),
        yaxis: sceneAxis(withUnit(a1.name, a1.unit)),
        zaxis: { ...sceneAxis(withUnit(this.label, this.unit)), range: this.range ?? undefined },
        camera: { eye: { x: 1.55, y: -1.55, z: 0.95 } },
        aspectmode: "manual", aspectratio: { x: 1, y: 1, z: 0.6 },
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
        { x, y: z.map((v, k) => (v === null || sd[k] === null ? null : v + 2 * sd[k])), mode: "lines",
          line: { width: 0 }, hoverinfo: "skip", showlegend: false },
        { x, y: z.map((v, k) => (v === null || sd[k] === null ? null : v - 2 * sd[k])), mode: "lines",
          line: { width: 0 }, fill: "tonexty", fillcolor: "rgba(59,130,246,0.18)", hoverinfo: "skip", name: "±2σ" },
      );
    }
    data.push({
      x, y: this.kind === "variance" ? (frame.variances ?? []) : z, mode: "lines+markers", name: this.label,
      customdata: cellText(frame), hovertemplate: this.hover(frame.axes),
      line: { color: this.kind === "diff" ? t.danger : t.accent, width: 2 }, marker: { size: 6 },
      type: this.kind === "diff" ? "bar" : "scatter",
    });
    const trail = frame.trail;
    if (trail?.x?.length && this.kind === "value") {
      const xv = trail.x.at(-1);
      data.push({ x: [xv], y: [interp1(x, z, xv)], mode: "markers", showlegend: false, hoverinfo: "skip",
        marker: { size: 11, color: "#22d3ee", line: { color: "#0b0e13", width: 2 } } });
    }
    const layout = baseLayout({
      xaxis: axis(withUnit(a0.name, a0.unit)),
      yaxis: axis(this.kind === "variance" ? "variance" : withUnit(this.label, this.unit),
        this.kind === "variance" ? { type: "log" } : this.range ? { range: pad(this.range) } : {}),
      showlegend: false,
    });
    return [data, layout];
  }
}

/* ---------- helpers ---------- */

function pad([lo, hi]) {
  const d = (hi - lo) * 0.08 || 1;
  return [lo - d, hi + d];
}

/** Edges of the heatmap brick drawn for breakpoint k (half-way to its neighbours). */
function brick(bp, k) {
  const i = Math.max(0, Math.min(bp.length - 1, k));
  const lo = i > 0 ? (bp[i - 1] + bp[i]) / 2 : bp[0] - (bp.length > 1 ? (bp[1] - bp[0]) / 2 : 1);
  const hi = i < bp.length - 1 ? (bp[i] + bp[i + 1]) / 2 : bp[i] + (bp.length > 1 ? (bp[i] - bp[i - 1]) / 2 : 1);
  return [lo, hi];
}

/** Plot range reaching half a cell beyond the outer breakpoints. */
function edges(bp) {
  if (bp.length < 2) return [bp[0] - 1, bp[0] + 1];
  return [bp[0] - (bp[1] - bp[0]) / 2, bp.at(-1) + (bp.at(-1) - bp.at(-2)) / 2];
}

/** values[i][j] (i along axis 0 = x) → z[j][i] (Plotly rows are y). */
export function transpose(m) {
  if (!Array.isArray(m[0])) return m;
  return m[0].map((_, j) => m.map((row) => row[j]));
}

export function logNested(m) {
  return Array.isArray(m) ? m.map((v) => (Array.isArray(v) ? logNested(v) : v === null ? null : Math.log10(Math.max(v, TINY)))) : m;
}

/** Hover text per cell: [value, variance, visits], already formatted, laid out like the z grid. */
function cellText(frame) {
  const { values, variances, visits } = frame;
  const cell = (i, j) => {
    const pick = (m) => (m ? (j === undefined ? m[i] : m[i]?.[j]) : null);
    const v = pick(values);
    const p = pick(variances);
    const n = pick(visits);
    return [quick(v, 4), quick(p, 3), n === null || n === undefined ? "–" : String(Math.round(n))];
  };
  if (!Array.isArray(values[0])) return values.map((_, i) => cell(i));
  return values[0].map((_, j) => values.map((__, i) => cell(i, j)));
}

/** Hover numbers, built for every cell of every frame: toPrecision, not the slow Intl path. */
function quick(v, digits) {
  if (v === null || v === undefined || Number.isNaN(v)) return "–";
  const abs = Math.abs(v);
  if (abs !== 0 && (abs >= 1e6 || abs < 1e-3)) return v.toExponential(digits - 1);
  return String(Number(v.toPrecision(digits)));
}

function locate(bp, x) {
  let i = 0;
  while (i < bp.length - 2 && x > bp[i + 1]) i += 1;
  const span = bp[i + 1] - bp[i] || 1;
  const w = Math.min(1, Math.max(0, (x - bp[i]) / span));
  return [i, w];
}

export function interp1(bp, v, x) {
  if (bp.length < 2) return v[0];
  const [i, w] = locate(bp, x);
  return (1 - w) * v[i] + w * v[i + 1];
}

/** Bilinear interpolation of a 2-D table (the table's own model), clamped at the edges. */
export function interp2(axes, values, x, y) {
  const [i, wx] = locate(axes[0].breakpoints, x);
  const [j, wy] = locate(axes[1].breakpoints, y);
  const v = (a, b) => values[Math.min(a, values.length - 1)][Math.min(b, values[0].length - 1)];
  return (1 - wx) * (1 - wy) * v(i, j) + wx * (1 - wy) * v(i + 1, j) + (1 - wx) * wy * v(i, j + 1) + wx * wy * v(i + 1, j + 1);
}

/** Element-wise b − a of two nested tables of the same shape (null where either is null). */
export function diffNested(a, b) {
  return a.map((row, i) => (Array.isArray(row) ? diffNested(row, b[i]) : row === null || b[i] === null ? null : b[i] - row));
}

export function sameGrid(axesA, axesB) {
  return axesA.length === axesB.length && axesA.every((ax, k) =>
    ax.breakpoints.length === axesB[k].breakpoints.length &&
    ax.breakpoints.every((v, i) => Math.abs(v - axesB[k].breakpoints[i]) <= 1e-9 * Math.max(1, Math.abs(v))));
}

/* ---------- HTML colour bar ---------- */

class ColorBar {
  constructor(plotEl, kind) {
    const wrap = h("div", { class: "mapplot" });
    plotEl.parentElement.insertBefore(wrap, plotEl);
    wrap.append(plotEl);
    this.el = h("div", { class: "cbar", "aria-hidden": "true", dataset: { colorbarFor: plotEl.dataset.plot ?? kind } });
    wrap.append(this.el);
    this.key = "";
  }

  clear() {
    this.el.replaceChildren();
    this.key = "";
  }

  draw({ scale, range, log, title, top, height }) {
    if (!range) return;
    const key = JSON.stringify([range, log, title, top, height, scale[0][1]]);
    if (key === this.key) return;
    this.key = key;
    const [lo, hi] = range;
    const ticks = log ? logTicks(lo, hi) : linearTicks(lo, hi);
    const stops = scale.map(([p, c]) => `${c} ${(p * 100).toFixed(1)}%`).join(", ");
    const frac = (v) => (hi > lo ? (v - lo) / (hi - lo) : 0.5);
    const grad = h("div", { class: "cbar-grad", style: { background: `linear-gradient(to top, ${stops})`,
      top: `${top}px`, height: height ? `${height}px` : "80%" } },
      ticks.filter((t) => t.v >= lo - 1e-12 && t.v <= hi + 1e-12).map((t) =>
        h("span", { class: "cbar-tick", style: { bottom: `${(100 * frac(t.v)).toFixed(2)}%` } }, t.label)));
    this.el.replaceChildren(h("div", { class: "cbar-title" }, title || "\u00a0"), grad);
  }
}

function niceStep(span, count = 5) {
  const raw = span / count;
  const mag = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 2.5, 5, 10].map((m) => m * mag).find((st) => st >= raw) ?? raw;
}

function linearTicks(lo, hi) {
  if (!(hi > lo)) return [{ v: lo, label: fmt(lo, 3) }];
  const step = niceStep(hi - lo);
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) {
    const r = Math.abs(v) < step * 1e-9 ? 0 : Number(v.toPrecision(12));
    out.push({ v: r, label: fmt(r, 3) });
  }
  return out;
}

function logTicks(lo, hi) {
  const { tickvals, ticktext } = decadeTicks(lo, hi);
  return tickvals.map((v, k) => ({ v, label: ticktext[k] }));
}
