"""Metrics shared by all runs (docs/algorithms.md §7).

Map metrics compare an estimated table with the true one on the cells the data excited;
output metrics summarise an error series; torque metrics are TQ (60)–(62).
:func:`score_run` puts them together for a finished run, as the service's worker and
``mapwise run`` report it.
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from estimation.errors import EstimationError, ShapeError
from estimation.table import Table

if TYPE_CHECKING:
    from estimation.scenarios import ScenarioData

STATUS_ACCEPTED = 0
TORQUE_WINDOW_S = (5.0, 30.0)  # TQ §VI: indices over 5–30 s


def cell_visits(table: Table, U: np.ndarray) -> np.ndarray:
    """Accumulated interpolation weight of every cell over the inputs ``U`` (table shape).

    A cell's visit count is the number of samples' worth of weight it received; a sample in
    the middle of a 2-D cell gives each of its four corners 0.25.
    """
    idx, w = table.regressor(U)
    return np.bincount(idx.ravel(), weights=w.ravel(), minlength=table.size).reshape(table.shape)


def map_metrics(
    estimate: Table,
    truth: Table,
    U: np.ndarray,
    *,
    min_visits: float = 1.0,
    truth_along: np.ndarray | None = None,
) -> dict[str, float]:
    """How well ``estimate`` matches ``truth`` where the operating points ``U`` went.

    * ``rmse``, ``max_abs_error`` — over the visited cells (accumulated weight ≥ ``min_visits``),
      in the table's unit;
    * ``mean_relative_error`` — LPV §4 as defined in docs/algorithms.md §3, robust where the map
      crosses zero: ``Σ_k |T̂(υ_k) − T(υ_k)| / Σ_k |T(υ_k)|`` along the trajectory;
    * ``coverage`` — fraction of cells visited; ``visited_cells`` their number.

    ``truth_along`` (n,): the true values at ``U`` when the truth is a function off the grid
    (docs/fidelity.md); ``truth`` is then its value at the nodes. Default ``truth.evaluate(U)``.
    """
    if estimate.shape != truth.shape or any(
        not np.array_equal(a.breakpoints, b.breakpoints)
        for a, b in zip(estimate.axes, truth.axes, strict=True)
    ):
        raise ShapeError("estimate and truth must share the same grid")
    visited = cell_visits(truth, U) >= min_visits
    error = estimate.values - truth.values
    true_along = truth.evaluate(U) if truth_along is None else np.asarray(truth_along, float)
    if true_along.shape != (len(U),):
        raise ShapeError(f"truth_along has shape {true_along.shape}, U has {len(U)} points")
    along = np.abs(estimate.evaluate(U) - true_along)
    scale = float(np.sum(np.abs(true_along)))
    n_visited = int(visited.sum())
    return {
        "rmse": float(np.sqrt(np.mean(error[visited] ** 2))) if n_visited else float("nan"),
        "max_abs_error": float(np.max(np.abs(error[visited]))) if n_visited else float("nan"),
        "mean_relative_error": float(np.sum(along) / scale) if scale > 0 else float("nan"),
        "coverage": n_visited / truth.size,
        "visited_cells": float(n_visited),
    }


def output_metrics(error: np.ndarray) -> dict[str, float]:
    """RMSE, mean absolute and maximum absolute value of an error series (NaNs ignored)."""
    e = np.asarray(error, dtype=np.float64)
    e = e[np.isfinite(e)]
    if e.size == 0:
        return {"rmse": float("nan"), "mae": float("nan"), "max_abs_error": float("nan")}
    return {
        "rmse": float(np.sqrt(np.mean(e**2))),
        "mae": float(np.mean(np.abs(e))),
        "max_abs_error": float(np.max(np.abs(e))),
    }


@dataclass(slots=True)
class ErrorSums:
    """:func:`output_metrics` of an error that comes a block at a time (a log read in
    windows): running sums, equal to the whole-array figures up to rounding."""

    n: int = 0
    e2: float = 0.0
    abs_sum: float = 0.0
    abs_max: float = 0.0

    def add(self, error: np.ndarray) -> None:
        e = error[np.isfinite(error)]
        if e.size:
            self.n += int(e.size)
            self.e2 += float(np.sum(e * e))
            self.abs_sum += float(np.sum(np.abs(e)))
            self.abs_max = max(self.abs_max, float(np.max(np.abs(e))))

    def metrics(self) -> dict[str, float]:
        if not self.n:
            return output_metrics(np.empty(0))
        n = self.n
        return {
            "rmse": float(np.sqrt(self.e2 / n)),
            "mae": self.abs_sum / n,
            "max_abs_error": self.abs_max,
        }


def torque_metrics(
    time_s: np.ndarray, error_nm: np.ndarray, *, window_s: Sequence[float] = (5.0, 30.0)
) -> dict[str, float]:
    """TQ (60)–(62) over ``window_s`` (the paper: 5–30 s): ``ISE = ∫ τ̃² dt`` (N²·m²·s, by the
    rectangle rule on the sample grid), ``MAE = max |τ̃|`` (N·m, the paper's maximum absolute
    error) and ``SD`` = standard deviation of τ̃ (N·m)."""
    t = np.asarray(time_s, dtype=np.float64)
    e = np.asarray(error_nm, dtype=np.float64)
    if t.shape != e.shape:
        raise ShapeError(f"time has shape {t.shape}, error {e.shape}")
    lo, hi = window_s
    inside = (t >= lo) & (t <= hi)
    if np.count_nonzero(inside) < 2:
        raise ShapeError(f"fewer than two samples inside the window {lo}–{hi} s")
    dt = np.diff(t, append=t[-1] + (t[-1] - t[-2]))
    ei = e[inside]
    return {
        "ise": float(np.sum(ei**2 * dt[inside])),
        "mae": float(np.max(np.abs(ei))),
        "sd": float(np.std(ei)),
    }


def running_ise(
    time_s: np.ndarray, error_nm: np.ndarray, *, window_s: Sequence[float] = TORQUE_WINDOW_S
) -> np.ndarray:
    """ISE so far at every sample: ``ISE(t) = Σ_{t_k ∈ window, t_k ≤ t} τ̃_k² Δt_k`` (TQ (60)
    by the rectangle rule of :func:`torque_metrics`, ``Δt_k = t_{k+1} − t_k``), 0 before the
    window and constant after it, so its last value is :func:`torque_metrics`' ``ise``.
    ``window_s`` is absolute time; samples not computed yet (NaN) add nothing. N²·m²·s."""
    t = np.asarray(time_s, dtype=np.float64)
    e = np.asarray(error_nm, dtype=np.float64)
    if t.shape != e.shape:
        raise ShapeError(f"time has shape {t.shape}, error {e.shape}")
    if t.size < 2:
        return np.zeros_like(t)
    lo, hi = window_s
    dt = np.diff(t, append=t[-1] + (t[-1] - t[-2]))
    inside = (t >= lo) & (t <= hi) & np.isfinite(e)
    return np.cumsum(np.where(inside, np.square(np.where(inside, e, 0.0)) * dt, 0.0))


def torque_window(time_s: np.ndarray) -> tuple[float, float]:
    """The scoring window of a record: 5–30 s after its first sample, cut at its last."""
    t = np.asarray(time_s, dtype=np.float64)
    return (float(t[0] + TORQUE_WINDOW_S[0]), float(min(t[0] + TORQUE_WINDOW_S[1], t[-1])))


def convergence_time(time_s: np.ndarray, error: np.ndarray, threshold: float) -> float | None:
    """First time after which ``error`` stays at or below ``threshold`` (``None`` if never)."""
    t = np.asarray(time_s, dtype=np.float64)
    above = np.asarray(error, dtype=np.float64) > threshold
    if above[-1]:
        return None
    if not above.any():
        return float(t[0])
    last_above = int(np.nonzero(above)[0][-1])
    return float(t[last_above + 1])


def series_metrics(data: ScenarioData, outputs: Mapping[str, np.ndarray]) -> dict[str, float]:
    """Score every estimator output the scenario has a true series for: ``torque_nm`` by
    TQ (60)–(62) over 5–30 s of the record (``ise``, ``mae``, ``sd``), any other series by
    its ``rmse`` (error = truth − estimate)."""
    metrics: dict[str, float] = {}
    for name, truth in data.scored_series.items():
        estimate = outputs.get(name)
        if estimate is None or estimate.shape != truth.shape:
            continue
        error = truth - estimate
        if name == "torque_nm":
            t = data.signals.time
            window = (t[0] + TORQUE_WINDOW_S[0], min(t[0] + TORQUE_WINDOW_S[1], t[-1]))
            metrics |= torque_metrics(t, error, window_s=window)
        else:
            metrics["rmse"] = output_metrics(error)["rmse"]
    return metrics


def score_run(
    outputs: Mapping[str, np.ndarray],
    status: np.ndarray | None,
    *,
    table: Table | None = None,
    truth: ScenarioData | None = None,
) -> dict[str, float]:
    """The known-truth and output metrics of a finished run.

    ``outputs`` are the estimator's per-sample series over the whole record (as the
    snapshots' ``outputs`` concatenated), ``status`` the per-sample status (0 accepted;
    ``None``: all accepted), ``table`` the final map and ``truth`` the scenario realisation
    the log came from (``None`` for a log without truth). Returns

    * ``output_rmse`` — RMS of ``residual`` over the accepted samples where it is finite,
      if there are any;
    * with a true map on the same grid as ``table``: :func:`map_metrics` along the
      scenario's scoring points, its ``rmse`` renamed ``map_rmse`` when the scenario also
      scores series;
    * :func:`series_metrics` of the outputs that are finite throughout (a record too short
      for the torque window gives no torque metrics rather than an error).

    Values may be NaN (e.g. no visited cell); callers decide how to show them.
    """
    metrics: dict[str, float] = {}
    residual = outputs.get("residual")
    if residual is not None:
        residual = np.asarray(residual, dtype=np.float64)
        ok = np.isfinite(residual)
        if status is not None and status.shape == residual.shape:
            ok &= status == STATUS_ACCEPTED
        if ok.any():  # output_metrics' rmse, squaring in place: one copy of the log's length
            accepted = residual[ok]
            metrics["output_rmse"] = float(np.sqrt(np.mean(np.square(accepted, out=accepted))))
    if truth is None:
        return metrics
    true_map = truth.true_map
    if table is not None and true_map is not None and _same_grid(table, true_map):
        found = map_metrics(table, true_map, truth.scoring_points(), truth_along=truth.true_along)
        if truth.scored_series:
            found["map_rmse"] = found.pop("rmse")
        metrics |= found
    finite = {k: np.asarray(v) for k, v in outputs.items() if np.all(np.isfinite(v))}
    with contextlib.suppress(EstimationError):
        metrics |= series_metrics(truth, finite)
    return metrics


def _same_grid(a: Table, b: Table) -> bool:
    return a.shape == b.shape and all(
        np.array_equal(x.breakpoints, y.breakpoints) for x, y in zip(a.axes, b.axes, strict=True)
    )
