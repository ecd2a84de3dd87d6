/**
 * Unit tests of frontend/js/grid-math.js under Node's own runner (no browser):
 * `node --test tests/frontend/js/grid-math.test.js`, run from pytest by test_grid_math.py.
 */
import assert from "node:assert/strict";
import { describe, test } from "node:test";

import {
  cellEdges,
  diffNested,
  finiteExtent,
  interp1,
  interp2,
  locate,
  logNested,
  nearestIndex,
  niceRange,
  niceStep,
  outerEdges,
  padRange,
  sameGrid,
  sliceNested,
  transpose,
  widenRange,
} from "../../../frontend/js/grid-math.js";

/** Seeded uniform numbers in [0, 1) (a 32-bit LCG): the same draws on every run. */
function rng(seed = 0) {
  let s = seed >>> 0;
  return () => {
    s = (Math.imul(s, 1664525) + 1013904223) >>> 0;
    return s / 2 ** 32;
  };
}

const close = (actual, expected, tol = 1e-12) =>
  assert.ok(
    Math.abs(actual - expected) <= tol * Math.max(1, Math.abs(expected)),
    `${actual} != ${expected}`,
  );

describe("cells", () => {
  const bp = [0, 1, 3, 7];

  test("cellEdges are half-way to the neighbours, mirrored at the ends", () => {
    assert.deepEqual(cellEdges(bp, 0), [-0.5, 0.5]);
    assert.deepEqual(cellEdges(bp, 1), [0.5, 2]);
    assert.deepEqual(cellEdges(bp, 2), [2, 5]);
    assert.deepEqual(cellEdges(bp, 3), [5, 9]);
  });

  test("cellEdges clamp the index and give ±1 around a single breakpoint", () => {
    assert.deepEqual(cellEdges(bp, -3), cellEdges(bp, 0));
    assert.deepEqual(cellEdges(bp, 99), cellEdges(bp, 3));
    assert.deepEqual(cellEdges([5], 0), [4, 6]);
  });

  test("the bricks tile outerEdges without gaps", () => {
    const [lo, hi] = outerEdges(bp);
    assert.equal(lo, cellEdges(bp, 0)[0]);
    assert.equal(hi, cellEdges(bp, bp.length - 1)[1]);
    for (let k = 1; k < bp.length; k += 1)
      assert.equal(cellEdges(bp, k - 1)[1], cellEdges(bp, k)[0]);
    assert.deepEqual(outerEdges([2]), [1, 3]);
  });

  test("nearestIndex picks the closest breakpoint, the first of a tie", () => {
    assert.equal(nearestIndex(bp, -10), 0);
    assert.equal(nearestIndex(bp, 2.1), 2);
    assert.equal(nearestIndex(bp, 2), 1);
    assert.equal(nearestIndex(bp, 100), 3);
  });

  test("locate brackets x and clamps the weight beyond the ends", () => {
    assert.deepEqual(locate(bp, 2), [1, 0.5]);
    assert.deepEqual(locate(bp, 5), [2, 0.5]);
    assert.deepEqual(locate(bp, -1), [0, 0]);
    assert.deepEqual(locate(bp, 70), [2, 1]);
  });
});

describe("interpolation", () => {
  const axes = [
    { name: "x", breakpoints: [0, 1, 3] },
    { name: "y", breakpoints: [10, 20] },
  ];
  const values = [
    [1, 2],
    [3, 5],
    [-1, 4],
  ];

  test("interp1 is exact at breakpoints, linear between, flat beyond", () => {
    assert.equal(interp1([0, 1, 3], [1, 3, -1], 1), 3);
    assert.equal(interp1([0, 1, 3], [1, 3, -1], 2), 1);
    assert.equal(interp1([0, 1, 3], [1, 3, -1], -5), 1);
    assert.equal(interp1([0, 1, 3], [1, 3, -1], 9), -1);
    assert.equal(interp1([4], [7], 100), 7);
  });

  test("interp2 equals interpolating along x then along y (random points, seeded)", () => {
    const draw = rng(0);
    const column = (j) => values.map((row) => row[j]);
    for (let n = 0; n < 200; n += 1) {
      const x = -1 + 5 * draw();
      const y = 5 + 20 * draw();
      const atY = axes[1].breakpoints.map((_, j) => interp1(axes[0].breakpoints, column(j), x));
      close(interp2(axes, values, x, y), interp1(axes[1].breakpoints, atY, y));
    }
  });

  test("interp2 returns the table at its breakpoints", () => {
    axes[0].breakpoints.forEach((x, i) =>
      axes[1].breakpoints.forEach((y, j) =>
        assert.equal(interp2(axes, values, x, y), values[i][j]),
      ),
    );
  });
});

describe("nested tables", () => {
  test("sliceNested picks the cells of the axes beyond the second", () => {
    // m[i][j][k]: 2 × 2 × 3, value 100 i + 10 j + k
    const m = [0, 1].map((i) => [0, 1].map((j) => [0, 1, 2].map((k) => 100 * i + 10 * j + k)));
    assert.deepEqual(sliceNested(m, [2]), [
      [2, 12],
      [102, 112],
    ]);
    assert.deepEqual(sliceNested(m, [7]), [
      [null, null],
      [null, null],
    ]);
    assert.equal(sliceNested(null, [0]), null);
  });

  test("transpose swaps axes of a 2-D table and keeps a 1-D one", () => {
    assert.deepEqual(
      transpose([
        [1, 2, 3],
        [4, 5, 6],
      ]),
      [
        [1, 4],
        [2, 5],
        [3, 6],
      ],
    );
    assert.deepEqual(transpose([1, 2]), [1, 2]);
  });

  test("logNested takes log10 everywhere, keeps null, floors zero", () => {
    assert.deepEqual(logNested([[100, null], [0.001]]), [[2, null], [-3]]);
    assert.equal(logNested([0])[0], -300);
  });

  test("diffNested is b − a with null where either is null", () => {
    assert.deepEqual(
      diffNested(
        [
          [1, 2],
          [null, 4],
        ],
        [
          [3, null],
          [5, 1],
        ],
      ),
      [
        [2, null],
        [null, -3],
      ],
    );
  });

  test("sameGrid compares breakpoints to a relative 1e-9", () => {
    const a = [{ breakpoints: [0, 1000] }, { breakpoints: [1, 2] }];
    assert.ok(sameGrid(a, [{ breakpoints: [0, 1000 + 1e-7] }, { breakpoints: [1, 2] }]));
    assert.ok(!sameGrid(a, [{ breakpoints: [0, 1000.01] }, { breakpoints: [1, 2] }]));
    assert.ok(!sameGrid(a, [{ breakpoints: [0, 1000] }]));
    assert.ok(!sameGrid(a, [{ breakpoints: [0, 1000] }, { breakpoints: [1, 2, 3] }]));
  });
});

describe("colour ranges", () => {
  test("finiteExtent skips null, NaN and infinities", () => {
    assert.deepEqual(
      finiteExtent([
        [3, null],
        [NaN, -2],
        [Infinity, 7],
      ]),
      [-2, 7],
    );
    assert.equal(finiteExtent([[null], [NaN]]), null);
  });

  test("niceStep is the smallest 1, 2, 2.5, 5 × 10^n at least span / count", () => {
    assert.equal(niceStep(10, 5), 2);
    assert.equal(niceStep(12, 5), 2.5);
    assert.equal(niceStep(0.3, 10), 0.05);
    assert.equal(niceStep(7, 1), 10);
  });

  test("niceRange holds the values on step-rounded bounds, the same every time", () => {
    const draw = rng(1);
    for (let n = 0; n < 100; n += 1) {
      const lo = -50 + 100 * draw();
      const hi = lo + 1e-3 + 10 ** (4 * draw() - 2);
      const [a, b] = niceRange(lo, hi);
      assert.ok(a <= lo && b >= hi, `${[a, b]} misses ${[lo, hi]}`);
      const step = niceStep(hi - lo, 10);
      close(a / step, Math.round(a / step), 1e-9);
      close(b / step, Math.round(b / step), 1e-9);
      assert.deepEqual(niceRange(lo, hi), [a, b]);
    }
  });

  test("niceRange pads an empty span, gives whole decades on a log scale, null for non-finite", () => {
    const [a, b] = niceRange(5, 5);
    assert.ok(a < 5 && b > 5);
    assert.deepEqual(niceRange(-3.2, -1.5, { log: true }), [-4, -1]);
    assert.deepEqual(niceRange(2, 2, { log: true }), [2, 3]);
    assert.equal(niceRange(NaN, 1), null);
  });

  test("widenRange keeps a range that holds the values, else steps out by quarter spans", () => {
    assert.deepEqual(widenRange([0, 4], 1, 3), [0, 4]);
    assert.deepEqual(widenRange([0, 4], -0.5, 4), [-1, 4]);
    assert.deepEqual(widenRange([0, 4], 0, 6.5), [0, 7]);
    assert.deepEqual(widenRange([0, 4], -2.1, 4.1), [-3, 5]);
  });

  test("padRange adds 8 % of the span each side, ±1 for an empty one", () => {
    assert.deepEqual(padRange([0, 100]), [-8, 108]);
    assert.deepEqual(padRange([3, 3]), [2, 4]);
  });
});
