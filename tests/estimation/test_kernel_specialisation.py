"""Kernels compiled for a fixed corner count (estimation/kernels/specialise.py) give the same
bits as the generic kernels: map, variances or covariance, predictions, statuses and
innovation variances, on 1-D, 2-D and 3-D tables, with and without the sensor model, with the
innovation gate, the accept mask, locked cells and covariance limiting."""

from __future__ import annotations

import numpy as np
import pytest
from numba.core import types as nb_types

from estimation.filters.state import FilterState
from estimation.kernels.gain_only import nlms_kernel, sskf_kernel
from estimation.kernels.kalman import ACCEPTED, REJECTED_GATE, REJECTED_MASK, kf_kernel
from estimation.kernels.local import local_kernel
from estimation.kernels.specialise import corner_token
from tests.factories import (
    KINDS,
    SENSOR_KINDS,
    Sensor,
    random_problem,
    run_in_chunks,
    state_bytes,
)

SHAPES = {"1d": (9,), "2d": (5, 4), "3d": (4, 3, 3), "4d": (3, 2, 2, 3)}
SENSOR = Sensor(lag=0.8, delay=3, sigma_f=0.2)
CASES = [
    (kind, dims, sensor, limit)
    for kind in KINDS
    for dims in SHAPES
    for sensor in ((None, SENSOR) if kind in SENSOR_KINDS else (None,))
    for limit in (False, True)
]
IDS = [f"{k}-{d}{'-sensor' if s else ''}{'-limit' if lim else ''}" for k, d, s, lim in CASES]
KERNELS = {"kf": kf_kernel, "skf": local_kernel, "rls": local_kernel}
KERNELS |= {"sskf": sskf_kernel, "nlms": nlms_kernel}


def _run_in_chunks(
    kind: str, dims: str, sensor: Sensor | None, limit: bool, *, specialised: bool
) -> tuple[list[FilterState], list[np.ndarray], np.ndarray]:
    """Three chunks of 200 samples or fewer (so the state carried between calls is compared
    too); the problem has outliers for the gate, a 10 % mask and two locked cells."""
    problem = random_problem(
        7, shape=SHAPES[dims], n=600, limit=limit, sensor=sensor, mask_rate=0.1
    )
    run = run_in_chunks(kind, problem, 200, specialised=specialised)
    return run.states, [array for chunk in run.outputs for array in chunk], run.idx


@pytest.mark.parametrize(("kind", "dims", "sensor", "limit"), CASES, ids=IDS)
def test_specialised_kernels_are_bit_identical_to_generic(
    kind: str, dims: str, sensor: Sensor | None, limit: bool
) -> None:
    fast_states, fast_out, idx = _run_in_chunks(kind, dims, sensor, limit, specialised=True)
    slow_states, slow_out, _ = _run_in_chunks(kind, dims, sensor, limit, specialised=False)
    for fast, slow in zip(fast_states, slow_states, strict=True):
        assert state_bytes(fast) == state_bytes(slow)
    for fast, slow in zip(fast_out, slow_out, strict=True):
        assert fast.dtype == slow.dtype
        assert fast.tobytes() == slow.tobytes()
    statuses = np.concatenate(fast_out[1::3])
    assert {ACCEPTED, REJECTED_MASK, REJECTED_GATE} <= set(statuses.tolist())
    assert len(set(map(tuple, idx))) > 1  # the active cell changes


@pytest.mark.parametrize("kind", KINDS)
def test_dispatch_compiles_one_kernel_per_corner_count(kind: str) -> None:
    """1-D, 2-D and 3-D tables run kernels typed with a size token of 2, 4, 8 elements; a 4-D
    table (16 corners) runs the generic kernel (empty token)."""
    for dims in SHAPES:
        _run_in_chunks(kind, dims, None, False, specialised=True)
    token_lengths = set()
    for signature in KERNELS[kind].signatures:
        tuples = [t for t in signature if isinstance(t, nb_types.BaseTuple)]
        token_lengths.add(len(tuples[0]))
    assert {0, 2, 4, 8} <= token_lengths
    assert corner_token(16) == ()
    assert corner_token(4) == (0, 0, 0, 0)
    assert corner_token(4, specialised=False) == ()
