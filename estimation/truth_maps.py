"""The true maps of the scenarios as smooth functions, evaluated off-grid (docs/fidelity.md).

Under ``mismatch="none"`` a scenario's truth is a table on the estimator's own grid
(bilinear between nodes, so a perfect estimator can reach zero error). Under ``"nominal"`` and
``"severe"`` the plant evaluates the smooth function itself at every operating point; the
estimator's table can then only approximate it. Each :class:`TruthMap` is defined on the box
of its estimator grid and constant beyond it along each axis (the clamp a table has,
docs/algorithms.md §1), so the scored error is the estimator's, not an extrapolation's.

Functions (their equations are in the docstrings cited):

- :data:`MAF_ERROR_2D` — additive MAF error ``ΔW_c(u_δ, n_e)`` [kg/s] on the LPV §4 box
  ``[0, 56] mg × [0, 3000] rpm``
  (:func:`estimation.plants.airpath_sensors.default_maf_error_2d`);
- :data:`MAF_RELATIVE_1D` — relative MAF error ``q(W)`` [-] on ``[0, 0.2] kg/s``
  (:func:`estimation.plants.airpath_sensors.default_maf_relative_error`);
- :data:`NOX_BASE` — age-0 engine-out NOx ``T_base(n, m_f)`` [ppm] on the SKF (34) box
  ``[750, 4500] rpm × [0, 80] mg/stroke`` (:func:`estimation.plants.nox.nox_base_ppm`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estimation.errors import ShapeError
from estimation.plants.airpath_sensors import (
    FUEL_AXIS_MG,
    MAF_AXIS_KG_S,
    SPEED_AXIS_RPM,
    default_maf_error_2d,
    default_maf_relative_error,
)
from estimation.plants.nox import nox_axes, nox_base_ppm
from estimation.table import Axis, Table

__all__ = ["MAF_ERROR_2D", "MAF_RELATIVE_1D", "NOX_BASE", "TruthMap"]


@dataclass(frozen=True, slots=True)
class TruthMap:
    """A smooth map over ``axes``' box: ``function(*columns)`` with inputs clipped to it."""

    name: str
    unit: str
    axes: tuple[Axis, ...]
    function: Callable[..., np.ndarray]

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Values at ``points`` (n, d), one column per axis in order."""
        u = np.atleast_2d(np.asarray(points, dtype=np.float64))
        if u.shape[1] != len(self.axes):
            raise ShapeError(f"{self.name} takes {len(self.axes)} columns, got {u.shape[1]}")
        cols = [
            np.clip(u[:, i], a.breakpoints[0], a.breakpoints[-1]) for i, a in enumerate(self.axes)
        ]
        return np.asarray(self.function(*cols), dtype=np.float64)

    def on_grid(self) -> Table:
        """The function at the nodes of its grid: the best a table can be at the nodes."""
        mesh = np.meshgrid(*[a.breakpoints for a in self.axes], indexing="ij")
        values = self.function(*mesh)
        return Table(list(self.axes), np.asarray(values, dtype=np.float64))


MAF_ERROR_2D = TruthMap(
    "maf_error_2d",
    "kg/s",
    (
        Axis("fuel_mg_per_cycle", "mg/cycle", FUEL_AXIS_MG),
        Axis("speed_rpm", "rpm", SPEED_AXIS_RPM),
    ),
    default_maf_error_2d,
)
MAF_RELATIVE_1D = TruthMap(
    "maf_relative_1d", "-", (Axis("maf_kg_s", "kg/s", MAF_AXIS_KG_S),), default_maf_relative_error
)
NOX_BASE = TruthMap("nox_base", "ppm", nox_axes(), nox_base_ppm)
