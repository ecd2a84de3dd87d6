"""Metrics (docs/algorithms.md §7) against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from estimation.errors import ShapeError
from estimation.metrics import (
    cell_visits,
    convergence_time,
    map_metrics,
    output_metrics,
    score_run,
    series_metrics,
    torque_metrics,
)
from estimation.scenarios import ScenarioData
from estimation.signals import Signals
from estimation.table import Axis, Table

GRID = [Axis("a", "", [0.0, 1.0, 2.0]), Axis("b", "", [0.0, 10.0])]


def test_cell_visits_spread_each_sample_over_its_corners() -> None:
    truth = Table(GRID, 0.0)
    visits = cell_visits(truth, np.array([[0.5, 5.0], [2.0, 10.0], [0.0, 0.0]]))
    expected = np.array([[0.25 + 1.0, 0.25], [0.25, 0.25], [0.0, 1.0]])
    np.testing.assert_allclose(visits, expected)
    assert visits.sum() == pytest.approx(3.0)


def test_map_metrics_by_hand() -> None:
    truth = Table(GRID, [[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    estimate = truth.with_values([[1.5, 2.0], [3.0, 3.0], [0.0, 0.0]])
    U = np.array([[0.0, 0.0], [1.0, 10.0]])  # visits cells (0,0) and (1,1) only
    m = map_metrics(estimate, truth, U)
    assert m["visited_cells"] == 2
    assert m["coverage"] == pytest.approx(2 / 6)
    assert m["rmse"] == pytest.approx(np.sqrt((0.5**2 + 1.0**2) / 2))
    assert m["max_abs_error"] == pytest.approx(1.0)
    # Σ|T̂(υ) − T(υ)| / Σ|T(υ)| = (0.5 + 1) / (1 + 4)
    assert m["mean_relative_error"] == pytest.approx(1.5 / 5.0)


def test_map_metrics_refuse_different_grids() -> None:
    truth = Table(GRID, 0.0)
    other = Table([Axis("a", "", [0.0, 1.0, 3.0]), GRID[1]], 0.0)
    with pytest.raises(ShapeError, match="same grid"):
        map_metrics(other, truth, np.zeros((1, 2)))


def test_output_metrics_ignore_nan() -> None:
    m = output_metrics(np.array([np.nan, 3.0, -4.0]))
    assert m == {"rmse": pytest.approx(np.sqrt(12.5)), "mae": 3.5, "max_abs_error": 4.0}


def test_torque_metrics_tq_60_to_62_inside_the_window() -> None:
    t = np.arange(0.0, 40.0, 0.5)
    e = np.where(t < 5.0, 100.0, np.where(t % 1.0 == 0.0, 2.0, -2.0))
    m = torque_metrics(t, e, window_s=(5.0, 30.0))
    inside = np.count_nonzero((t >= 5.0) & (t <= 30.0))
    assert m["ise"] == pytest.approx(inside * 4.0 * 0.5)  # ∫ τ̃² dt with dt = 0.5 s
    assert m["mae"] == 2.0
    assert m["sd"] == pytest.approx(np.std(e[(t >= 5.0) & (t <= 30.0)]))


def test_convergence_time_is_the_start_of_the_final_stretch_below_threshold() -> None:
    t = np.arange(6.0)
    assert convergence_time(t, np.array([5.0, 0.5, 3.0, 0.4, 0.3, 0.2]), 1.0) == 3.0
    assert convergence_time(t, np.full(6, 0.1), 1.0) == 0.0
    assert convergence_time(t, np.array([0.1, 0.1, 0.1, 0.1, 0.1, 2.0]), 1.0) is None


def _truth(n: int, *, true_map: Table | None, scored: dict[str, np.ndarray]) -> ScenarioData:
    t = np.arange(n) * 0.5
    signals = Signals(t, {"a": np.linspace(0.0, 2.0, n), "b": np.full(n, 5.0)})
    return ScenarioData(
        "by-hand", 0, signals, {}, true_map=true_map, map_inputs=("a", "b"), scored_series=scored
    )


def test_score_run_output_rmse_over_accepted_finite_samples() -> None:
    residual = np.array([3.0, np.nan, 4.0, 100.0])
    status = np.array([0, 0, 0, 2], dtype=np.int8)
    assert score_run({"residual": residual}, status) == {"output_rmse": pytest.approx(12.5**0.5)}
    everything = score_run({"residual": residual}, None)["output_rmse"]
    assert everything == pytest.approx(((9 + 16 + 100**2) / 3) ** 0.5)
    assert score_run({"residual": residual[:2]}, np.array([1, 1], np.int8)) == {}
    assert score_run({"torque_nm": residual}, None) == {}


def test_score_run_scores_the_map_on_its_grid_only() -> None:
    true_map = Table(GRID, [[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    estimate = true_map.with_values(true_map.values + 0.5)
    n = 9
    truth = _truth(n, true_map=true_map, scored={})
    got = score_run({}, None, table=estimate, truth=truth)
    want = map_metrics(estimate, true_map, truth.scoring_points())
    assert got == want
    assert got["rmse"] == pytest.approx(0.5)
    other_grid = Table([Axis("a", "", [0.0, 2.0]), GRID[1]], 0.0)
    assert score_run({}, None, table=other_grid, truth=truth) == {}

    # with a scored series, the series takes "rmse" and the map's moves to "map_rmse"
    w_true = np.linspace(1.0, 2.0, n)
    truth = _truth(n, true_map=true_map, scored={"w": w_true})
    got = score_run({"w": w_true - 0.25}, None, table=estimate, truth=truth)
    assert got["map_rmse"] == pytest.approx(0.5)
    assert got["rmse"] == pytest.approx(0.25)


def test_score_run_skips_series_it_cannot_score() -> None:
    n = 20  # 10 s at 2 Hz: the torque window 5–30 s holds 10 samples
    tau = np.linspace(0.0, 50.0, n)
    truth = _truth(n, true_map=None, scored={"torque_nm": tau})
    got = score_run({"torque_nm": tau + 1.0}, None, truth=truth)
    assert got == series_metrics(truth, {"torque_nm": tau + 1.0})
    assert got["mae"] == pytest.approx(1.0)
    short = _truth(8, true_map=None, scored={"torque_nm": tau[:8]})  # 3.5 s: no window
    with pytest.raises(ShapeError, match="window"):
        series_metrics(short, {"torque_nm": tau[:8]})
    assert score_run({"torque_nm": tau[:8]}, None, truth=short) == {}
    with_nan = tau.copy()
    with_nan[3] = np.nan
    assert score_run({"torque_nm": with_nan}, None, truth=truth) == {}
