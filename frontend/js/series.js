/**
 * Time series of a run kept in the browser: appended from live deltas, capped by halving
 * (every other point) so long runs stay light, and looked up by the names the API uses.
 */
import { SERIES_CAP } from "./constants.js";

/** Candidate names per quantity, first match wins. */
export const SERIES_KEYS = Object.freeze({
  measured: ["measured", "y_measured", "y", "output"],
  prediction: ["prediction", "predicted", "y_pred", "y_hat"],
  residual: ["residual", "innovation", "e"],
  torqueTrue: ["torque_nm_true", "torque_true"],
  torqueEst: ["torque_nm", "torque_est"],
  error: ["torque_nm_error", "error", "torque_error"],
  lambdaMin: ["pe_lambda_min", "lambda_min"],
});

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
      const cur = this.data[name] ?? (this.data[name] = { unit: s.unit ?? "", time: [], values: [] });
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

  trim(name) {
    const s = this.data[name];
    if (s.values.length <= this.cap) return;
    s.time = s.time.filter((_, k) => k % 2 === 0);
    s.values = s.values.filter((_, k) => k % 2 === 0);
  }

  /**
   * The first series present for a quantity in SERIES_KEYS, with its name. Scored outputs
   * other than torque follow the same pattern (NAME, NAME_true, NAME_error = true − NAME).
   */
  pick(quantity) {
    for (const key of SERIES_KEYS[quantity] ?? [quantity]) {
      if (this.data[key]?.values?.length) return { name: key, ...this.data[key] };
    }
    const suffix = { torqueTrue: "_true", error: "_error" }[quantity];
    const scored = Object.keys(this.data).find((k) => k.endsWith("_true") && this.data[k].values?.length);
    if (suffix && scored) {
      const key = scored.replace(/_true$/, suffix);
      if (this.data[key]?.values?.length) return { name: key, ...this.data[key] };
    }
    if (quantity === "torqueEst" && scored) {
      const key = scored.replace(/_true$/, "");
      if (this.data[key]?.values?.length) return { name: key, ...this.data[key] };
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
