"""The peer sections of ``mapwise bench`` (:mod:`app.cli.bench`): the full KF from P0 and at
steady state against the plain-numpy update and FilterPy's ``KalmanFilter``, and SKF, SSKF,
RLS and NLMS against their plain-numpy updates (:mod:`app.cli.bench_numpy`); every peer must
give the kernel's map.
"""

from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np

from app.cli import bench_numpy
from app.cli.bench_filters import (
    NOX_FUEL_MG,
    NOX_SPEED_RPM,
    config_for,
    filter_rate,
    problem,
)
from app.cli.bench_timing import rates
from estimation.filters.functions import run_chunk
from estimation.filters.settings import FilterSettings
from estimation.registry import get_spec

DENSE = 0.9  # P counts as filled when this share of its entries is non-zero


def full_kf(n: int, quick: bool) -> dict[str, Any]:
    """The full KF on an n×n table, timed from P0 and at steady state, against the plain-numpy
    update (:func:`app.cli.bench_numpy.kf`) and FilterPy's ``KalmanFilter`` (dense
    predict/update, Joseph form) on the same samples.

    From P0 most of P is zero and the kernel skips zero rows of the rank-1 update, so it looks
    far faster than it is. Steady state is after a warm-up on the same drive log, run until
    at least :data:`DENSE` of P's entries are non-zero (or the warm-up budget runs out); every
    steady-state figure starts from that state. Each peer must give the kernel's map.
    """
    timed = 2_000 if quick else 10_000
    budget = 40_000 if quick else 200_000
    signals, base = problem(n, n, budget + timed, seed=16)
    estimator = get_spec("kf").build(config_for("kf", base))
    prepared = estimator.prepare(signals)
    settings = prepared.settings
    start = estimator.initial_state(prepared)

    def run(state: Any, first: int, count: int) -> Any:
        sl = slice(first, first + count)
        return run_chunk(
            state, prepared.idx[sl], prepared.w[sl], prepared.y[sl], prepared.accept[sl], settings
        )[0]

    from_p0 = rates(lambda: run(start, 0, timed), timed)
    density_from_p0 = _density(run(start, 0, timed).P)
    warm, used = start, 0
    while used < budget and _density(warm.P) < DENSE:
        warm = run(warm, used, 5_000)
        used += 5_000
    steady = rates(lambda: run(warm, used, timed), timed)

    n_numpy = 100 if quick else 500
    rows = slice(used, used + n_numpy)

    def numpy_kf() -> np.ndarray:
        return bench_numpy.kf(
            warm.theta, warm.P, prepared.idx[rows], prepared.w[rows], prepared.y[rows],
            sigma_w2=settings.sigma_w2, sigma_v2=settings.sigma_v2,
        )[0]  # fmt: skip

    numpy_rate = rates(numpy_kf, n_numpy)
    out: dict[str, Any] = {
        "n": n,
        "p": n * n,
        "timed_samples": timed,
        "from_p0": {"samples_per_s": from_p0, "p_nonzero_after": density_from_p0},
        "steady_state": {
            "warm_up_samples": used,
            "p_nonzero": _density(warm.P),
            "samples_per_s": steady,
        },
        "numpy": {
            "samples": n_numpy,
            "samples_per_s": numpy_rate,
            "same_map": _same(run(warm, used, n_numpy).theta, numpy_kf()),
        },
    }
    out["filterpy"] = _filterpy_kf(warm, prepared, used, 20 if quick else 100)
    return out


def _filterpy_kf(warm: Any, prepared: Any, first: int, samples: int) -> dict[str, Any]:
    """FilterPy's ``KalmanFilter`` from the warm state over ``samples`` samples (its cost does
    not depend on how full P is)."""
    try:
        from filterpy.kalman import KalmanFilter
    except ImportError:
        return {"available": False, "note": "pip install filterpy to compare"}
    settings = prepared.settings
    p = warm.theta.size
    H = np.zeros((samples, p))
    sl = slice(first, first + samples)
    np.put_along_axis(H, prepared.idx[sl], prepared.w[sl], axis=1)
    y = prepared.y[sl]

    def filterpy_run() -> np.ndarray:
        kf = KalmanFilter(dim_x=p, dim_z=1)
        kf.x = warm.theta.reshape(p, 1).copy()
        kf.P = warm.P.copy()
        kf.F = np.eye(p)
        kf.Q = np.diag(settings.sigma_w2)
        kf.R = np.array([[settings.sigma_v2]])
        for k in range(samples):
            kf.predict()
            kf.update(y[k], H=H[k : k + 1])
        return kf.x.ravel()

    ours = run_chunk(warm, prepared.idx[sl], prepared.w[sl], y, prepared.accept[sl], settings)[
        0
    ].theta
    return {
        "available": True,
        "samples": samples,
        "samples_per_s": rates(filterpy_run, samples),
        "same_map": _same(ours, filterpy_run()),
    }


def numpy_comparison(quick: bool) -> dict[str, Any]:
    """Each covariance-free or local filter against its plain-numpy update
    (:mod:`app.cli.bench_numpy`) on the 12×18 table and the same drive log: numpy over the
    log's first samples, the kernel over the whole log (too short a run times the call, not the
    kernel); both must give the same map over the first samples."""
    samples = 200_000 if quick else 1_000_000
    n_numpy = 500 if quick else 3_000
    signals, base = problem(len(NOX_SPEED_RPM), len(NOX_FUEL_MG), samples, seed=34)
    out: dict[str, Any] = {"shape": [len(NOX_SPEED_RPM), len(NOX_FUEL_MG)], "filters": {}}
    for name in ("skf", "sskf", "rls", "nlms"):
        estimator = get_spec(name).build(config_for(name, base))
        prepared = estimator.prepare(signals)
        settings = prepared.settings
        start = estimator.initial_state(prepared)
        sl = slice(0, n_numpy)
        idx, w, y = prepared.idx[sl], prepared.w[sl], prepared.y[sl]
        reference = partial(_numpy_reference, name, start.theta, idx, w, y, settings)
        ours = run_chunk(start, idx, w, y, prepared.accept[sl], settings)[0].theta
        kernel = filter_rate(name, signals, config_for(name, base), end_to_end=False, generic=False)
        numpy_rate = rates(reference, n_numpy)
        out["filters"][name] = {
            "kernel": kernel["kernel"],
            "numpy": numpy_rate,
            "numpy_samples": n_numpy,
            "speedup_cpu": kernel["kernel"]["cpu_median"] / numpy_rate["cpu_median"],
            "same_map": _same(ours, reference()),
        }
    return out


def _numpy_reference(
    name: str, theta0: np.ndarray, idx: np.ndarray, w: np.ndarray, y: np.ndarray,
    settings: FilterSettings,
) -> np.ndarray:  # fmt: skip
    """The map after the plain-numpy update of filter ``name`` over ``idx, w, y``."""
    if name in ("skf", "rls"):
        rls = name == "rls"
        return bench_numpy.local(
            theta0, idx, w, y, p0=settings.p0,
            sigma_w2=np.zeros_like(settings.sigma_w2) if rls else settings.sigma_w2,
            r=1.0 if rls else settings.sigma_v2, forget=settings.forgetting if rls else 1.0,
        )  # fmt: skip
    if name == "sskf":
        return bench_numpy.sskf(
            theta0, idx, w, y, sigma_w2=settings.sigma_w2, sigma_v2=settings.sigma_v2
        )
    return bench_numpy.nlms(theta0, idx, w, y, mu=settings.mu, eps=settings.eps)


def _density(P: np.ndarray) -> float:
    return float(np.count_nonzero(P)) / P.size


def _same(ours: np.ndarray, theirs: np.ndarray) -> bool:
    """The same map up to rounding (different summation orders)."""
    return bool(np.allclose(ours, theirs, rtol=1e-9, atol=1e-9 * max(1.0, np.max(np.abs(theirs)))))
