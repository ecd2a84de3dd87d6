"""The local filters' kernel defers each accepted sample's rank-1 covariance update to the
start of the next sample (estimation/kernels/local.py): when that sample keeps none of the
active elements, only the diagonal is updated and the local system restarts diagonal. Run
one sample per call, every update is applied at the end of its own call, as if at once: the
two must give the same bits, on 1-D to 3-D tables, with and without the sensor model, RLS
forgetting, limiting, the gate, the mask and locked cells."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from estimation.kernels.kalman import ACCEPTED
from tests.factories import ChunkedRun, Sensor, random_problem, run_in_chunks, state_bytes

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


def _run(kind: str, dims: str, sensor: Sensor | None, limit: bool, chunk: int) -> ChunkedRun:
    """The filter over the problem in calls of ``chunk`` samples."""
    problem = random_problem(11, shape=SHAPES[dims], n=500, limit=limit, sensor=sensor)
    return run_in_chunks(kind, problem, chunk)


def _outputs(run: ChunkedRun) -> list[np.ndarray]:
    """The predictions, statuses and innovation variances of the whole log."""
    return [np.concatenate(column) for column in zip(*run.outputs, strict=True)]


@pytest.mark.parametrize(("kind", "dims", "sensor", "limit"), CASES, ids=IDS)
def test_deferred_update_gives_the_bits_of_an_update_at_once(
    kind: str, dims: str, sensor: Sensor | None, limit: bool
) -> None:
    whole = _run(kind, dims, sensor, limit, chunk=10_000)
    each = _run(kind, dims, sensor, limit, chunk=1)
    assert state_bytes(whole.states[-1]) == state_bytes(each.states[-1])
    whole_out = _outputs(whole)
    for a, b in zip(whole_out, _outputs(each), strict=True):
        assert a.tobytes() == b.tobytes()
    # Both paths of the deferred update ran: accepted samples followed by a sample keeping
    # some of their elements, and by one keeping none of them.
    accepted = whole_out[1][:-1] == ACCEPTED
    kept = np.array([np.intersect1d(a, b).size for a, b in itertools.pairwise(whole.idx)])
    assert np.any(accepted & (kept > 0))
    assert np.any(accepted & (kept == 0))
