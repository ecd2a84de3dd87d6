/**
 * What each run metric is: a name that says it (max |e|, mean |e|: the torque paper's "MAE"
 * is a maximum) and the formula behind it, shown as the metric card's tooltip. Sources:
 * estimation/metrics.py (map, output and torque metrics; TQ (60)–(62) over the 5–30 s window),
 * estimation/holdout.py (held-out error, NIS; docs/tuning.md), app/runs/results.py (coverage).
 */
import { h, metricLabel } from "./dom.js";

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
  return FORMULAS[key] ?? "";
}
