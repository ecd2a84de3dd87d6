"""The map editor's pure operations (``frontend/js/map-edit-ops.js``) under Node: the unit
tests in ``js/map-edit-ops.test.js`` (lock, reset, accept/reject, undo/redo), and the
smoothing checked against a NumPy reference of its documented formula on random 1-, 2- and
3-D tables with locked cells and NaN holes. No browser or server."""

from __future__ import annotations

import itertools
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).parent
REPO = HERE.parents[1]
TESTS = HERE / "js" / "map-edit-ops.test.js"
NODE = shutil.which("node")

# Reads {shape, values (flat, null for NaN), cells, locked} per case from stdin, prints the
# edited values of each: toggleLock(locked) then smooth(cells) on a fresh edit.
SCRIPT = """
import { startEdit, toggleLock, smooth } from "./frontend/js/map-edit-ops.js";
let text = "";
process.stdin.on("data", (d) => (text += d));
process.stdin.on("end", () => {
  const out = JSON.parse(text).map((c) => {
    const learned = c.values.map((v) => (v === null ? NaN : v));
    let s = startEdit({ shape: c.shape, learned, base: learned.map(() => 0) });
    if (c.locked.length) s = toggleLock(s, c.locked);
    s = smooth(s, c.cells);
    return s.values.map((v) => (Number.isFinite(v) ? v : null));
  });
  process.stdout.write(JSON.stringify(out));
});
"""


def smooth_reference(values: np.ndarray, cells: set[int], locked: set[int]) -> np.ndarray:
    """v'(i) = Σ w(o)·v(i+o) / Σ w(o) over o ∈ {−1,0,1}^d with i+o inside the table and
    v(i+o) finite, w(o) = Π_k (2 if o_k = 0 else 1); only selected, unlocked cells change,
    all from the values before the pass; a cell with no finite neighbour keeps its value."""
    out = values.copy()
    shape = values.shape
    for k in cells - locked:
        idx = np.unravel_index(k, shape)
        num = den = 0.0
        for o in itertools.product((-1, 0, 1), repeat=values.ndim):
            j = tuple(i + d for i, d in zip(idx, o, strict=True))
            if any(x < 0 or x >= n for x, n in zip(j, shape, strict=True)):
                continue
            if not np.isfinite(values[j]):
                continue
            w = float(np.prod([2.0 if d == 0 else 1.0 for d in o]))
            num += w * values[j]
            den += w
        if den > 0:
            out[idx] = num / den
    return out


def test_map_edit_ops_under_node() -> None:
    assert NODE is not None, (
        "Node.js is not installed (apt-get install -y nodejs): these tests run under it"
    )
    done = subprocess.run(
        [NODE, "--test", str(TESTS)], cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "# fail 0" in done.stdout, done.stdout
    assert "# pass 0" not in done.stdout, done.stdout


def test_smoothing_matches_the_python_reference() -> None:
    assert NODE is not None, (
        "Node.js is not installed (apt-get install -y nodejs): these tests run under it"
    )
    rng = np.random.default_rng(18)
    cases = []
    for shape in [(7,), (1,), (5, 6), (1, 4), (8, 9), (3, 4, 5)]:
        values = rng.normal(100.0, 30.0, shape)
        size = values.size
        if size > 4:
            values.flat[rng.choice(size, 2, replace=False)] = np.nan
        cells = set(rng.choice(size, max(1, size // 2), replace=False).tolist())
        locked = set(rng.choice(size, max(1, size // 6), replace=False).tolist())
        cases.append((values, cells, locked))
    payload = [
        {
            "shape": list(v.shape),
            "values": [None if not np.isfinite(x) else float(x) for x in v.ravel()],
            "cells": sorted(c),
            "locked": sorted(lk),
        }
        for v, c, lk in cases
    ]
    done = subprocess.run(
        [NODE, "--input-type=module", "-e", SCRIPT],
        cwd=REPO,
        input=json.dumps(payload),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    results = json.loads(done.stdout)
    for (values, cells, locked), got in zip(cases, results, strict=True):
        expected = smooth_reference(values, cells, locked)
        got_arr = np.array([np.nan if x is None else x for x in got]).reshape(values.shape)
        np.testing.assert_allclose(got_arr, expected, rtol=1e-12, atol=0, equal_nan=True)
        untouched = [k for k in range(values.size) if k in locked or k not in cells]
        np.testing.assert_array_equal(got_arr.flat[untouched], values.flat[untouched])
    # An interior 2-D cell is the documented [[1 2 1] [2 4 2] [1 2 1]] / 16 average.
    plane = np.arange(20.0).reshape(4, 5) ** 2
    kernel = np.outer([1, 2, 1], [1, 2, 1]) / 16
    assert smooth_reference(plane, {6}, set())[1, 1] == pytest.approx(
        float((plane[0:3, 0:3] * kernel).sum())
    )
