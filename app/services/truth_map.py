"""A simulated dataset's true map on a run's grid: what the run view's "estimated − true" map
subtracts (docs/dashboard.md).

The dataset's truth (:class:`app.io.payload.Truth`) holds the scenario's true map as a table on
the scenario's grid, over the input channels ``map_inputs``. The run's grid (its latest map
version, else the run's table) may order those inputs differently or use other breakpoints:

* the run's axes are matched to the truth's inputs by channel name (any order);
* on the truth's own breakpoints the values are the truth's nodes exactly (``exact``), which
  is what the run metrics score (:func:`estimation.metrics.map_metrics`);
* on other breakpoints they are the truth table's multilinear interpolation, clamped beyond
  its box (:meth:`estimation.table.Table.on_grid`: numpy only, so the API process loads no
  numba); an off-grid truth (a smooth function, docs/fidelity.md) is then approximated
  between the truth's nodes (``exact`` false).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from app.db.engine import Database
from app.db.repositories import DatasetRepo, RunRepo, VersionRepo
from app.domain import Run
from app.errors import NotFoundError
from app.io.payload import unpack_truth
from estimation.table import Axis, Table

# The map quantity of the map estimators without a measured output column (signals.y): the
# LPV observer's additive MAF error ΔW_c (estimation/observers/lpv.py, maf_error_kg_s) and the
# EKF map's relative MAF error q (estimation/observers/ekf.py, maf_q; dimensionless).
MAP_QUANTITY = {"lpv": ("maf_error_kg_s", "kg/s"), "ekf-map": ("maf_q", "-")}


@dataclass(frozen=True, slots=True)
class TruthOnGrid:
    """The true map on the run's grid: ``values`` shaped like the run's table, or ``None``
    with the ``reason`` when the run's grid is not over the true map's inputs."""

    axes: list[dict[str, Any]]
    values: np.ndarray | None
    name: str
    unit: str
    exact: bool
    reason: str | None = None


def truth_on_grid(db: Database, run_id: int) -> TruthOnGrid:
    """The true map of run ``run_id``'s simulated dataset on the run's grid.

    404 (field ``run_id``) when the run does not exist, its dataset has no truth or the truth
    has no map (torque, a log). A run without a grid, or whose grid reads other inputs than
    the true map, has no true map to compare with: ``values`` is ``None`` and ``reason`` says
    why (an answer, not an error: the run view asks for every simulated map run).
    """
    with db.read() as s:
        run = RunRepo(s).get(run_id)
        latest = VersionRepo(s).latest(run_id)
        datasets = DatasetRepo(s)
        dataset = datasets.get(run.dataset_id)
        blob = datasets.truth(run.dataset_id)
    if blob is None:
        raise NotFoundError(
            f"run {run_id}'s dataset has no truth (only simulated datasets have one)",
            field="run_id",
        )
    truth = unpack_truth(blob)
    true_map = truth.true_map
    if true_map is None:
        raise NotFoundError(f"run {run_id}'s dataset has a truth but no true map", field="run_id")
    name, unit = map_quantity(run)
    if not unit and truth.map_output:
        unit = dataset.unit_of(truth.map_output)
    name = name or truth.map_output or "value"
    axes = _grid_axes(run, None if latest is None else latest.axes)
    if not axes:
        return TruthOnGrid([], None, name, unit, False, f"run {run_id} has no map grid")
    inputs = list(truth.map_inputs)
    if len(inputs) != true_map.ndim:
        inputs = [a.name for a in true_map.axes]
    grid = [Axis.from_dict(a) for a in axes]
    if len(grid) != len(inputs) or any(a.name not in inputs for a in grid):
        reason = (
            f"run {run_id}'s grid reads {[a.name for a in grid]}, the true map {inputs}: "
            "no true map on this grid"
        )
        return TruthOnGrid(axes, None, name, unit, False, reason)
    order = [inputs.index(a.name) for a in grid]  # the truth's axis of each run axis
    exact = all(
        np.array_equal(true_map.axes[k].breakpoints, a.breakpoints)
        for k, a in zip(order, grid, strict=True)
    )
    targets: list[np.ndarray] = [np.empty(0)] * len(grid)
    for run_axis, truth_axis in enumerate(order):
        targets[truth_axis] = grid[run_axis].breakpoints
    on_truth_axes = Table(list(true_map.axes), true_map.values).on_grid(targets)
    return TruthOnGrid(
        axes=[a.to_dict() for a in grid],
        values=np.transpose(on_truth_axes, order),  # run axis r is the truth's axis order[r]
        name=name,
        unit=unit,
        exact=exact,
    )


def map_quantity(run: Run) -> tuple[str, str]:
    """The name and unit of a run's map values: its output column and that column's unit
    (table filters), else the estimator's map quantity (:data:`MAP_QUANTITY`)."""
    config = run.estimator_config
    output = run.signals.get("y") or config.get("output")
    if isinstance(output, str) and output:
        return output, str(config.get("output_unit") or "")
    return MAP_QUANTITY.get(run.estimator, ("", ""))


def _grid_axes(run: Run, version_axes: list[dict[str, Any]] | None) -> list[dict[str, Any]]:
    """The axes of the map the run view shows: its latest version's, else the run's table's."""
    if version_axes:
        return version_axes
    table = run.table or {}
    return list(table.get("axes") or run.estimator_config.get("axes") or [])
