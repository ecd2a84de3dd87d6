"""The plain-numpy updates ``mapwise bench`` compares the kernels with (app/cli/bench_numpy.py)
compute the same maps as the kernels, so the speed-ups it reports compare like with like."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from app.cli.bench_filters import config_for, problem
from app.cli.bench_peers import _numpy_reference
from estimation.filters.functions import run_chunk
from estimation.registry import get_spec


def _prepared(name: str, *, uniform: bool) -> tuple[Any, Any]:
    signals, base = problem(5, 7, 800, seed=3, uniform=uniform)
    estimator = get_spec(name).build(config_for(name, base))
    prepared = estimator.prepare(signals)
    return prepared, estimator.initial_state(prepared)


@pytest.mark.parametrize("uniform", [False, True], ids=["drive", "uniform"])
@pytest.mark.parametrize("name", ["skf", "sskf", "rls", "nlms"])
def test_numpy_reference_gives_the_kernels_map(name: str, uniform: bool) -> None:
    prepared, start = _prepared(name, uniform=uniform)
    ours = run_chunk(start, prepared.idx, prepared.w, prepared.y, None, prepared.settings)[0]
    theirs = _numpy_reference(
        name, start.theta, prepared.idx, prepared.w, prepared.y, prepared.settings
    )
    assert not np.allclose(ours.theta, start.theta)  # the map moved
    np.testing.assert_allclose(ours.theta, theirs, rtol=1e-9, atol=1e-12)


def test_numpy_full_kf_gives_the_kernels_map_and_covariance() -> None:
    from app.cli import bench_numpy

    prepared, start = _prepared("kf", uniform=False)
    ours = run_chunk(start, prepared.idx, prepared.w, prepared.y, None, prepared.settings)[0]
    theta, P = bench_numpy.kf(
        start.theta,
        start.P,
        prepared.idx,
        prepared.w,
        prepared.y,
        sigma_w2=prepared.settings.sigma_w2,
        sigma_v2=prepared.settings.sigma_v2,
    )
    np.testing.assert_allclose(ours.theta, theta, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(ours.P, P, rtol=1e-9, atol=1e-12)
