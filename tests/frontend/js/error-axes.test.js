/**
 * Unit tests of frontend/js/error-axes.js and of SeriesStore.trim (series.js) under Node's
 * own runner (no browser): `node --test tests/frontend/js/error-axes.test.js`, run from
 * pytest by test_extremes.py.
 */
import assert from "node:assert/strict";
import { describe, test } from "node:test";

import {
  errorOf,
  groupByAxis,
  quantityOf,
  robustRange,
  stackAxes,
} from "../../../frontend/js/error-axes.js";
import { SeriesStore } from "../../../frontend/js/series.js";

const store = (series) => {
  const s = new SeriesStore();
  s.reset(series, [0, 1, 2]);
  return s;
};

describe("errorOf", () => {
  test("an LPV error is a MAF error in the series' own kg/s, not a torque error", () => {
    const e = errorOf(
      store({
        w_c_kg_s: { unit: "kg/s", values: [1, 2, 3] },
        w_c_kg_s_true: { unit: "kg/s", values: [1, 2, 3] },
        w_c_kg_s_error: { unit: "kg/s", values: [0, 0, 0] },
        residual: { unit: "kg/s", values: [0, 0, 0] },
      }),
    );
    assert.equal(e.title, "MAF error");
    assert.equal(e.unit, "kg/s");
  });

  test("a torque error in N·m, a residual in ppm, other outputs by name", () => {
    const torque = store({
      torque_nm: { unit: "N·m", values: [1, 2, 3] },
      torque_nm_true: { unit: "N·m", values: [1, 2, 3] },
      torque_nm_error: { unit: "N·m", values: [0, 0, 0] },
    });
    assert.deepEqual([errorOf(torque).title, errorOf(torque).unit], ["Torque error", "N·m"]);
    const table = store({ residual: { unit: "ppm", values: [1, 2, 3] } });
    assert.deepEqual([errorOf(table).title, errorOf(table).unit], ["Residual", "ppm"]);
    assert.equal(quantityOf("theta1", ""), "theta1");
    assert.equal(errorOf(store({ prediction: { unit: "ppm", values: [1] } })), null);
  });
});

describe("axes", () => {
  test("one group per title and unit: never two units on one axis", () => {
    const groups = groupByAxis([
      { title: "Residual", unit: "ppm", id: 1 },
      { title: "Torque error", unit: "N·m", id: 2 },
      { title: "Residual", unit: "ppm", id: 3 },
      { title: "Residual", unit: "kg/s", id: 4 },
    ]);
    assert.deepEqual(
      groups.map((g) => [g.title, g.unit, g.entries.map((e) => e.id)]),
      [
        ["Residual", "ppm", [1, 3]],
        ["Torque error", "N·m", [2]],
        ["Residual", "kg/s", [4]],
      ],
    );
    const axes = stackAxes(groups);
    assert.deepEqual(
      axes.map((a) => [a.yaxis, a.layoutKey]),
      [
        ["y", "yaxis"],
        ["y2", "yaxis2"],
        ["y3", "yaxis3"],
      ],
    );
    for (let i = 1; i < axes.length; i += 1) assert.ok(axes[i].domain[1] < axes[i - 1].domain[0]);
  });

  test("the robust range leaves a transient out and keeps the bulk", () => {
    const values = Array.from({ length: 1000 }, (_, k) => Math.sin(k / 10) * 10);
    values[0] = -1000;
    values[500] = null;
    const [lo, hi] = robustRange(values);
    assert.ok(lo > -1000 && lo < -9.9 && hi > 9.9 && hi < 13, `${lo} ${hi}`);
    const [group] = groupByAxis([{ title: "Torque error", unit: "N·m", values }]);
    assert.equal(stackAxes([group])[0].outside, 1);
    assert.equal(robustRange([null, NaN]), null);
    const [a, b] = robustRange([2, 2, 2]);
    assert.ok(a < 2 && b > 2);
  });
});

describe("SeriesStore past its cap", () => {
  test("a live spike survives the halving", () => {
    const s = new SeriesStore(1000);
    const n = 5000;
    const time = Array.from({ length: n }, (_, k) => k / 100);
    const values = time.map((t) => Math.sin(t));
    values[3333] = 64.7;
    for (let a = 0; a < n; a += 250) {
      s.append({
        e: { unit: "N·m", time: time.slice(a, a + 250), values: values.slice(a, a + 250) },
      });
    }
    const e = s.data.e;
    assert.ok(e.values.length <= 1000);
    assert.equal(Math.max(...e.values), 64.7);
    assert.equal(e.time[e.values.indexOf(64.7)], time[3333]);
    for (let k = 1; k < e.time.length; k += 1) assert.ok(e.time[k] > e.time[k - 1]);
  });
});
