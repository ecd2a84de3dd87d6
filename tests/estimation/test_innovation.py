"""Innovation statistics (estimation/innovation.py, docs/tuning.md#innovations): the kernels'
innovation variances against a dense reference, and NIS against its χ² band."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2, norm

from estimation.errors import ConfigError
from estimation.innovation import (
    chi2_band,
    innovation_stats,
    log_likelihood,
    map_filter,
    output_error_stats,
    run_innovations,
    stats_of,
)
from estimation.signals import Signals

BREAKPOINTS = [0.0, 1.0, 2.0, 3.0, 4.0]
SIGMA_V = 0.5
P0 = 4.0


def linear_gaussian_log(n: int, seed: int) -> Signals:
    """``y = T(u) + v``: the cells of ``T`` drawn from N(0, P0), ``v ~ N(0, σv²)`` — exactly
    the model of a KF with ``θ0 = 0``, ``P0``, ``σw = 0`` and ``σv``."""
    rng = np.random.default_rng(seed)
    cells = rng.normal(0.0, math.sqrt(P0), len(BREAKPOINTS))
    u = rng.uniform(BREAKPOINTS[0], BREAKPOINTS[-1], n)
    y = np.interp(u, BREAKPOINTS, cells) + rng.normal(0.0, SIGMA_V, n)
    return Signals(np.arange(n) * 0.1, {"u": u, "y": y}, {"u": "rpm", "y": "ppm"})


def config(sigma_v: float = SIGMA_V, breakpoints: list[float] = BREAKPOINTS) -> dict:
    return {
        "axes": [{"name": "u", "breakpoints": breakpoints}],
        "output": "y",
        "output_unit": "ppm",
        "sigma_w": 0.0,
        "sigma_v": sigma_v,
        "p0": P0,
    }


def dense_kf_variances(signals: Signals, sigma_w: float, sigma_v: float) -> np.ndarray:
    """``S_k = ψ_kᵀ (P + σw² I) ψ_k + σv²`` of a dense KF written from the equations."""
    p = len(BREAKPOINTS)
    P = np.eye(p) * P0
    out = []
    for u in signals["u"]:
        psi = _hat(u)
        P = P + sigma_w**2 * np.eye(p)
        s = float(psi @ P @ psi + sigma_v**2)
        out.append(s)
        g = P @ psi / s
        P = P - np.outer(g, psi @ P)
    return np.array(out)


def _hat(u: float) -> np.ndarray:
    """Interpolation weights of ``u`` on :data:`BREAKPOINTS` (docs/algorithms.md §1)."""
    unit = np.eye(len(BREAKPOINTS))
    return np.array([np.interp(u, BREAKPOINTS, row) for row in unit])


def test_kernel_innovation_variance_is_the_dense_kalman_filters() -> None:
    signals = linear_gaussian_log(300, seed=1)
    cfg = config() | {"sigma_w": 0.05}
    run = run_innovations(map_filter("kf", cfg), signals)
    np.testing.assert_allclose(run.s, dense_kf_variances(signals, 0.05, SIGMA_V), rtol=1e-9)


def test_skf_equals_kf_when_both_cells_stay_active() -> None:
    """On a one-interval axis the two cells are always active, so SKF is the full KF."""
    signals = linear_gaussian_log(200, seed=2)
    cfg = config(breakpoints=[0.0, 4.0]) | {"sigma_w": 0.1}
    kf = run_innovations(map_filter("kf", cfg), signals)
    skf = run_innovations(map_filter("skf", cfg), signals)
    np.testing.assert_allclose(skf.s, kf.s, rtol=1e-12)
    np.testing.assert_allclose(skf.e, kf.e, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("estimator", ["sskf", "nlms"])
def test_covariance_free_filters_report_sigma_v_squared(estimator: str) -> None:
    signals = linear_gaussian_log(50, seed=3)
    cfg = {k: v for k, v in config().items() if k != "p0"}
    if estimator == "nlms":
        cfg.pop("sigma_w")
    run = run_innovations(map_filter(estimator, cfg), signals)
    assert np.all(run.s == SIGMA_V**2)


def test_right_noise_settings_give_nis_inside_the_chi2_band() -> None:
    run = run_innovations(map_filter("kf", config()), linear_gaussian_log(4000, seed=4))
    stats = stats_of(run)
    assert stats.samples == 4000
    lo, hi = stats.mean_nis_band
    assert lo < 1.0 < hi
    assert hi - lo < 0.2
    assert stats.consistent, stats
    assert 0.93 < stats.in_band < 0.97
    assert abs(stats.innovation_mean) < 3 * stats.innovation_rms / math.sqrt(4000)


@pytest.mark.parametrize(("factor", "side"), [(3.0, "below"), (1.0 / 3.0, "above")])
def test_wrong_sigma_v_puts_mean_nis_outside_the_band(factor: float, side: str) -> None:
    signals = linear_gaussian_log(4000, seed=5)
    stats = stats_of(run_innovations(map_filter("kf", config(SIGMA_V * factor)), signals))
    lo, hi = stats.mean_nis_band
    assert not stats.consistent
    assert (stats.mean_nis < lo) if side == "below" else (stats.mean_nis > hi)


def test_chi2_band_and_log_likelihood_match_their_definitions() -> None:
    lo, hi = chi2_band(1)
    assert lo == pytest.approx(0.000982069, rel=1e-5)
    assert hi == pytest.approx(5.023886, rel=1e-6)
    rng = np.random.default_rng(6)
    s = rng.uniform(0.5, 2.0, 100)
    e = rng.normal(0.0, np.sqrt(s))
    assert log_likelihood(e, s) == pytest.approx(float(np.sum(norm.logpdf(e, 0.0, np.sqrt(s)))))
    assert log_likelihood(e, np.where(np.arange(100) == 7, 0.0, s)) == -math.inf
    empty = innovation_stats(np.empty(0), np.empty(0))
    assert empty.samples == 0
    assert math.isnan(empty.mean_nis)


@pytest.mark.parametrize("dof", [1, 2, 3, 7.5, 40, 1_000, 262_144])
def test_chi2_band_is_scipy_stats_quantiles(dof: float) -> None:
    """The band comes from ``scipy.special`` (cheaper to import): the same quantiles as
    ``scipy.stats.chi2.ppf``, up to a large log's sample count."""
    lo, hi = chi2_band(dof, 0.9)
    assert lo == pytest.approx(chi2.ppf(0.05, dof), rel=1e-12, abs=1e-300)
    assert hi == pytest.approx(chi2.ppf(0.95, dof), rel=1e-12)
    assert lo < dof < hi


def test_only_map_filters_have_innovations() -> None:
    with pytest.raises(ConfigError, match="not a map filter"):
        map_filter("uio", {})


def _output_error_reference(e: np.ndarray, ok: np.ndarray) -> tuple[float, ...]:
    """Plain loops: mean, rms, their ratio, lag-1 autocorrelation over consecutive ok pairs."""
    vals = [float(v) for v, g in zip(e, ok, strict=True) if g]
    mean = sum(vals) / len(vals)
    rms = math.sqrt(sum(v * v for v in vals) / len(vals))
    num = sum((e[k] - mean) * (e[k - 1] - mean) for k in range(1, e.size) if ok[k] and ok[k - 1])
    den = sum((v - mean) ** 2 for v in vals)
    return mean, rms, mean / rms, num / den, 1.959963984540054 / math.sqrt(len(vals))


def test_output_error_stats_match_a_plain_reference_and_test_whiteness() -> None:
    """The LPV observer's covariance-free statistics: against plain loops (masked samples
    and pairs left out), and the white-noise band: an AR(1) error with φ = 0.8 falls
    outside it, white noise inside."""
    rng = np.random.default_rng(0)
    n = 4000
    white = 0.3 + rng.normal(0.0, 1.0, n)
    ok = rng.uniform(size=n) > 0.1
    got = output_error_stats(white, ok)
    ref = _output_error_reference(white, ok)
    assert got.samples == int(ok.sum())
    np.testing.assert_allclose(
        [got.mean, got.rms, got.mean_over_rms, got.autocorr_lag1, got.autocorr_band],
        ref,
        rtol=1e-9,
    )
    assert abs(got.autocorr_lag1) < got.autocorr_band
    ar = np.empty(n)
    ar[0] = 0.0
    for k in range(1, n):
        ar[k] = 0.8 * ar[k - 1] + rng.normal()
    assert output_error_stats(ar, np.ones(n, dtype=bool)).autocorr_lag1 == pytest.approx(
        0.8, abs=0.05
    )
    assert math.isnan(output_error_stats(white[:1], ok[:1]).mean)
