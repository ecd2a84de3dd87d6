"""The unvisited region of an LPV map: which elements the data reached, and two fills.

The observer (:mod:`estimation.observers.lpv`) only adapts the elements the trajectory
visits; the rest keep their initial value. :func:`fill_quadratic` fills them with the
quadratic surface of LPV (37), :func:`fill_smooth` with the smoothest continuation of the
visited part (a convex least-squares problem, optionally bounded and monotone).
"""

from __future__ import annotations

import numpy as np

from estimation.errors import ConfigError, ShapeError
from estimation.observers.lpv import LpvState
from estimation.table import Table

__all__ = ["fill_quadratic", "fill_smooth", "visited_cells"]


def visited_cells(
    state_or_weights: LpvState | np.ndarray, *, min_weight: float = 1.0
) -> np.ndarray:
    """Boolean (p,) mask of elements whose accumulated ψ weight reaches ``min_weight``."""
    ws = state_or_weights.weight_sum if isinstance(state_or_weights, LpvState) else state_or_weights
    return np.asarray(ws) >= min_weight


def fill_quadratic(table: Table, visited: np.ndarray) -> tuple[Table, np.ndarray]:
    """Fill unvisited cells of a 2-D map with LPV (37)'s quadratic surface.

    ``ΔW_c,e = a2u² + a1u + b2n² + b1n + c2·u·n + c1`` is fitted by least squares to the
    visited nodes (axes normalised to [0, 1]); visited nodes keep their values. Returns the
    filled table and the (shape) mask of estimated (True) vs filled (False) nodes.
    """
    if table.ndim != 2:
        raise ShapeError(f"the LPV (37) fill is for 2-D maps, got {table.ndim}-D")
    mask = np.asarray(visited, dtype=bool).reshape(table.shape)
    if mask.sum() < 6:
        raise ConfigError(f"the quadratic fill needs >= 6 visited nodes, got {int(mask.sum())}")
    g0, g1 = (a.breakpoints for a in table.axes)
    u, v = np.meshgrid(
        (g0 - g0[0]) / (g0[-1] - g0[0]), (g1 - g1[0]) / (g1[-1] - g1[0]), indexing="ij"
    )
    X = np.stack([u * u, u, v * v, v, u * v, np.ones_like(u)], axis=-1)
    vals = np.asarray(table.values, dtype=np.float64)
    coef, *_ = np.linalg.lstsq(X[mask], vals[mask], rcond=None)
    filled = np.where(mask, vals, X @ coef)
    return table.with_values(filled), mask


def fill_smooth(
    table: Table,
    visited: np.ndarray,
    *,
    smoothness: float = 1.0,
    lower: float | None = None,
    upper: float | None = None,
    increasing: tuple[int, ...] = (),
    decreasing: tuple[int, ...] = (),
) -> tuple[Table, np.ndarray]:
    """Smooth convex fill: ``min Σ_visited (T − θ̂)² + λ Σ (second differences)²``.

    Solved with cvxpy (Clarabel) over all nodes of a 1-D or 2-D map (values scaled by their
    largest visited magnitude); ``lower``/``upper`` bound every node [table unit];
    ``increasing``/``decreasing`` list axes along which the whole map must be monotone
    (first differences ≥ 0 / ≤ 0). Visited nodes are fitted (not pinned), unvisited ones
    follow the smoothest continuation. Returns the table and the estimated-node mask as
    :func:`fill_quadratic` does.
    """
    import cvxpy as cp

    if table.ndim not in (1, 2):
        raise ShapeError(f"the smooth fill is for 1-D or 2-D maps, got {table.ndim}-D")
    if smoothness < 0:
        raise ConfigError(f"smoothness must be >= 0, got {smoothness}")
    mask = np.asarray(visited, dtype=bool).reshape(table.shape)
    if not mask.any():
        raise ConfigError("the smooth fill needs at least one visited node")
    vals = np.asarray(table.values, dtype=np.float64)
    scale = max(float(np.abs(vals[mask]).max()), 1e-12)
    T = cp.Variable(table.shape)
    fit = cp.sum_squares(cp.multiply(mask.astype(float), T - vals / scale))
    rough = 0
    for ax in range(table.ndim):
        if table.shape[ax] >= 3:
            rough = rough + cp.sum_squares(cp.diff(T, k=2, axis=ax))
    cons = []
    for axes, sign in ((increasing, 1.0), (decreasing, -1.0)):
        for ax in axes:
            if not 0 <= ax < table.ndim:
                raise ConfigError(f"monotone axis {ax} is not an axis of a {table.ndim}-D map")
            if table.shape[ax] >= 2:
                cons.append(sign * cp.diff(T, k=1, axis=ax) >= 0)
    if lower is not None:
        cons.append(lower / scale <= T)
    if upper is not None:
        cons.append(upper / scale >= T)
    prob = cp.Problem(cp.Minimize(fit + smoothness * rough), cons)
    prob.solve(solver=cp.CLARABEL)
    if prob.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
        raise ConfigError(f"smooth fill failed: solver status {prob.status!r}")
    return table.with_values(np.asarray(T.value) * scale), mask
