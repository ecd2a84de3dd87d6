"""Every registered estimator keeps the one contract of :mod:`estimation.registry`.

For each spec, on a short stretch of the first scenario it applies to: the estimator is the
declared kind, yields exactly the series its ``output_units`` name, reads exactly the
channels its signal roles name, produces states of its ``state_class`` that survive
``to_dict`` → JSON → :func:`load_state`, and resumes from such a state to the uninterrupted
result, bit for bit.
"""

from __future__ import annotations

import json
from functools import cache

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from estimation.errors import ConfigError, StateError
from estimation.estimator import ChunkedEstimator, Estimator, Snapshot
from estimation.filters.functions import FILTER_KINDS
from estimation.registry import (
    ROLES,
    EstimatorKind,
    EstimatorSpec,
    get_spec,
    load_state,
    names,
    registry,
)
from estimation.scenarios import ScenarioData, scenarios
from estimation.state import EstimatorState

DURATION_S = {"torque-si": 6.0, "torque-rig": 6.0}  # 1 kHz; others ≤ 10 Hz
CHUNKS = 3


@cache
def _data(scenario: str) -> ScenarioData:
    """60 s of ``scenario`` (6 s of the 1 kHz ones), built once for all its estimators."""
    return scenarios()[scenario].build(seed=0, duration_s=DURATION_S.get(scenario, 60.0))


@cache
def _case(name: str) -> tuple[dict, ScenarioData]:
    """The default config of ``name`` on the first scenario it applies to, and 60 s of it."""
    for scenario in scenarios().values():
        config = scenario.configs(name)
        if config is not None:
            return config, _data(scenario.name)
    raise AssertionError(f"no scenario applies to {name!r}")


@cache
def _runs(name: str) -> tuple[Snapshot, tuple[Snapshot, ...]]:
    """The uninterrupted run and the same run in ``CHUNKS`` chunks."""
    config, data = _case(name)
    estimator = get_spec(name).build(config)
    whole = estimator.fit(data.signals)
    every = len(data.signals) // CHUNKS + 1
    return whole, tuple(estimator.run(data.signals, every=every))


def _assert_states_equal(a: EstimatorState, b: EstimatorState) -> None:
    assert type(a) is type(b)
    saved = b.to_dict()
    for name, value in a.to_dict().items():
        if name not in a.ARRAYS:
            assert value == saved[name], name
    for name in a.ARRAYS:
        got, want = getattr(a, name), getattr(b, name)
        assert got.dtype == want.dtype, name
        assert_array_equal(got, want, err_msg=name)


def test_names_partition_the_registry_by_kind() -> None:
    by_kind = {kind: names(kind) for kind in EstimatorKind}
    assert names() == tuple(registry())
    assert sorted(n for group in by_kind.values() for n in group) == sorted(names())
    for kind, group in by_kind.items():
        assert group, f"no estimator of kind {kind}"
        assert all(get_spec(n).kind is kind for n in group)
    assert by_kind[EstimatorKind.MAP_FILTER] == FILTER_KINDS  # the kernels' dispatch table


def test_get_spec_names_the_choices() -> None:
    with pytest.raises(ConfigError, match=r"unknown estimator 'kalman'.*'ekf-map'.*'uio'"):
        get_spec("kalman")


def test_load_state_refuses_unknown_or_missing_tags() -> None:
    with pytest.raises(StateError, match="unknown estimator state class 'Nope'"):
        load_state({"state_class": "Nope", "kind": "kf", "step": 0})
    with pytest.raises(StateError, match="no state_class"):
        load_state({"kind": "kf", "step": 0})


def test_states_stored_before_the_registry_still_load() -> None:
    """The stored format (keys, ``{"dtype", "shape", "data"}`` arrays, class names) is fixed:
    these dicts are what the service wrote before the states shared a base class."""
    theta = {"dtype": "float64", "shape": [2, 1], "data": [1.5, -2.0]}
    state = load_state(
        {"state_class": "ThetaState", "kind": "nlms", "step": 7, "rejected_mask": 1}
        | {"rejected_gate": 2, "theta": theta}
    )
    assert (type(state).__name__, state.kind, state.step) == ("ThetaState", "nlms", 7)
    assert_array_equal(state.theta, [[1.5], [-2.0]])
    empty = {"dtype": "float64", "shape": [0, 0], "data": []}
    torque = load_state(
        {"state_class": "TorqueState", "kind": "uio", "step": 3}
        | {"x": {"dtype": "float64", "shape": [2], "data": [1.0, 2.0]}, "P": empty}
        | {"Q": {"dtype": "float64", "shape": [0], "data": []}, "R": empty}
        | {"theta": {"dtype": "float64", "shape": [0], "data": []}}
    )
    assert type(torque).__name__ == "TorqueState"
    assert torque.P.shape == (0, 0)
    counts = {"dtype": "int64", "shape": [2], "data": [0, 4]}
    ekf = load_state(
        {"state_class": "EkfState", "kind": "ekf-def", "step": 5, "rejected_mask": 0}
        | {"rejected_gate": 0, "counts": counts, "x": theta, "P": empty, "mem": theta}
    )
    assert ekf.counts.dtype == np.int64
    assert ekf.to_dict()["counts"] == counts


@pytest.mark.parametrize("name", names())
def test_the_spec_describes_what_the_estimator_does(name: str) -> None:
    spec: EstimatorSpec = get_spec(name)
    config, data = _case(name)
    estimator: Estimator = spec.build(config)
    assert isinstance(estimator, ChunkedEstimator)
    assert estimator.name == name
    whole, chunks = _runs(name)

    # kind and map: map kinds report a table, the torque estimators none
    assert (whole.table is not None) is spec.produces_map
    if spec.kind in (EstimatorKind.MAP_FILTER, EstimatorKind.MAP_OBSERVER):
        assert spec.produces_map
    if spec.kind is EstimatorKind.TORQUE:
        assert not spec.produces_map

    # outputs: every series has a declared unit, and every declared series is produced
    assert set(spec.output_units) == set(estimator.output_names())
    for snap in (whole, *chunks):
        assert set(snap.outputs) == set(spec.output_units), snap.chunk_start
        for values in snap.outputs.values():
            assert values.shape == (snap.sample - snap.chunk_start,)

    # roles: known roles, existing channels, together exactly what the estimator reads
    roles = spec.signal_roles(config)
    assert set(roles) <= set(ROLES)
    read = [c for channels in roles.values() for c in channels]
    assert sorted(set(read)) == sorted(set(estimator.required_signals()))
    assert all(c in data.signals for c in read)
    if spec.kind is EstimatorKind.MAP_FILTER:
        assert roles["output"] == [config["output"]]
        assert roles["axis"] == [a["name"] for a in config["axes"]]
    assert bool(roles.get("axis")) is (whole.table is not None)

    entry = spec.catalog_entry()
    assert entry["kind"] == spec.kind.value
    json.dumps(entry)


@pytest.mark.parametrize("name", names())
def test_states_round_trip_and_resume_bit_for_bit(name: str) -> None:
    spec = get_spec(name)
    config, data = _case(name)
    whole, chunks = _runs(name)
    assert len(chunks) == CHUNKS
    assert type(whole.state) is spec.state_class
    _assert_states_equal(chunks[-1].state, whole.state)

    first = chunks[0]
    saved = json.loads(json.dumps(first.state.to_dict()))
    assert saved["state_class"] == spec.state_class.__name__
    restored = load_state(saved)
    _assert_states_equal(restored, first.state)
    assert type(spec.state_class.from_dict(saved)) is spec.state_class

    rest = list(spec.build(config).run(data.signals, state=restored))
    _assert_states_equal(rest[-1].state, whole.state)
    for key, full in whole.outputs.items():
        tail = np.concatenate([r.outputs[key] for r in rest])
        assert_array_equal(tail, full[first.sample :], err_msg=key)
    if whole.table is not None:
        assert_array_equal(rest[-1].table.values, whole.table.values)
