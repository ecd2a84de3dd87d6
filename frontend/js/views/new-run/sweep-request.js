/**
 * What a sweep asks the API for: the settings to vary (each a list of values or a range drawn
 * from at random), the sample size and seed, and the metric the runs are ranked by. The rows
 * typed in the sweep form (`state.sweep`) are checked here, each problem next to its field.
 */
import { parseNumberList } from "../../dom.js";
import { sweepableKeys } from "../../schema-form.js";
import { hiddenKeys } from "./config-form.js";
import { fieldError } from "./state.js";

/** Ranking metrics offered per kind of estimator (the first is the default). */
const SWEEP_METRICS = Object.freeze({
  "table-filter": [
    "output_rmse",
    "rmse",
    "map_rmse",
    "max_abs_error",
    "mean_relative_error",
    "coverage",
  ],
  "maf-observer": ["map_rmse", "output_rmse", "rmse"],
  torque: ["ise", "mae", "sd", "rmse"],
});
/** Metrics where bigger is better (ranked highest first by default). */
const HIGHER_BETTER = new Set(["coverage"]);

export const metricsFor = (est) => SWEEP_METRICS[est?.kind] ?? ["output_rmse", "rmse"];

/** The default ranking order of a metric. */
export const orderFor = (metric) => (HIGHER_BETTER.has(metric) ? "max" : "min");

/** The numeric and enum settings of the estimator's schema a sweep may vary. */
export function sweepKeys(est) {
  return sweepableKeys(est.config_schema ?? {}, { hide: hiddenKeys(est) });
}

/** A list of values as typed: split on commas, semicolons and spaces. */
const splitValues = (raw) =>
  String(raw ?? "")
    .split(/[\s,;]+/)
    .filter(Boolean);

/** How many runs the sweep will start (null while a range waits for a sample size) and why. */
export function sweepSize(sw) {
  const samples = Number(sw.samples);
  if (String(sw.samples ?? "").trim() && Number.isInteger(samples) && samples > 0) {
    return {
      n: samples,
      text: `${samples} runs: random draws from the values and ranges (seed ${sw.seed || 0}).`,
    };
  }
  if (!sw.rows.length) return { n: 0, text: "Add a parameter to sweep." };
  if (sw.rows.some((r) => r.kind === "range")) {
    return { n: null, text: "A range is drawn from: give the number of samples." };
  }
  const sizes = sw.rows.map((r) => splitValues(r.values).length);
  const n = sizes.reduce((a, b) => a * b, 1);
  const s = n === 1 ? "" : "s";
  return { n, text: `${n} run${s}: the grid of ${sizes.join(" × ")} value${s}.` };
}

/** One row's part of `parameters`: {min, max, scale, integer} for a range, else its values. */
function readRow(row, info, field) {
  if (row.kind === "range") {
    const num = (prop) => {
      const raw = String(row[prop] ?? "").trim();
      const v = Number(raw);
      if (!raw || !Number.isFinite(v))
        throw fieldError(`${field}.${prop}`, `Give the ${prop} of the range.`);
      return v;
    };
    return {
      min: num("min"),
      max: num("max"),
      scale: row.scale === "log" ? "log" : "linear",
      integer: Boolean(row.integer) || info.type === "integer",
    };
  }
  const raw = String(row.values ?? "").trim();
  if (!raw) throw fieldError(field, "Give the values to try, e.g. 0.5, 1, 2.");
  if (info.type === "enum") {
    return splitValues(raw).map((v) => info.options.find((o) => String(o) === v) ?? v);
  }
  try {
    return parseNumberList(raw);
  } catch (err) {
    throw fieldError(field, err.message);
  }
}

/** A whole number ≥ `min` typed in `raw`, or undefined when it is empty. */
function readWhole(raw, min, field, message) {
  const text = String(raw ?? "").trim();
  if (!text) return undefined;
  const n = Number(text);
  if (!Number.isInteger(n) || n < min) throw fieldError(field, message);
  return n;
}

/** The sweep part of the request: parameters, sample size and seed, metric and order. */
export function readSweep(sw, est) {
  const keys = sweepKeys(est);
  const parameters = {};
  for (const row of sw.rows) {
    const info = keys.find((x) => x.key === row.key);
    const field = `parameters.${row.key}`;
    if (!info) throw fieldError(field, `${row.key} is not a setting of ${est.name}.`);
    if (row.key in parameters)
      throw fieldError(field, `${row.key} is swept twice: remove one of its rows.`);
    parameters[row.key] = readRow(row, info, field);
  }
  if (!Object.keys(parameters).length) throw fieldError("parameters", "Add a parameter to sweep.");
  const out = {
    parameters,
    metric: sw.metric || metricsFor(est)[0],
    order: sw.order === "max" ? "max" : "min",
  };
  const samples = readWhole(
    sw.samples,
    1,
    "samples",
    "Give a whole number of samples (at least 1), or leave it empty for the grid.",
  );
  if (samples !== undefined) out.samples = samples;
  const seed = readWhole(sw.seed, 0, "seed", "The seed is a whole number ≥ 0.");
  if (seed !== undefined) out.seed = seed;
  return out;
}

/** Remove a (dotted) key from a config object: the sweep sets it per run. */
export function dropKey(config, key) {
  const parts = key.split(".");
  const last = parts.pop();
  const node = parts.reduce((n, k) => (n && typeof n === "object" ? n[k] : undefined), config);
  if (node && typeof node === "object") delete node[last];
}
