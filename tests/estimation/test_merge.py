"""Fleet map merge (estimation.merge) against the obvious per-cell loops."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from estimation.errors import ShapeError
from estimation.merge import merge_maps


def _slow(theta: np.ndarray, var: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = theta.shape[0]
    flat_t, flat_v = theta.reshape(n, -1), var.reshape(n, -1)
    mean, out_var, z = np.zeros(flat_t.shape[1]), np.zeros(flat_t.shape[1]), np.zeros_like(flat_t)
    for c in range(flat_t.shape[1]):
        w = [1.0 / flat_v[i, c] for i in range(n)]
        mean[c] = sum(w[i] * flat_t[i, c] for i in range(n)) / sum(w)
        out_var[c] = 1.0 / sum(w)
        for i in range(n):
            others = [j for j in range(n) if j != i]
            wo = sum(w[j] for j in others)
            mo = sum(w[j] * flat_t[j, c] for j in others) / wo
            z[i, c] = (flat_t[i, c] - mo) / np.sqrt(flat_v[i, c] + 1.0 / wo)
    return mean.reshape(theta.shape[1:]), out_var.reshape(theta.shape[1:]), z.reshape(theta.shape)


def test_inverse_variance_merge_matches_the_slow_reference() -> None:
    rng = np.random.default_rng(0)
    theta = rng.normal(100.0, 10.0, (5, 4, 6))
    var = rng.uniform(0.5, 50.0, (5, 4, 6))
    got = merge_maps(theta, var)
    mean, out_var, z = _slow(theta, var)
    assert_allclose(got.values, mean, rtol=1e-12)
    assert_allclose(got.variances, out_var, rtol=1e-12)
    assert_allclose(got.z, z, rtol=1e-9, atol=1e-12)
    assert_allclose(got.weights.sum(axis=0), 1.0)


def test_a_deviating_vehicle_stands_out_and_unvisited_cells_barely_count() -> None:
    rng = np.random.default_rng(1)
    truth = np.linspace(0.0, 50.0, 12).reshape(3, 4)
    theta = truth + rng.normal(0.0, 1.0, (8, 3, 4))
    var = np.ones((8, 3, 4))
    theta[3, 1, 2] += 20.0  # vehicle 3 differs in one cell
    theta[5, 0, 0], var[5, 0, 0] = 1e4, 1e8  # vehicle 5 never visited cell (0, 0)
    merged = merge_maps(theta, var)
    assert abs(merged.z[3, 1, 2]) > 10
    assert np.sum(np.abs(merged.z) > 5) == 1
    assert abs(merged.values[0, 0] - truth[0, 0]) < 3.0  # its prior hardly moves the merge
    assert merged.weights[5, 0, 0] < 1e-6


def test_visit_weighted_merge_without_variances() -> None:
    theta = np.array([[1.0, 2.0], [3.0, 6.0]])
    visits = np.array([[1.0, 0.0], [3.0, 0.0]])
    merged = merge_maps(theta, visits=visits)
    assert_allclose(merged.values, [2.5, 4.0])  # unvisited everywhere: plain mean
    assert merged.variances is None
    assert merged.z is None


def test_bad_shapes_and_variances_are_refused() -> None:
    with pytest.raises(ShapeError, match="vehicles"):
        merge_maps(np.ones(3), np.ones(3))
    with pytest.raises(ShapeError, match="positive"):
        merge_maps(np.ones((2, 2)), np.array([[1.0, 0.0], [1.0, 1.0]]))
    with pytest.raises(ShapeError, match="differs"):
        merge_maps(np.ones((2, 2)), np.ones((2, 3)))
    with pytest.raises(ShapeError, match="visit"):
        merge_maps(np.ones((2, 2)))
