/**
 * What each run metric is: a name that says it (max |e|, mean |e|: the torque paper's "MAE"
 * is a maximum) and the formula behind it, shown as the metric card's tooltip. Sources:
 * estimation/metrics.py (map, output and torque metrics; TQ (60)–(62) over the 5–30 s window),
 * estimation/holdout.py (held-out error, NIS; docs/tuning.md), app/runs/results.py (coverage).
 */
import { fmt, h, metricLabel } from "./dom.js";

/** Names the run view uses instead of the shared labels (dom.js metricLabel). */
const NAMES = {
  mae: "Max |e|",
  max_abs_error: "Max |e|",
  sd: "SD of e",
  visited_cells: "Visited cells",
};

/** e: the error true − estimated (torque τ̃ = τ − τ̂); θ̂, θ: estimated and true map cells. */
const FORMULAS = {
  ise: "ISE = ∫ τ̃² dt over the scoring window (5–30 s of the record), τ̃ = τ − τ̂ (TQ (60))",
  mae: "max |τ̃| over the scoring window (5–30 s), τ̃ = τ − τ̂: the torque paper's “MAE” (TQ (61)) is a maximum, not a mean",
  sd: "standard deviation of τ̃ = τ − τ̂ over the scoring window (5–30 s) (TQ (62))",
  output_rmse:
    "√(mean r²) over the accepted samples, r = y − ŷ the residual of the measured output",
  map_rmse: "√(mean (θ̂_c − θ_c)²) over the visited cells c (≥ 1 sample of interpolation weight)",
  max_abs_error: "max |θ̂_c − θ_c| over the visited cells c (≥ 1 sample of interpolation weight)",
  mean_relative_error:
    "Σ_k |T̂(υ_k) − T(υ_k)| / Σ_k |T(υ_k)| along the trajectory υ_k (LPV §4, docs/algorithms.md §3)",
  coverage: "share of cells with ≥ 1 sample of interpolation weight: Σ_k w_k,c ≥ 1",
  visited_cells: "number of cells with ≥ 1 sample of interpolation weight",
  "holdout:rmse": "√(mean (y − ŷ)²) on the last 30 % of the log, the map fitted on the first 70 %",
  "holdout:mae": "mean |y − ŷ| on the last 30 % of the log, the map fitted on the first 70 %",
  "holdout:max_abs_error":
    "max |y − ŷ| on the last 30 % of the log, the map fitted on the first 70 %",
  "holdout:base_rmse": "√(mean (y − ŷ)²) of the starting map on the last 30 % of the log",
  "holdout:base_mae": "mean |y − ŷ| of the starting map on the last 30 % of the log",
  "holdout:base_max_abs_error": "max |y − ŷ| of the starting map on the last 30 % of the log",
  "holdout:samples": "samples in the held-out last 30 % of the log",
  "nis:mean":
    "mean of NIS_k = ν_k² / S_k (innovation ν, its predicted variance S); ≈ 1 when the noises are right",
  "nis:in_band": "share of samples whose NIS lies in the 95 % band of χ²(1)",
  "nis:innovation_mean": "mean innovation ν = y − ŷ before the update; ≈ 0 when unbiased",
  "nis:mean_band_low": "lower end of the 95 % band of the mean NIS, χ²(N)/N over N samples",
  "nis:mean_band_high": "upper end of the 95 % band of the mean NIS, χ²(N)/N over N samples",
  "residual:mean":
    "mean output error r = y − ŷ of the fit pass (the LPV observer has no covariance, so no NIS)",
  "residual:rms": "√(mean r²) of the fit pass's output error r = y − ŷ",
  "residual:mean_over_rms": "mean r / √(mean r²): near 0 when the output error is unbiased",
  "residual:autocorr_lag1": "lag-1 autocorrelation of r: near 0 when r is white",
  "residual:autocorr_band": "95 % band of a white sequence's lag-1 autocorrelation, 1.96/√N",
};

/** The card name of metric `key`. */
export function metricName(key) {
  return NAMES[key] ?? metricLabel(key);
}

/**
 * The card name as a node: the metric cards set their names in capitals, which would turn the
 * error e into E; the symbols keep their case.
 */
export function metricNameNode(key) {
  const parts = metricName(key).split(/(\|e\||θ̂|τ̃)/);
  return parts.map((p, k) => (k % 2 ? h("span", { style: { textTransform: "none" } }, p) : p));
}

/**
 * The formula of metric `key` (a tooltip), or "". `rmse` is the map's over visited cells,
 * unless the run also has map_rmse: then it is the scored output's along the log.
 */
export function metricFormula(key, metrics = {}) {
  if (key === "rmse") {
    return "map_rmse" in metrics
      ? "√(mean e²) of the scored output along the log, e = true − estimated"
      : FORMULAS.map_rmse;
  }
  if (/^(holdout|nis):not_applicable:/.test(key)) {
    return "not computed: the estimator has no honest form of this check (docs/tuning.md)";
  }
  const other = /^(holdout|nis):(.+)_(rmse|mean)$/.exec(key);
  if (!FORMULAS[key] && other) {
    return other[1] === "holdout"
      ? `√(mean (y − ŷ)²) of output ${other[2]} on the last 30 % of the log, fitted on the first 70 %`
      : `mean NIS of output ${other[2]}; ≈ 1 when the noises are right`;
  }
  return FORMULAS[key] ?? "";
}

/** Metrics that are shares (0–1), shown in per cent everywhere: coverage, NIS in band, and
 * the mean relative error Σ|T̂ − T| / Σ|T| (a ratio, so 0.0907 reads 9.07 %). */
export const PERCENT_METRICS = new Set(["coverage", "nis:in_band", "mean_relative_error"]);

/** A metric's value for a table or card: shares in per cent, anything else as fmt gives it. */
export function fmtMetric(key, value) {
  return PERCENT_METRICS.has(key) && typeof value === "number"
    ? `${fmt(value * 100, 3)} %`
    : fmt(value);
}

/**
 * The unit of metric `key` of a run whose scored output is in `outputUnit`: "%" for shares,
 * the output's unit for errors (rmse, max |e|, held-out MAE, innovation mean), a torque
 * estimator's ISE in (unit)²·s, "s" for compute time, else "".
 */
export function metricUnit(key, outputUnit, { torque = false } = {}) {
  if (PERCENT_METRICS.has(key)) return "%";
  if (key === "run_s") return "s";
  if (torque && (key === "mae" || key === "sd")) return outputUnit;
  if (torque && key === "ise") return outputUnit === "N·m" ? "N²·m²·s" : `(${outputUnit})²·s`;
  if (/rmse|max_abs|^holdout:.*mae$|^nis:innovation_mean$|^residual:(mean|rms)$/.test(key))
    return outputUnit;
  return "";
}
