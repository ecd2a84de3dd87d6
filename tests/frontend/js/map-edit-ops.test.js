/**
 * Unit tests of frontend/js/map-edit-ops.js under Node's own runner (no browser):
 * `node --test tests/frontend/js/map-edit-ops.test.js`, run from pytest by
 * test_map_edit_ops.py (which also checks the smoothing against a Python reference).
 */
import assert from "node:assert/strict";
import { describe, test } from "node:test";

import {
  acceptCells,
  baseOnGrid,
  editedCells,
  flatIndex,
  flatten,
  history,
  historyLimit,
  indexOf,
  nest,
  record,
  rectangle,
  redo,
  rejectCells,
  resetCells,
  setCells,
  shapeOf,
  smooth,
  smoothValues,
  startEdit,
  toggleLock,
  undo,
} from "../../../frontend/js/map-edit-ops.js";

/** A 3 × 4 table: learned 10·i + j, base all 1. */
function table() {
  const shape = [3, 4];
  const learned = flatten([
    [0, 1, 2, 3],
    [10, 11, 12, 13],
    [20, 21, 22, 23],
  ]);
  return startEdit({ shape, learned, base: new Array(12).fill(1) });
}

describe("tables", () => {
  test("flatten and nest are inverse, row-major", () => {
    const nested = [
      [
        [1, 2],
        [3, 4],
      ],
      [
        [5, 6],
        [7, 8],
      ],
    ];
    assert.deepEqual(shapeOf(nested), [2, 2, 2]);
    assert.deepEqual(flatten(nested), [1, 2, 3, 4, 5, 6, 7, 8]);
    assert.deepEqual(nest(flatten(nested), [2, 2, 2]), nested);
    assert.deepEqual(nest([1, 2, 3], [3]), [1, 2, 3]);
    assert.ok(Number.isNaN(flatten([[null, 1]])[0]));
  });

  test("flat indices and index tuples", () => {
    const shape = [3, 4, 5];
    for (let k = 0; k < 60; k += 1) assert.equal(flatIndex(indexOf(k, shape), shape), k);
    assert.deepEqual(indexOf(23, shape), [1, 0, 3]);
  });

  test("a rectangle between any two corners", () => {
    const shape = [3, 4];
    const r = rectangle([2, 3], [1, 1], shape);
    assert.deepEqual(r, [5, 6, 7, 9, 10, 11]);
    assert.deepEqual(rectangle([0], [2], [5]), [0, 1, 2]);
  });

  test("the base map on the grid: constant broadcast, table kept, mismatch null", () => {
    assert.deepEqual(baseOnGrid(300, [2, 2]), [300, 300, 300, 300]);
    assert.deepEqual(
      baseOnGrid(
        [
          [1, 2],
          [3, 4],
        ],
        [2, 2],
      ),
      [1, 2, 3, 4],
    );
    assert.equal(baseOnGrid([1, 2, 3], [2, 2]), null);
    assert.equal(baseOnGrid(undefined, [2, 2]), null);
  });
});

describe("operations", () => {
  test("reset to base and reject leave locked cells", () => {
    let s = table();
    s = toggleLock(s, [5]);
    assert.deepEqual([...s.locked], [5]);
    s = resetCells(s, [4, 5, 6]);
    assert.deepEqual(s.values.slice(4, 8), [1, 11, 1, 13]);
    s = rejectCells(s);
    assert.equal(s.values.filter((v) => v === 1).length, 11);
    assert.equal(s.values[5], 11);
    s = acceptCells(s);
    assert.deepEqual(s.values, s.learned);
    assert.deepEqual(
      s.log.map((e) => e.op),
      ["lock", "reset", "reject", "accept"],
    );
  });

  test("lock toggles: all locked → unlocked", () => {
    let s = table();
    s = toggleLock(s, [1, 2]);
    s = toggleLock(s, [2, 3]); // 3 not locked yet: lock both
    assert.deepEqual([...s.locked].sort(), [1, 2, 3]);
    s = toggleLock(s, [2, 3]);
    assert.deepEqual([...s.locked], [1]);
    assert.equal(s.log.at(-1).op, "unlock");
  });

  test("smooth: the 3 × 3 binomial average inside, renormalised at edges, locked untouched", () => {
    let s = table();
    s = toggleLock(s, [0]);
    const before = s.values;
    s = smooth(s, [0, 1, 5]);
    assert.equal(s.values[0], before[0]); // locked
    // Cell (1, 1): [[1 2 1] [2 4 2] [1 2 1]]/16 over 0..2 × 0..2 of 10·i + j: a plane, kept.
    assert.equal(s.values[5], 11);
    // Cell (0, 1), top edge: rows 0..1, cols 0..2, weights [[2 4 2] [1 2 1]] / 12.
    const expected = (2 * 0 + 4 * 1 + 2 * 2 + 1 * 10 + 2 * 11 + 1 * 12) / 12;
    assert.ok(Math.abs(s.values[1] - expected) < 1e-12);
    assert.equal(s.values[2], before[2]); // not selected
    assert.equal(s.log.at(-1).kernel, "binomial-3");
  });

  test("smooth reads the values before the pass, skips non-finite ones", () => {
    const out = smoothValues([0, 4, 0, NaN], [4], [0, 1, 2, 3]);
    assert.deepEqual(out, [(2 * 0 + 4) / 3, (0 + 8 + 0) / 4, (4 + 0) / 3, 0]);
    assert.deepEqual(smoothValues([NaN], [1], [0]), [NaN]);
  });

  test("typed values: finite only, locked refused", () => {
    let s = table();
    s = setCells(s, [3], 42);
    assert.equal(s.values[3], 42);
    assert.equal(setCells(s, [3], NaN), s);
    s = toggleLock(s, [3]);
    assert.equal(setCells(s, [3], 7), s);
    s = setCells(s, [2, 3], 7);
    assert.deepEqual([s.values[2], s.values[3]], [7, 42]);
    assert.deepEqual(s.log.at(-1), { op: "set", cells: [2], value: 7 });
    assert.deepEqual(editedCells(s), [2, 3]);
  });
});

describe("history", () => {
  test("undo and redo walk the states; a new edit clears redo", () => {
    let s = table();
    let h = history();
    const s0 = s;
    const step = (op) => {
      const after = op(s);
      h = record(h, s, after);
      s = after;
    };
    step((x) => smooth(x, [1, 2, 5, 6]));
    const s1 = s;
    step((x) => toggleLock(x, [5]));
    const s2 = s;
    step((x) => resetCells(x, [1, 2, 5, 6]));
    assert.equal(s.values[5], s2.values[5]); // locked
    ({ history: h, state: s } = undo(h, s));
    assert.equal(s, s2);
    ({ history: h, state: s } = undo(h, s));
    assert.equal(s, s1);
    ({ history: h, state: s } = redo(h, s));
    assert.equal(s, s2);
    ({ history: h, state: s } = undo(h, s));
    ({ history: h, state: s } = undo(h, s));
    assert.equal(s, s0);
    const same = undo(h, s);
    assert.equal(same.state, s0);
    step((x) => rejectCells(x));
    assert.equal(h.future.length, 0);
    assert.equal(redo(h, s).state, s);
  });

  test("the history is bounded; a no-op is not recorded", () => {
    let h = history(3);
    let s = table();
    for (let k = 0; k < 10; k += 1) {
      const after = setCells(s, [0], k + 100);
      h = record(h, s, after);
      s = after;
    }
    assert.equal(h.past.length, 3);
    assert.equal(record(h, s, s), h);
    assert.equal(historyLimit(16), 100);
    assert.equal(historyLimit(262_144), 15);
  });
});
