/**
 * Pure arithmetic on look-up tables, as the map plots need it: cells and their edges,
 * breakpoint look-up and interpolation (the table's own bilinear model), slices of nested
 * tables, and colour ranges on "nice" bounds. No DOM, no Plotly: tests/frontend/js/ runs
 * these under Node.
 *
 * A table is `axes` ([{name, unit, breakpoints}], breakpoints ascending) and `values` nested
 * one array level per axis: values[i][j] is the cell at breakpoint i of axis 0, j of axis 1.
 */

/** Smallest positive value a log10 is taken of (zero variances stay finite on a log scale). */
const TINY = 1e-300;

/**
 * Edges [lo, hi] of the brick drawn for breakpoint k: half-way to its neighbours, and as far
 * beyond an outer breakpoint as the half-cell inside it (±1 for a single breakpoint).
 * k is clamped to the breakpoints.
 */
export function cellEdges(bp, k) {
  const i = Math.max(0, Math.min(bp.length - 1, k));
  const lo = i > 0 ? (bp[i - 1] + bp[i]) / 2 : bp[0] - (bp.length > 1 ? (bp[1] - bp[0]) / 2 : 1);
  const hi =
    i < bp.length - 1
      ? (bp[i] + bp[i + 1]) / 2
      : bp[i] + (bp.length > 1 ? (bp[i] - bp[i - 1]) / 2 : 1);
  return [lo, hi];
}

/** The span of all bricks: half a cell beyond the outer breakpoints (the plot's axis range). */
export function outerEdges(bp) {
  if (bp.length < 2) return [bp[0] - 1, bp[0] + 1];
  return [bp[0] - (bp[1] - bp[0]) / 2, bp.at(-1) + (bp.at(-1) - bp.at(-2)) / 2];
}

/** Index of the breakpoint nearest to v (the first of two equally near). */
export function nearestIndex(bp, v) {
  let best = 0;
  for (let i = 1; i < bp.length; i += 1) {
    if (Math.abs(bp[i] - v) < Math.abs(bp[best] - v)) best = i;
  }
  return best;
}

/**
 * The segment of x: [i, w] with bp[i] ≤ x ≤ bp[i+1] and weight w = (x − bp[i]) / (bp[i+1] − bp[i])
 * clamped to [0, 1], so points beyond the outer breakpoints take the edge value.
 */
export function locate(bp, x) {
  let i = 0;
  while (i < bp.length - 2 && x > bp[i + 1]) i += 1;
  const span = bp[i + 1] - bp[i] || 1;
  const w = Math.min(1, Math.max(0, (x - bp[i]) / span));
  return [i, w];
}

/** Linear interpolation of a 1-D table: (1 − w)·v[i] + w·v[i+1], clamped at the edges. */
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
  return (
    (1 - wx) * (1 - wy) * v(i, j) +
    wx * (1 - wy) * v(i + 1, j) +
    (1 - wx) * wy * v(i, j + 1) +
    wx * wy * v(i + 1, j + 1)
  );
}

/** m[i][j][k][l]… → m[i][j] at the given indices of the axes beyond the second (null if absent). */
export function sliceNested(m, idx) {
  if (!Array.isArray(m)) return m;
  return m.map((row) =>
    row.map((cell) => idx.reduce((c, k) => (Array.isArray(c) ? (c[k] ?? null) : null), cell)),
  );
}

/** values[i][j] (i along axis 0 = x) → z[j][i] (Plotly rows are y); a 1-D table as it is. */
export function transpose(m) {
  if (!Array.isArray(m[0])) return m;
  return m[0].map((_, j) => m.map((row) => row[j]));
}

/** log10 of every entry of a nested table (null stays null; zero becomes log10 of TINY). */
export function logNested(m) {
  if (!Array.isArray(m)) return m;
  return m.map((v) => {
    if (Array.isArray(v)) return logNested(v);
    return v === null ? null : Math.log10(Math.max(v, TINY));
  });
}

/** Element-wise b − a of two nested tables of the same shape (null where either is null). */
export function diffNested(a, b) {
  return a.map((row, i) => {
    if (Array.isArray(row)) return diffNested(row, b[i]);
    return row === null || b[i] === null ? null : b[i] - row;
  });
}

/** Whether two grids have the same axes count and breakpoints (to a relative 1e-9). */
export function sameGrid(axesA, axesB) {
  return (
    axesA.length === axesB.length &&
    axesA.every(
      (ax, k) =>
        ax.breakpoints.length === axesB[k].breakpoints.length &&
        ax.breakpoints.every(
          (v, i) => Math.abs(v - axesB[k].breakpoints[i]) <= 1e-9 * Math.max(1, Math.abs(v)),
        ),
    )
  );
}

/* ---------- colour ranges ---------- */

/** [lo, hi] of the finite numbers of a nested table, or null when it has none. */
export function finiteExtent(m) {
  let lo = Infinity;
  let hi = -Infinity;
  for (const v of [m].flat(Infinity)) {
    if (v === null || !Number.isFinite(v)) continue;
    if (v < lo) lo = v;
    if (v > hi) hi = v;
  }
  return lo <= hi ? [lo, hi] : null;
}

/** The smallest of 1, 2, 2.5, 5, 10 × 10^n at least span / count (a tick or rounding step). */
export function niceStep(span, count = 5) {
  const raw = span / count;
  const mag = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 2.5, 5, 10].map((m) => m * mag).find((st) => st >= raw) ?? raw;
}

/**
 * A colour range on "nice" bounds around [lo, hi] (whole decades for log-coded variances):
 * the same values always give the same range. An empty span is padded by 5 % (or ±1).
 */
export function niceRange(lo, hi, { log = false } = {}) {
  if (!(Number.isFinite(lo) && Number.isFinite(hi))) return null;
  if (log) {
    const a = Math.floor(lo);
    const b = Math.ceil(hi);
    return [a, b > a ? b : a + 1];
  }
  if (hi <= lo) {
    const pad = Math.abs(hi) * 0.05 || 1;
    lo -= pad;
    hi += pad;
  }
  const step = niceStep(hi - lo, 10);
  return [Math.floor(lo / step) * step, Math.ceil(hi / step) * step];
}

/**
 * Widen [r0, r1] to take in [lo, hi], in steps of a quarter of its span: a function of the
 * values only, so successive frames stay comparable. A range that holds them is returned as is.
 */
export function widenRange([r0, r1], lo, hi) {
  if (lo >= r0 && hi <= r1) return [r0, r1];
  const step = (r1 - r0) / 4;
  return [
    lo < r0 ? r0 - step * Math.ceil((r0 - lo) / step) : r0,
    hi > r1 ? r1 + step * Math.ceil((hi - r1) / step) : r1,
  ];
}

/** [lo, hi] padded by 8 % of its span on each side (±1 for an empty span). */
export function padRange([lo, hi]) {
  const d = (hi - lo) * 0.08 || 1;
  return [lo - d, hi + d];
}
