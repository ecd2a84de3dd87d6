/**
 * The error plot of the Compare view, as plain data (no DOM, no Plotly; Node-testable):
 * which series of a run is its error and what it is called, one y-axis per quantity and unit
 * (stacked subplots on a shared time axis, never two units on one axis), and a robust y-range
 * per axis so a start-up transient does not flatten the errors that matter.
 */

/** Scored outputs by name (estimation/: torque estimators' torque_nm, the LPV/EKF W_c). */
const QUANTITY_BY_NAME = Object.freeze({ torque_nm: "Torque", w_c_kg_s: "MAF" });
/** Otherwise by the series' unit; failing both, the output's own name. */
const QUANTITY_BY_UNIT = Object.freeze({ "N·m": "Torque", Nm: "Torque", "kg/s": "Mass flow" });

/** The quantity an output measures, for a title: "Torque", "MAF", else its name. */
export function quantityOf(name, unit) {
  return QUANTITY_BY_NAME[name] ?? QUANTITY_BY_UNIT[unit] ?? name ?? "Output";
}

/**
 * A run's error series from a SeriesStore: NAME_error (true − NAME) of its first scored
 * output, else the residual (measured − predicted). {title, unit, hint, time, values} or null;
 * the unit is the series' own (never inferred from the estimator family).
 */
export function errorOf(store) {
  const err = store.pick("error");
  if (err) {
    const title = `${quantityOf(store.scored(), err.unit)} error`;
    return { ...err, title, hint: "true − estimated" };
  }
  const res = store.pick("residual");
  if (res) return { ...res, title: "Residual", hint: "measured − predicted" };
  return null;
}

/**
 * Errors grouped by axis: one group per (title, unit), in first-seen order. `entries` are
 * {title, unit, ...}; returns [{key, title, unit, entries}].
 */
export function groupByAxis(entries) {
  const groups = new Map();
  for (const e of entries) {
    const unit = e.unit ?? "";
    const key = `${e.title}\u0000${unit}`;
    if (!groups.has(key)) groups.set(key, { key, title: e.title, unit, entries: [] });
    groups.get(key).entries.push(e);
  }
  return [...groups.values()];
}

/** Quantile q ∈ [0, 1] of sorted finite numbers (linear between neighbours). */
function sortedQuantile(xs, q) {
  const pos = (xs.length - 1) * q;
  const lo = Math.floor(pos);
  const hi = Math.ceil(pos);
  return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo);
}

/**
 * The y-range [lo, hi] that shows the bulk of `values`: the `low`–`high` quantiles (1st–99th
 * percentile) widened by `margin` of their span on each side. Single-sample extremes (a t = 0
 * transient, a spike) fall outside; "Full range" shows them. Null without finite values.
 */
export function robustRange(values, { low = 0.01, high = 0.99, margin = 0.1 } = {}) {
  const xs = values.filter((v) => v !== null && Number.isFinite(v)).sort((a, b) => a - b);
  if (!xs.length) return null;
  const a = sortedQuantile(xs, low);
  const b = sortedQuantile(xs, high);
  const span = b - a > 0 ? b - a : Math.max(Math.abs(a), 1e-9);
  return [a - margin * span, b + margin * span];
}

/** Values outside `range` (how many the robust scale leaves off the plot). */
export function countOutside(values, range) {
  if (!range) return 0;
  return values.filter((v) => v !== null && Number.isFinite(v) && (v < range[0] || v > range[1]))
    .length;
}

/**
 * Stacked subplots for `groups` (top to bottom), sharing one time axis: the axis ids of each
 * group ("y", "y2", …) and, per group, its y-axis domain and robust range.
 * Returns [{yaxis: "y2", layoutKey: "yaxis2", domain: [lo, hi], range, outside}], `outside`
 * the number of plotted values beyond the robust range.
 */
export function stackAxes(groups, { gap = 0.1 } = {}) {
  const n = groups.length;
  const height = (1 - gap * (n - 1)) / n;
  return groups.map((g, i) => {
    const top = 1 - i * (height + gap);
    const suffix = i === 0 ? "" : String(i + 1);
    const values = g.entries.flatMap((e) => e.values ?? []);
    const range = robustRange(values);
    return {
      yaxis: `y${suffix}`,
      layoutKey: `yaxis${suffix}`,
      domain: [Math.max(0, top - height), Math.min(1, top)],
      range,
      outside: countOutside(values, range),
    };
  });
}
