"""Filter states: chunked runs, save / resume (JSON and npz) bit-identical to one run, the
procedure form agreeing with the class, and states that do not fit being refused."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from estimation.errors import StateError
from estimation.estimator import Snapshot
from estimation.filters.functions import initial_state, run_chunk, variance
from estimation.filters.settings import grid_of, resolve_settings
from estimation.filters.state import FilterState
from estimation.registry import get_spec
from tests.factories import KINDS, SENSOR_KINDS, Problem, Sensor, random_problem

SENSOR = Sensor(lag=0.7, delay=4, sigma_f=0.3)
CASES = [(k, None) for k in KINDS] + [(k, SENSOR) for k in SENSOR_KINDS]
IDS = [f"{k}{'-sensor' if s else ''}" for k, s in CASES]


def _problem(sensor: Sensor | None) -> Problem:
    return random_problem(21, shape=(4, 5), n=250, limit=True, sensor=sensor)


def _assert_states_equal(a: FilterState, b: FilterState) -> None:
    assert type(a) is type(b)
    for f in dataclasses.fields(a):
        va, vb = getattr(a, f.name), getattr(b, f.name)
        if isinstance(va, np.ndarray):
            assert va.dtype == vb.dtype, f.name
            assert_array_equal(va, vb, err_msg=f.name, strict=True)
        else:
            assert va == vb, f.name


def _joined(snaps: list[Snapshot]) -> tuple[np.ndarray, np.ndarray]:
    return (
        np.concatenate([s.outputs["prediction"] for s in snaps]),
        np.concatenate([s.status for s in snaps]),
    )


def _json_round_trip(state: FilterState) -> FilterState:
    data = json.loads(json.dumps(state.to_dict()))
    return type(state).from_dict(data)


def _npz_round_trip(state: FilterState, path: Path) -> FilterState:
    state.save(path)
    return FilterState.load(path)


@pytest.mark.parametrize(("kind", "sensor"), CASES, ids=IDS)
def test_chunked_runs_equal_one_run(kind: str, sensor: Sensor | None) -> None:
    problem = _problem(sensor)
    est = get_spec(kind).build(problem.config(kind))
    signals = problem.signals()
    whole = est.fit(signals, accept=problem.accept)
    assert whole.outputs["prediction"].size == problem.n
    for every in (1, 7, 37, problem.n + 5):
        snaps = list(est.run(signals, every=every, accept=problem.accept))
        prediction, status = _joined(snaps)
        assert_array_equal(prediction, whole.outputs["prediction"])  # NaNs in the same places
        assert_array_equal(status, whole.status)
        residual = np.concatenate([s.outputs["residual"] for s in snaps])
        assert_array_equal(residual, whole.outputs["residual"])
        assert_array_equal(residual, problem.y - prediction)
        assert [s.chunk_start for s in snaps[1:]] == [s.sample for s in snaps[:-1]]
        assert snaps[-1].done
        assert snaps[-1].sample == problem.n
        _assert_states_equal(snaps[-1].state, whole.state)
        assert snaps[-1].rejected == whole.rejected
        assert_array_equal(snaps[-1].table.values, whole.table.values)
        if whole.variance is not None:
            assert_array_equal(snaps[-1].variance, whole.variance)


@pytest.mark.parametrize(("kind", "sensor"), CASES, ids=IDS)
@pytest.mark.parametrize("how", ["json", "npz"])
def test_save_and_resume_is_bit_identical(
    kind: str, sensor: Sensor | None, how: str, tmp_path: Path
) -> None:
    problem = _problem(sensor)
    signals = problem.signals()
    whole = get_spec(kind).build(problem.config(kind)).fit(signals, accept=problem.accept)
    first = list(
        get_spec(kind).build(problem.config(kind)).run(signals, every=61, accept=problem.accept)
    )
    saved = first[1].state
    restored = (
        _json_round_trip(saved) if how == "json" else _npz_round_trip(saved, tmp_path / "s.npz")
    )
    _assert_states_equal(restored, saved)
    # A fresh estimator (as after a restart) resumes from the restored state.
    fresh = get_spec(kind).build(problem.config(kind))
    rest = list(fresh.run(signals, every=50, state=restored, accept=problem.accept))
    assert rest[0].chunk_start == first[1].sample
    prediction, status = _joined(first[:2] + rest)
    assert_array_equal(prediction, whole.outputs["prediction"])
    assert_array_equal(status, whole.status)
    _assert_states_equal(rest[-1].state, whole.state)
    assert rest[-1].rejected == whole.rejected
    assert_array_equal(rest[-1].table.values, whole.table.values)
    # The saved state was not mutated by resuming from it.
    _assert_states_equal(restored, saved)


@pytest.mark.parametrize("kind", KINDS)
def test_resume_from_the_final_state_is_a_no_op(kind: str) -> None:
    problem = _problem(None)
    est = get_spec(kind).build(problem.config(kind))
    whole = est.fit(problem.signals(), accept=problem.accept)
    (again,) = list(est.run(problem.signals(), state=whole.state, accept=problem.accept))
    assert again.done
    assert again.status.size == 0
    _assert_states_equal(again.state, whole.state)


@pytest.mark.parametrize(("kind", "sensor"), CASES, ids=IDS)
def test_procedure_form_agrees_with_the_class(kind: str, sensor: Sensor | None) -> None:
    problem = _problem(sensor)
    est = get_spec(kind).build(problem.config(kind))
    whole = est.fit(problem.signals(), accept=problem.accept)

    config = get_spec(kind).config_model.model_validate(problem.config(kind))
    grid = grid_of(config)
    settings = resolve_settings(config, grid)
    tau = sensor.delay if sensor else 0
    idx, w = grid.regressor(problem.U[: problem.n - tau])
    y = problem.y[tau:]
    accept = problem.accept[tau:] & problem.accept[: problem.n - tau]
    state = initial_state(kind, problem.theta0, settings, y_m0=float(y[0]) if sensor else None)
    predictions, statuses = [], []
    for start in range(0, y.size, 40):
        stop = start + 40
        before = state.copy()
        state, yhat, status = run_chunk(
            state, idx[start:stop], w[start:stop], y[start:stop], accept[start:stop], settings
        )
        _assert_states_equal(before, before.copy())
        predictions.append(yhat)
        statuses.append(status)
    _assert_states_equal(state, whole.state)
    assert_array_equal(np.concatenate(predictions), whole.outputs["prediction"][tau:])
    assert_array_equal(np.concatenate(statuses), whole.status[tau:])
    var = variance(state, settings)
    if whole.variance is None:
        assert var is None
    else:
        assert_array_equal(var, whole.variance.ravel())


def test_run_chunk_does_not_mutate_its_input_state() -> None:
    problem = _problem(SENSOR)
    for kind in SENSOR_KINDS:
        config = get_spec(kind).config_model.model_validate(problem.config(kind))
        grid = grid_of(config)
        settings = resolve_settings(config, grid)
        state = initial_state(kind, problem.theta0, settings, y_m0=1.0)
        snapshot = state.copy()
        idx, w = grid.regressor(problem.U[:50])
        run_chunk(state, idx, w, problem.y[:50], None, settings)
        _assert_states_equal(state, snapshot)


def test_a_state_of_another_filter_is_refused() -> None:
    problem = _problem(None)
    kf = get_spec("kf").build(problem.config("kf")).fit(problem.signals())
    skf = get_spec("skf").build(problem.config("skf"))
    with pytest.raises(StateError, match="'kf'"):
        list(skf.run(problem.signals(), state=kf.state))


def test_a_state_of_another_table_is_refused() -> None:
    small = random_problem(5, shape=(3, 3), n=40)
    big = random_problem(5, shape=(4, 5), n=40)
    state = get_spec("skf").build(small.config("skf")).fit(small.signals()).state
    with pytest.raises(StateError, match="9 cells"):
        list(get_spec("skf").build(big.config("skf")).run(big.signals(), state=state))


def test_a_state_past_the_end_of_the_log_is_refused() -> None:
    problem = _problem(None)
    est = get_spec("nlms").build(problem.config("nlms"))
    state = est.fit(problem.signals()).state
    short = random_problem(21, shape=(4, 5), n=100)
    with pytest.raises(StateError, match="step 250"):
        list(est.run(short.signals(), state=state))


def test_a_saved_state_lacking_fields_is_refused() -> None:
    problem = _problem(None)
    state = get_spec("kf").build(problem.config("kf")).fit(problem.signals()).state
    data = state.to_dict()
    del data["P"]
    with pytest.raises(StateError, match="lacks"):
        type(state).from_dict(data)


def test_npz_that_is_not_a_state_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "other.npz"
    np.savez(path, __class__="Something", __scalars__="{}")
    with pytest.raises(StateError, match="not a saved filter state"):
        FilterState.load(path)


@pytest.mark.parametrize("kind", ["kf", "skf"])
def test_base_from_dict_restores_the_full_state(kind: str) -> None:
    """``FilterState.from_dict`` (the documented entry point, like ``FilterState.load``) must
    give back the concrete state, not a bare ``FilterState`` without ``P``."""
    problem = _problem(None)
    state = get_spec(kind).build(problem.config(kind)).fit(problem.signals()).state
    data = json.loads(json.dumps(state.to_dict()))
    restored = FilterState.from_dict(data)
    assert type(restored) is type(state)
    _assert_states_equal(restored, state)
