"""Merging maps learnt on several vehicles of a fleet into one, cell by cell.

Each vehicle ``i`` contributes its estimate ``θ_i`` of a cell with the filter's variance
``σ_i²`` (diag P). Treating the vehicles as independent measurements of one true cell value,
the minimum-variance combination is the inverse-variance weighted mean

    θ̄ = Σ_i θ_i / σ_i²  /  Σ_i 1 / σ_i²,        σ̄² = 1 / Σ_i 1 / σ_i²

(the static Kalman/Gauss–Markov fusion of independent estimates). A cell a vehicle never
visited keeps its prior variance, so it barely counts. A vehicle that differs from the fleet
is told by its standardised deviation

    z_i = (θ_i − θ̄_{−i}) / sqrt(σ_i² + σ̄_{−i}²)

against the merge of the *other* vehicles (leave-one-out, so a vehicle does not pull the
reference towards itself); ``|z_i| > 3`` marks a cell where vehicle ``i`` is unlikely to
share the fleet's value. Filters without a covariance (SSKF, NLMS) are merged with weights
``visits_i`` instead (visit-weighted mean) and give no ``z``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimation.errors import ShapeError


@dataclass(frozen=True, slots=True)
class FleetMerge:
    """``values``/``variances`` of the merged map, ``z`` (n_vehicles, *shape) deviations
    (``None`` without variances), ``weights`` (n_vehicles, *shape) normalised per cell."""

    values: np.ndarray
    variances: np.ndarray | None
    z: np.ndarray | None
    weights: np.ndarray


def merge_maps(
    values: np.ndarray,
    variances: np.ndarray | None = None,
    *,
    visits: np.ndarray | None = None,
) -> FleetMerge:
    """Merge ``values`` (n, *shape) by inverse variance (or by ``visits`` (n, *shape))."""
    theta = np.asarray(values, dtype=np.float64)
    if theta.ndim < 2 or theta.shape[0] < 1:
        raise ShapeError(f"values must be (vehicles, *map shape), got shape {theta.shape}")
    if variances is None:
        if visits is None:
            raise ShapeError("merging needs the maps' variances or their visit counts")
        w = np.asarray(visits, dtype=np.float64)
        if w.shape != theta.shape:
            raise ShapeError(f"visits shape {w.shape} differs from values shape {theta.shape}")
        total = w.sum(axis=0)
        weights = np.divide(w, total, out=np.full_like(w, 1.0 / len(w)), where=total > 0)
        return FleetMerge((weights * theta).sum(axis=0), None, None, weights)
    var = np.asarray(variances, dtype=np.float64)
    if var.shape != theta.shape:
        raise ShapeError(f"variances shape {var.shape} differs from values shape {theta.shape}")
    if np.any(~(var > 0)):
        raise ShapeError("variances must be positive and finite to be merged by inverse variance")
    info = 1.0 / var
    total = info.sum(axis=0)
    merged = (info * theta).sum(axis=0) / total
    z = None
    if len(theta) > 1:
        rest_info = total - info
        rest_mean = ((info * theta).sum(axis=0) - info * theta) / rest_info
        z = (theta - rest_mean) / np.sqrt(var + 1.0 / rest_info)
    return FleetMerge(merged, 1.0 / total, z, info / total)
