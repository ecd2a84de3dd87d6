/**
 * Pure editing operations on a learned map (the run view's editor, views/run/edit.js): lock,
 * reset to the run's base map, smooth, accept or reject the learned values, and a bounded
 * undo/redo history. No DOM, no Plotly: tests/frontend/js/map-edit-ops.test.js runs these
 * under Node and tests/frontend/test_map_edit_ops.py checks the smoothing against a Python
 * reference.
 *
 * A table of shape [n0, n1, …] is held flat in row-major order (the last axis fastest, as
 * nested lists flatten): cell (i0, i1, …) is at k = (i0·n1 + i1)·n2 + …. An edit state is
 * immutable — every operation returns a new one — so the history is a list of states:
 *   {shape, learned, base, values, locked: Set<k>, log: [{op, cells, …}]}
 * learned: the run version's values; base: the map the run started from; values: the edit.
 * Locked cells keep their value through every operation but (un)lock itself.
 */

/** The smoothing kernel's name in the edit log (see smooth). */
export const SMOOTH_KERNEL = "binomial-3";
/** Undo steps kept at most, and the cells all kept states may hold together (memory bound). */
export const HISTORY_STEPS = 100;
export const HISTORY_CELLS = 4_000_000;

/* ---------- tables ---------- */

/** The shape of regular nested lists ([] for a number). */
export function shapeOf(nested) {
  const shape = [];
  let x = nested;
  while (Array.isArray(x)) {
    shape.push(x.length);
    x = x[0];
  }
  return shape;
}

/** Nested lists → flat array (row-major); null/undefined become NaN. */
export function flatten(nested) {
  const out = [];
  const walk = (x) => {
    if (Array.isArray(x)) for (const y of x) walk(y);
    else out.push(typeof x === "number" ? x : NaN);
  };
  walk(nested);
  return out;
}

/** Flat array → nested lists of the given shape. */
export function nest(flat, shape) {
  if (!shape.length) return flat[0];
  const build = (offset, d) => {
    const n = shape[d];
    if (d === shape.length - 1) return Array.from({ length: n }, (_, i) => flat[offset + i]);
    const stride = shape.slice(d + 1).reduce((a, b) => a * b, 1);
    return Array.from({ length: n }, (_, i) => build(offset + i * stride, d + 1));
  };
  return build(0, 0);
}

/** Flat index of the index tuple idx. */
export function flatIndex(idx, shape) {
  let k = 0;
  for (let d = 0; d < shape.length; d += 1) k = k * shape[d] + idx[d];
  return k;
}

/** Index tuple of flat index k. */
export function indexOf(k, shape) {
  const idx = new Array(shape.length);
  let r = k;
  for (let d = shape.length - 1; d >= 0; d -= 1) {
    idx[d] = r % shape[d];
    r = Math.floor(r / shape[d]);
  }
  return idx;
}

/** Flat indices of the box spanned by index tuples a and b (inclusive, any corner order). */
export function rectangle(a, b, shape) {
  const lo = a.map((v, d) => Math.min(v, b[d]));
  const hi = a.map((v, d) => Math.max(v, b[d]));
  const out = [];
  const walk = (d, idx) => {
    if (d === shape.length) {
      out.push(flatIndex(idx, shape));
      return;
    }
    for (let i = lo[d]; i <= hi[d]; i += 1) walk(d + 1, [...idx, i]);
  };
  walk(0, []);
  return out;
}

/**
 * The run's base map on the version's grid: a nested table of the same shape as it is, a
 * number (constant θ0) broadcast to every cell; null when it does not fit the grid.
 */
export function baseOnGrid(start, shape) {
  const n = shape.reduce((a, b) => a * b, 1);
  if (typeof start === "number" && Number.isFinite(start)) return new Array(n).fill(start);
  if (!Array.isArray(start)) return null;
  const got = shapeOf(start);
  if (got.length !== shape.length || got.some((v, d) => v !== shape[d])) return null;
  const flat = flatten(start);
  return flat.length === n ? flat : null;
}

/* ---------- edit state ---------- */

/** A fresh edit of a learned map: values = learned, nothing locked, an empty log. */
export function startEdit({ shape, learned, base }) {
  return {
    shape: [...shape],
    learned: [...learned],
    base: [...base],
    values: [...learned],
    locked: new Set(),
    log: [],
  };
}

function next(s, values, locked, entry) {
  return { ...s, values, locked, log: [...s.log, entry] };
}

/** Cells to act on: the given ones (deduplicated, sorted), or every cell when none is given. */
function targets(s, cells) {
  const all = cells === null || cells === undefined;
  const list = all ? s.values.map((_, k) => k) : [...new Set(cells)].sort((a, b) => a - b);
  return list.filter((k) => Number.isInteger(k) && k >= 0 && k < s.values.length);
}

/**
 * Lock the cells, or unlock them when all of them are locked already (a toggle, as one key
 * or button does both). Values are unchanged.
 */
export function toggleLock(s, cells) {
  const list = targets(s, cells);
  if (!list.length) return s;
  const unlock = list.every((k) => s.locked.has(k));
  const locked = new Set(s.locked);
  for (const k of list) {
    if (unlock) locked.delete(k);
    else locked.add(k);
  }
  return next(s, s.values, locked, { op: unlock ? "unlock" : "lock", cells: list });
}

/** Set the unlocked cells of `cells` (all when null) from `source`; the log entry `op`. */
function copyFrom(s, cells, source, op) {
  const list = targets(s, cells);
  const values = [...s.values];
  const changed = [];
  for (const k of list) {
    if (s.locked.has(k)) continue;
    values[k] = source[k];
    changed.push(k);
  }
  return next(s, values, s.locked, {
    op,
    cells: cells === null ? null : list,
    changed: changed.length,
  });
}

/** Reset the cells (unlocked ones) to the run's base map. */
export function resetCells(s, cells) {
  return copyFrom(s, cells, s.base, "reset");
}

/** Accept the learned values in the cells (all when null): undoes edits there. */
export function acceptCells(s, cells = null) {
  return copyFrom(s, cells, s.learned, "accept");
}

/** Reject the learned values in the cells (all when null): back to the base map there. */
export function rejectCells(s, cells = null) {
  return copyFrom(s, cells, s.base, "reject");
}

/** Set the (unlocked) cells to a typed value; a non-finite value changes nothing. */
export function setCells(s, cells, value) {
  if (!Number.isFinite(value)) return s;
  const list = targets(s, cells).filter((k) => !s.locked.has(k));
  if (!list.length) return s;
  const values = [...s.values];
  for (const k of list) values[k] = value;
  return next(s, values, s.locked, { op: "set", cells: list, value });
}

/**
 * Smooth the cells (unlocked ones) with the separable binomial 3-tap kernel, one pass:
 *
 *   v'(i) = Σ_{o ∈ {−1,0,1}^d, i+o in the table, v(i+o) finite} w(o) · v(i+o)
 *           / Σ_{same o} w(o),        w(o) = Π_k b(o_k),  b(0) = 2, b(±1) = 1
 *
 * i.e. [1 2 1]/4 on a 1-D table and [[1 2 1] [2 4 2] [1 2 1]]/16 inside a 2-D one; at the
 * table's edges the weights of the neighbours that exist are renormalised (no padding).
 * All cells are updated from the values before the pass (not in place), neighbours that are
 * locked or not selected are read but not changed, and non-finite values are skipped (a cell
 * with no finite neighbour keeps its value). The binomial kernel is the discrete Gaussian of
 * variance 1/2 per axis (Burt & Adelson 1983, "The Laplacian pyramid…", IEEE Trans. Commun.).
 */
export function smooth(s, cells) {
  const list = targets(s, cells).filter((k) => !s.locked.has(k));
  const values = smoothValues(s.values, s.shape, list);
  return next(s, values, s.locked, {
    op: "smooth",
    cells: targets(s, cells),
    kernel: SMOOTH_KERNEL,
  });
}

/** The smoothing of `smooth` on a flat table: a new array, only `cells` changed. */
export function smoothValues(flat, shape, cells) {
  const out = [...flat];
  const d = shape.length;
  const offsets = [];
  const walk = (k, o) => {
    if (k === d) {
      offsets.push(o);
      return;
    }
    for (const x of [-1, 0, 1]) walk(k + 1, [...o, x]);
  };
  walk(0, []);
  for (const c of cells) {
    const idx = indexOf(c, shape);
    let num = 0;
    let den = 0;
    for (const o of offsets) {
      let inside = true;
      let w = 1;
      for (let k = 0; k < d; k += 1) {
        const j = idx[k] + o[k];
        if (j < 0 || j >= shape[k]) inside = false;
        w *= o[k] === 0 ? 2 : 1;
      }
      if (!inside) continue;
      const v =
        flat[
          flatIndex(
            idx.map((i, k) => i + o[k]),
            shape,
          )
        ];
      if (!Number.isFinite(v)) continue;
      num += w * v;
      den += w;
    }
    if (den > 0) out[c] = num / den;
  }
  return out;
}

/** Cells whose value differs from the learned one (flat indices). */
export function editedCells(s) {
  const out = [];
  s.values.forEach((v, k) => {
    if (!(v === s.learned[k] || (Number.isNaN(v) && Number.isNaN(s.learned[k])))) out.push(k);
  });
  return out;
}

/* ---------- history ---------- */

/** The number of undo steps kept for a table of n cells: HISTORY_STEPS, fewer for big tables. */
export function historyLimit(n) {
  return Math.max(5, Math.min(HISTORY_STEPS, Math.floor(HISTORY_CELLS / Math.max(1, n))));
}

/** An empty history of at most `limit` undo steps. */
export function history(limit = HISTORY_STEPS) {
  return { past: [], future: [], limit };
}

/**
 * The history after moving from state `before` to a new one: `before` is pushed (the oldest
 * dropped beyond the limit) and the redo list cleared. An operation that changed nothing
 * (the same state object) leaves the history as it is.
 */
export function record(h, before, after) {
  if (before === after) return h;
  const past = [...h.past, before];
  return { ...h, past: past.slice(Math.max(0, past.length - h.limit)), future: [] };
}

/** Undo: {history, state} with the previous state, or the same when there is none. */
export function undo(h, current) {
  if (!h.past.length) return { history: h, state: current };
  return {
    history: { ...h, past: h.past.slice(0, -1), future: [current, ...h.future] },
    state: h.past.at(-1),
  };
}

/** Redo: {history, state} with the state undone last, or the same when there is none. */
export function redo(h, current) {
  if (!h.future.length) return { history: h, state: current };
  return {
    history: { ...h, past: [...h.past, current], future: h.future.slice(1) },
    state: h.future[0],
  };
}
