"""The five map filters against slow dense references (tests/estimation/reference.py).

Random problems (tests/factories.py): irregular axes, inputs partly outside the grid, random
σw / P0 / θ0 per cell, locked cells, an accept mask, outliers the innovation gate rejects,
covariance limiting on and off, sensor lag and delay (KF, SKF); 1-D, 2-D and 3-D tables.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from estimation.errors import ConfigError, ShapeError
from estimation.estimator import Snapshot
from estimation.filters.settings import grid_of, resolve_settings
from estimation.registry import get_spec
from estimation.signals import Signals
from tests.estimation import reference as ref
from tests.factories import Problem, Sensor, random_problem

RTOL = 1e-9
SHAPES = [(6,), (5, 4), (3, 4, 3)]
SENSOR = Sensor(lag=0.8, delay=3, sigma_f=0.2)


def _cases() -> list:
    cases = []
    for shape in SHAPES:
        for kind in ("kf", "skf"):
            for limit in (False, True):
                for sensor in (None, SENSOR):
                    cases.append((kind, shape, limit, sensor))
        cases += [("rls", shape, False, None), ("rls", shape, True, None)]
        cases += [("sskf", shape, False, None), ("nlms", shape, False, None)]
    return cases


def _id(case: tuple) -> str:
    kind, shape, limit, sensor = case
    dims = "x".join(map(str, shape))
    return f"{kind}-{dims}-{'p0' if limit else 'nolimit'}{'-sensor' if sensor else ''}"


CASES = _cases()


def _close(actual: np.ndarray, desired: np.ndarray, what: str) -> None:
    scale = max(1.0, float(np.nanmax(np.abs(desired))))
    assert_allclose(actual, desired, rtol=RTOL, atol=1e-12 * scale, err_msg=what)


def _run(problem: Problem, kind: str) -> Snapshot:
    est = get_spec(kind).build(problem.config(kind))
    return est.fit(problem.signals(), accept=problem.accept)


@pytest.mark.parametrize("case", CASES, ids=[_id(c) for c in CASES])
def test_filter_matches_reference(case: tuple) -> None:
    kind, shape, limit, sensor = case
    seed = 1000 + CASES.index(case)
    problem = random_problem(seed, shape=shape, limit=limit, sensor=sensor)
    # The problem exercises what it claims to.
    lo = np.array([g[0] for g in problem.breakpoints])
    hi = np.array([g[-1] for g in problem.breakpoints])
    assert np.any(lo > problem.U)
    assert np.any(hi < problem.U)
    assert problem.locked.sum() == 2

    want = ref.reference(problem, kind)
    got = _run(problem, kind)

    assert want.n_mask > 0
    assert want.n_gate > 0
    assert want.n_gate < 0.25 * problem.n  # the gate rejects outliers, not the data
    assert got.rejected["mask"] == want.n_mask
    assert got.rejected["innovation"] == want.n_gate
    assert_array_equal(got.status, want.status)
    _close(got.outputs["prediction"], want.prediction, "prediction")
    if sensor is not None:
        assert np.all(np.isnan(got.outputs["prediction"][: sensor.delay]))
        assert np.all(got.status[: sensor.delay] == 3)
    _close(got.table.values.ravel(), want.theta, "theta")
    assert got.table.shape == shape

    locked = problem.locked
    # Locked cells are known constants: bit-exactly untouched.
    assert_array_equal(got.table.values.ravel()[locked], problem.theta0[locked])
    if kind in ("sskf", "nlms"):
        assert got.variance is None
        return
    _close(got.variance.ravel(), want.variance, "variance")
    assert_array_equal(got.variance.ravel()[locked], problem.p0[locked])
    if limit:  # the cap was reached somewhere, and never exceeded
        free = ~locked
        assert np.all(want.variance[free] <= problem.p0[free] * (1 + 1e-12))
        assert np.any(np.isclose(want.variance[free], problem.p0[free], rtol=1e-12))
    state = got.state
    if kind == "kf":
        _close(state.P, want.P, "P")
        assert_array_equal(state.P, state.P.T)
    else:
        # The active block of the lazy implementation is the block of the dense reference.
        active = list(state.active)
        assert set(active) == want.active
        rows = active + ([problem.size] if sensor is not None else [])
        _close(state.P_active, want.P[np.ix_(rows, rows)], "P_active")
    if sensor is not None:
        _close(np.array(state.y_m), np.array(want.y_m), "y_m")


@pytest.mark.parametrize("sensor", [None, SENSOR], ids=["plain", "sensor"])
def test_skf_reference_differs_from_kf(sensor: Sensor | None) -> None:
    """The comparison above can tell SKF from KF: forgetting cross-covariances matters."""
    problem = random_problem(7, shape=(5, 4), sensor=sensor)
    kf, skf = ref.reference(problem, "kf"), ref.reference(problem, "skf")
    assert np.max(np.abs(kf.theta - skf.theta)) > 1e-3
    got = _run(problem, "skf")
    assert np.max(np.abs(got.table.values.ravel() - kf.theta)) > 1e-3


def test_locked_cells_without_gate_or_mask() -> None:
    """Every active corner locked: nothing may move; a table with no free weight still runs."""
    problem = random_problem(3, shape=(2, 2), n=60, n_locked=4, gate_sigma=None, mask_rate=0)
    for kind in ("kf", "skf", "rls", "sskf", "nlms"):
        got = _run(problem, kind)
        assert_array_equal(got.table.values.ravel(), problem.theta0)
        assert np.all(got.status == 0)
        want = ref.reference(problem, kind)
        _close(got.outputs["prediction"], want.prediction, kind)


# --- configuration errors -------------------------------------------------------------------

BASE = {"axes": [{"name": "u1", "breakpoints": [0.0, 1.0, 2.0]}], "output": "y"}
TINY = Signals([0.0, 1.0, 2.0], {"u1": [0.0, 1.5, 3.0], "y": [1.0, 2.0, 3.0]})


def _build_and_run(kind: str, config: dict) -> None:
    """Some checks need the grid (per-cell values), so they may fire at build or at run."""
    get_spec(kind).build(config).fit(TINY)


@pytest.mark.parametrize(
    ("kind", "extra", "match"),
    [
        ("kf", {"sigma": 1.0}, "sigma: Extra inputs are not permitted"),
        ("sskf", {"p0": 1.0}, "p0: Extra inputs"),
        ("nlms", {"sensor": {"lag": 0.5}}, "sensor: Extra inputs"),
        ("skf", {"sensor": {"lag": 0.5, "colour": 1}}, "sensor.colour"),
        ("kf", {"sigma_v": -1.0}, "sigma_v"),
        ("kf", {"sigma_v": 0.0}, "sigma_v"),
        ("skf", {"sigma_w": -0.1}, "sigma_w"),
        ("sskf", {"sigma_w": [1.0, -1.0, 1.0]}, "sigma_w"),
        ("kf", {"p0": -1.0}, "p0"),
        ("kf", {"limit": "p0"}, "limit='p0'.*P0"),
        ("skf", {"limit": "p0", "p0": [1.0, 0.0, 1.0]}, "limit='p0'.*P0"),
        ("rls", {"limit": "p0", "p0": 0.0}, "limit='p0'.*P0"),
        ("kf", {"limit": "cap"}, "limit"),
        ("kf", {"locked": [[3]]}, r"locked: cell \[3\] is not inside a table of shape \[3\]"),
        ("skf", {"locked": [[0, 0]]}, "locked"),
        ("nlms", {"locked": [[-1]]}, "locked"),
        ("kf", {"gate_sigma": 0.0}, "gate_sigma"),
        ("rls", {"forgetting": 1.5}, "forgetting"),
        ("nlms", {"mu": 2.0}, "mu"),
        ("kf", {"sensor": {"lag": 1.0}}, "sensor.lag"),
        ("kf", {"axes": [{"name": "u1", "breakpoints": [0.0, 0.0]}]}, "axes.0.breakpoints"),
        ("kf", {"axes": []}, "axes"),
    ],
)
def test_config_errors_name_the_field(kind: str, extra: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        _build_and_run(kind, BASE | extra)


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        ({"sigma_w": [1.0, 1.0]}, r"sigma_w: expected a scalar or shape \(3,\)"),
        ({"p0": [[1.0, 1.0, 1.0]]}, r"p0: expected a scalar or shape \(3,\)"),
        ({"theta0": [1.0, np.nan, 1.0]}, r"theta0: non-finite value nan at cell \(1,\)"),
    ],
)
def test_cell_values_of_the_wrong_shape_name_the_field(extra: dict, match: str) -> None:
    """Per-cell values are checked against the grid; the error is a ShapeError (an
    EstimationError and a ValueError), not a ConfigError."""
    with pytest.raises(ShapeError, match=match):
        _build_and_run("kf", BASE | extra)


def test_config_errors_from_resolve_settings() -> None:
    config = get_spec("kf").config_model.model_validate(BASE | {"sigma_w": -2.0})
    with pytest.raises(ConfigError, match="sigma_w must be >= 0, got -2"):
        resolve_settings(config, grid_of(config))
    config = get_spec("kf").config_model.model_validate(BASE | {"limit": "p0", "p0": 0.0})
    with pytest.raises(ConfigError, match="limit='p0'"):
        resolve_settings(config, grid_of(config))
    # P0 = 0 is allowed on locked cells, which are never capped.
    config = get_spec("kf").config_model.model_validate(
        BASE | {"limit": "p0", "p0": [0.0, 1.0, 1.0], "locked": [[0]]}
    )
    assert resolve_settings(config, grid_of(config)).limit


def test_unknown_estimator_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="unknown estimator 'ekf'"):
        get_spec("ekf")
