/**
 * Time series of a run kept in the browser: appended from live deltas, capped by halving
 * (min and max per bucket, so spikes stay) so long runs stay light, and looked up by the
 * names the API uses.
 */
import { SERIES_CAP } from "./constants.js";

/**
 * The series names the worker sends (app/runs/results.py, `RunResults.lines`, streamed by
 * app/runs/live.py; each line's role in full frames and REST /series): the
 * operating-point channels under their own names, "measured" (a table filter's output column),
 * the estimator's outputs ("prediction" and "residual" for table filters; "torque_nm", "theta1",
 * "theta2" and "pe_lambda_min" for torque estimators; an observer's states, e.g. "w_c_kg_s"),
 * and for every output scored against a simulated truth NAME_true and NAME_error (true − NAME).
 * An output named like an input channel comes as "output:NAME" (the EKF's p_im_pa).
 */
export const SERIES = Object.freeze({
  measured: "measured",
  prediction: "prediction",
  residual: "residual",
  lambdaMin: "pe_lambda_min",
});
const TRUE_SUFFIX = "_true";
const ERROR_SUFFIX = "_error";

export class SeriesStore {
  constructor(cap = SERIES_CAP) {
    this.cap = cap;
    this.data = {};
  }

  /** Replace everything (full frame or REST /series). Accepts {name: {unit, time?, values}} + shared time. */
  reset(series, sharedTime = null) {
    this.data = {};
    for (const [name, s] of Object.entries(series ?? {})) {
      const time = s.time ?? sharedTime ?? [];
      this.data[name] = { unit: s.unit ?? "", time: [...time], values: [...(s.values ?? [])] };
      this.trim(name);
    }
  }

  /** Append the new points of a delta. */
  append(series) {
    for (const [name, s] of Object.entries(series ?? {})) {
      const cur =
        this.data[name] ?? (this.data[name] = { unit: s.unit ?? "", time: [], values: [] });
      if (s.unit) cur.unit = s.unit;
      const t = s.time ?? [];
      const v = s.values ?? [];
      for (let k = 0; k < v.length; k += 1) {
        cur.time.push(t[k]);
        cur.values.push(v[k]);
      }
      this.trim(name);
    }
  }

  /** Past the cap, about halve the series by min/max per bucket (not every other point), so
   * a live run's spikes survive the thinning as they do the server's (app/io/decimate.py). */
  trim(name) {
    const s = this.data[name];
    if (s.values.length <= this.cap) return;
    const { x, y } = decimate(s.time, s.values, Math.floor(this.cap / 2));
    s.time = x;
    s.values = y;
  }

  /**
   * A series by quantity: "measured", "prediction", "residual", "lambdaMin" (exact names, see
   * SERIES), or of the first output scored against a truth: "estimate" (NAME), "truth"
   * (NAME_true) and "error" (NAME_error). Returns {name, unit, time, values} or null.
   */
  pick(quantity) {
    const get = (key) =>
      key && this.data[key]?.values?.length ? { name: key, ...this.data[key] } : null;
    if (quantity in SERIES) return get(SERIES[quantity]);
    const scored = this.scored();
    if (!scored) return null;
    if (quantity === "estimate") return get(scored);
    if (quantity === "truth") return get(`${scored}${TRUE_SUFFIX}`);
    if (quantity === "error") return get(`${scored}${ERROR_SUFFIX}`);
    return null;
  }

  /** The first output the worker scored against a truth (NAME with NAME_true and NAME_error). */
  scored() {
    for (const key of Object.keys(this.data)) {
      if (!key.endsWith(TRUE_SUFFIX)) continue;
      const name = key.slice(0, -TRUE_SUFFIX.length);
      if (this.data[name] && this.data[`${name}${ERROR_SUFFIX}`]) return name;
    }
    return null;
  }

  has(quantity) {
    return this.pick(quantity) !== null;
  }
}

/**
 * At most ~maxPoints points for drawing: per bucket the min and the max, in time order, so
 * spikes survive (a plain stride would drop them).
 */
export function decimate(time, values, maxPoints = 1600) {
  const n = values.length;
  if (n <= maxPoints) return { x: time, y: values };
  const bucket = Math.ceil(n / Math.floor(maxPoints / 2));
  const x = [];
  const y = [];
  for (let start = 0; start < n; start += bucket) {
    const end = Math.min(n, start + bucket);
    let lo = start;
    let hi = start;
    for (let k = start + 1; k < end; k += 1) {
      if (values[k] === null) continue;
      if (values[lo] === null || values[k] < values[lo]) lo = k;
      if (values[hi] === null || values[k] > values[hi]) hi = k;
    }
    for (const k of lo <= hi ? [lo, hi] : [hi, lo]) {
      if (k === lo && k === hi && x.length && x[x.length - 1] === time[k]) continue;
      x.push(time[k]);
      y.push(values[k]);
    }
  }
  return { x, y };
}
