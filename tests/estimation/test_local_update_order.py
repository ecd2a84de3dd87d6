"""The local filters' kernel defers each accepted sample's rank-1 covariance update to the
start of the next sample (estimation/kernels/local.py): when that sample keeps none of the
active elements, only the diagonal is updated and the local system restarts diagonal. Run
one sample per call, every update is applied at the end of its own call, as if at once: the
two must give the same bits, on 1-D to 3-D tables, with and without the sensor model, RLS
forgetting, limiting, the gate, the mask and locked cells."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from estimation.filters.functions import run_chunk
from estimation.filters.state import FilterState
from estimation.kernels.kalman import ACCEPTED
from estimation.registry import get_spec
from tests.factories import Sensor, random_problem

SHAPES = {"1d": (9,), "2d": (5, 4), "3d": (4, 3, 3)}
SENSOR = Sensor(lag=0.8, delay=3, sigma_f=0.2)
CASES = [
    (kind, dims, sensor, limit)
    for kind in ("skf", "rls")
    for dims in SHAPES
    for sensor in ((None, SENSOR) if kind == "skf" else (None,))
    for limit in (False, True)
]
IDS = [f"{k}-{d}{'-sensor' if s else ''}{'-limit' if lim else ''}" for k, d, s, lim in CASES]


def _bytes(state: FilterState) -> dict[str, bytes | object]:
    return {
        f.name: (v.tobytes() if isinstance(v, np.ndarray) else v)
        for f in dataclasses.fields(state)
        for v in [getattr(state, f.name)]
    }


def _run(kind: str, dims: str, sensor: Sensor | None, limit: bool, chunk: int):  # type: ignore[no-untyped-def]
    """The filter over the problem in calls of ``chunk`` samples: the final state, the
    predictions, statuses and innovation variances, and the regressor's cells."""
    problem = random_problem(11, shape=SHAPES[dims], n=500, limit=limit, sensor=sensor)
    estimator = get_spec(kind).build(problem.config(kind))
    prepared = estimator.prepare(problem.signals(), problem.accept)
    state = estimator.initial_state(prepared)
    n = prepared.y.size
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for start in range(0, n, chunk):
        sl = slice(start, min(start + chunk, n))
        s_out = np.empty(sl.stop - sl.start)
        state, yhat, status = run_chunk(
            state,
            prepared.idx[sl],
            prepared.w[sl],
            prepared.y[sl],
            prepared.accept[sl],
            prepared.settings,
            s_out=s_out,
        )
        parts.append((yhat, status, s_out))
    outputs = [np.concatenate(column) for column in zip(*parts, strict=True)]
    return state, outputs, prepared.idx


@pytest.mark.parametrize(("kind", "dims", "sensor", "limit"), CASES, ids=IDS)
def test_deferred_update_gives_the_bits_of_an_update_at_once(
    kind: str, dims: str, sensor: Sensor | None, limit: bool
) -> None:
    whole_state, whole_out, idx = _run(kind, dims, sensor, limit, chunk=10_000)
    each_state, each_out, _ = _run(kind, dims, sensor, limit, chunk=1)
    assert _bytes(whole_state) == _bytes(each_state)
    for whole, each in zip(whole_out, each_out, strict=True):
        assert whole.tobytes() == each.tobytes()
    # Both paths of the deferred update ran: accepted samples followed by a sample keeping
    # some of their elements, and by one keeping none of them.
    accepted = whole_out[1][:-1] == ACCEPTED
    kept = np.array([np.intersect1d(a, b).size for a, b in itertools.pairwise(idx)])
    assert np.any(accepted & (kept > 0))
    assert np.any(accepted & (kept == 0))
