"""The innovation sequence of a map filter and its statistics: a consistency check without truth.

A map filter (docs/algorithms.md §2) predicts each measurement before it uses it. Its
innovation and innovation variance at kernel step ``k`` are (docs/tuning.md#innovations)::

    e_k = y_k − ŷ_k                      ŷ_k = ψ_kᵀθ_k⁻  (or the sensor state y_M,k⁻)
    S_k = h_kᵀ P_k⁻ h_k + σv²            (KF, SKF; RLS: σv²·(h_kᵀP_k⁻h_k + 1); SSKF, NLMS: σv²)

If the filter's model and its noise settings σw, σv (σf) are right, the ``e_k`` are zero-mean,
white and ``e_k ~ N(0, S_k)`` (Bar-Shalom, Li & Kirubarajan, *Estimation with Applications
to Tracking and Navigation*, 2001, §5.4: the innovation-based consistency tests). Hence:

* the normalised innovation squared ``NIS_k = e_k²/S_k`` is χ²(1): 95 % of the samples fall
  in ``[χ²₁(0.025), χ²₁(0.975)] = [0.00098, 5.02]``;
* the time-averaged NIS over ``N`` samples, ``N · mean(NIS) ~ χ²(N)``, lies in
  ``[χ²_N(0.025)/N, χ²_N(0.975)/N]`` with 95 % probability (the band tightens around 1 as
  ``N`` grows); mean NIS above the band says the filter's ``S`` is too small (σw or σv too
  low, or the model wrong), below it says ``S`` is too large;
* the innovation log-likelihood of the log, the objective of ``mapwise tune``
  (:mod:`estimation.tuning`), is ``ℓ = Σ_k −½ (log 2πS_k + e_k²/S_k)``.

Only accepted kernel steps count (status 0): samples masked by a gate or rejected by the
innovation gate were not used by the filter and are left out. The χ² quantiles are
``scipy.stats.chi2``'s, computed from ``scipy.special`` (scipy ships with the solvers mapwise
depends on).

The run goes through the registry (:func:`estimation.registry.get_spec`) and the compiled
kernels (:func:`estimation.filters.functions.run_chunk`), one call over the whole log.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import BaseModel

from estimation.errors import ConfigError
from estimation.filters.estimator import REGRESSOR_BLOCK, Prepared, TableFilter
from estimation.filters.functions import run_chunk
from estimation.filters.state import FilterState
from estimation.registry import EstimatorKind, get_spec
from estimation.signals import Signals

BAND_PROBABILITY = 0.95
"""Probability mass of the χ² bands (two-sided, 2.5 % in each tail)."""

STATUS_ACCEPTED = 0


@dataclass(frozen=True, slots=True, eq=False)
class Innovations:
    """A map filter's pass over a log: per kernel step ``e``, ``S`` and the status code.

    Kernel step ``i`` pairs the measurement at log sample ``i + delay`` with the operating
    point at log sample ``i``. ``state`` is the filter state after the last step and
    ``estimator`` the filter that ran (its grid and initial map ``theta0``).
    """

    e: np.ndarray
    s: np.ndarray
    status: np.ndarray
    state: FilterState
    estimator: TableFilter
    prepared: Prepared

    @property
    def accepted(self) -> np.ndarray:
        return (self.status == STATUS_ACCEPTED) & np.isfinite(self.e) & (self.s > 0)


def map_filter(name: str, config: BaseModel | dict[str, Any]) -> TableFilter:
    """The map filter ``name`` built from ``config`` by its registry spec."""
    spec = get_spec(name)
    if spec.kind != EstimatorKind.MAP_FILTER:
        raise ConfigError(f"{name!r} is not a map filter; innovations need one")
    estimator = spec.build(config)
    if not isinstance(estimator, TableFilter):
        raise ConfigError(f"{name!r} does not run as a table filter")
    return estimator


def run_innovations(
    estimator: TableFilter, signals: Signals, accept: np.ndarray | None = None
) -> Innovations:
    """Run ``estimator`` over ``signals`` and keep ``e_k`` and ``S_k``: :func:`run_chunk` a
    :data:`REGRESSOR_BLOCK` of steps at a time, whose regressor rows (``c`` indices and
    weights a step) are made per block, so only the per-step results span the log; the
    kernel carries its state across blocks, so the result is that of one call."""
    prepared = estimator.prepare(signals, accept)
    state = estimator.initial_state(prepared)
    n = prepared.y.size
    s = np.empty(n)
    yhat = np.empty(n)
    status = np.empty(n, dtype=np.int8)
    for a in range(0, n, REGRESSOR_BLOCK):
        z = min(a + REGRESSOR_BLOCK, n)
        idx, w = prepared.regressor(a, z)
        state, yhat[a:z], status[a:z] = run_chunk(
            state, idx, w, prepared.y[a:z], prepared.accept[a:z], prepared.settings, s_out=s[a:z]
        )
    np.subtract(prepared.y, yhat, out=yhat)  # e = y − ŷ, in place of ŷ
    return Innovations(yhat, s, status, state, estimator, prepared)


def log_likelihood(e: np.ndarray, s: np.ndarray) -> float:
    """``ℓ = Σ −½ (log 2πS + e²/S)`` over the given samples (``-inf`` if any ``S ≤ 0``)."""
    if e.size and (not np.all(s > 0) or not np.all(np.isfinite(s))):
        return -math.inf
    return float(-0.5 * np.sum(np.log(2.0 * math.pi * s) + e * e / s))


def chi2_band(dof: float, probability: float = BAND_PROBABILITY) -> tuple[float, float]:
    """The two-sided ``probability`` band of a χ²(``dof``) variable."""
    tail = 0.5 * (1.0 - probability)
    return _chi2_ppf(tail, dof), _chi2_ppf(1.0 - tail, dof)


def _chi2_ppf(q: float, dof: float) -> float:
    """The χ²(``dof``) quantile ``2·P⁻¹(dof/2, q)``, with ``P⁻¹`` the inverse of the
    regularised lower incomplete gamma function; ``scipy.stats.chi2.ppf`` computes the same
    expression. ``scipy.special`` rather than ``scipy.stats``: every run's hold-out metrics
    ask for this band, and importing ``scipy.stats`` cost each new run worker about 0.5 s of
    CPU (docs/contributing.md#where-the-time-goes)."""
    from scipy.special import gammaincinv

    return float(2.0 * gammaincinv(0.5 * dof, q))


@dataclass(frozen=True, slots=True)
class InnovationStats:
    """The innovation statistics of one pass (module docstring); all dimensionless except
    ``innovation_mean`` and ``innovation_rms``, in the output's unit."""

    samples: int
    mean_nis: float
    mean_nis_band: tuple[float, float]
    in_band: float  # fraction of samples with NIS_k inside the per-sample χ²(1) band
    innovation_mean: float
    innovation_rms: float
    log_likelihood: float

    @property
    def consistent(self) -> bool:
        """Mean NIS inside its χ²(N)/N band."""
        lo, hi = self.mean_nis_band
        return lo <= self.mean_nis <= hi

    def metrics(self) -> dict[str, float]:
        """The run metrics ``nis:*`` (dimensionless; docs/tuning.md#which-runs-report-what)."""
        return {
            "nis:mean": self.mean_nis,
            "nis:mean_band_low": self.mean_nis_band[0],
            "nis:mean_band_high": self.mean_nis_band[1],
            "nis:in_band": self.in_band,
            "nis:innovation_mean": self.innovation_mean,
        }

    def to_dict(self) -> dict[str, Any]:
        return {
            "samples": self.samples,
            "mean_nis": self.mean_nis,
            "mean_nis_band": list(self.mean_nis_band),
            "consistent": self.consistent,
            "in_band": self.in_band,
            "innovation_mean": self.innovation_mean,
            "innovation_rms": self.innovation_rms,
            "log_likelihood": self.log_likelihood,
        }


def innovation_stats(e: np.ndarray, s: np.ndarray) -> InnovationStats:
    """Statistics of the innovations ``e`` with variances ``s`` (accepted samples only)."""
    n = int(e.size)
    if n == 0:
        nan = math.nan
        return InnovationStats(0, nan, (nan, nan), nan, nan, nan, nan)
    nis = e * e / s
    lo1, hi1 = chi2_band(1)
    lo, hi = chi2_band(n)
    return InnovationStats(
        samples=n,
        mean_nis=float(np.mean(nis)),
        mean_nis_band=(lo / n, hi / n),
        in_band=float(np.mean((nis >= lo1) & (nis <= hi1))),
        innovation_mean=float(np.mean(e)),
        innovation_rms=float(np.sqrt(np.mean(e * e))),
        log_likelihood=log_likelihood(e, s),
    )


@dataclass(slots=True)
class InnovationSums:
    """:func:`innovation_stats` of accepted steps that come a block at a time (a log read in
    windows): running sums, equal to the whole-array statistics up to rounding."""

    samples: int = 0
    nis: float = 0.0
    in_band: int = 0
    e: float = 0.0
    e2: float = 0.0
    log_terms: float = 0.0  # Σ log 2πS + NIS
    band: tuple[float, float] | None = None  # χ²(1) band, found on first use

    def add(self, e: np.ndarray, s: np.ndarray) -> None:
        """Add accepted steps' innovations ``e`` and variances ``s`` (all ``s > 0``)."""
        if not e.size:
            return
        if self.band is None:
            self.band = chi2_band(1)
        nis = e * e / s
        self.samples += int(e.size)
        self.nis += float(np.sum(nis))
        self.in_band += int(np.count_nonzero((nis >= self.band[0]) & (nis <= self.band[1])))
        self.e += float(np.sum(e))
        self.e2 += float(np.sum(e * e))
        self.log_terms += float(np.sum(np.log(2.0 * math.pi * s) + nis))

    def stats(self) -> InnovationStats:
        n = self.samples
        if n == 0:
            return innovation_stats(np.empty(0), np.empty(0))
        lo, hi = chi2_band(n)
        return InnovationStats(
            samples=n,
            mean_nis=self.nis / n,
            mean_nis_band=(lo / n, hi / n),
            in_band=self.in_band / n,
            innovation_mean=self.e / n,
            innovation_rms=math.sqrt(self.e2 / n),
            log_likelihood=-0.5 * self.log_terms,
        )


def stats_of(run: Innovations) -> InnovationStats:
    """:func:`innovation_stats` over the accepted steps of a pass."""
    ok = run.accepted
    return innovation_stats(run.e[ok], run.s[ok])


@dataclass(frozen=True, slots=True)
class OutputErrorStats:
    """Normalised statistics of an output error that has no variance to normalise by (the
    LPV observer's, docs/tuning.md#which-runs-report-what): ``mean`` and ``rms`` in the
    output's unit, and two dimensionless ones whose value under a zero-mean white error is
    known without a variance:

    * ``mean_over_rms = mean(e)/rms(e)`` in [−1, 1]: 0 unbiased, ±1 a pure offset;
    * ``autocorr_lag1 = Σ ẽ_k ẽ_{k−1} / Σ ẽ_k²`` (``ẽ = e − mean(e)``, over consecutive
      samples), inside ``±autocorr_band = ±1.96/√N`` for white noise with 95 % probability
      (Box & Jenkins, *Time Series Analysis*, §6.2: Bartlett's large-lag variance 1/N).
    """

    samples: int
    mean: float
    rms: float
    mean_over_rms: float
    autocorr_lag1: float
    autocorr_band: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "samples": self.samples,
            "mean": self.mean,
            "rms": self.rms,
            "mean_over_rms": self.mean_over_rms,
            "autocorr_lag1": self.autocorr_lag1,
            "autocorr_band": self.autocorr_band,
        }


WHITE_BAND_Z = 1.959963984540054
"""The two-sided 95 % point of N(0, 1), for the white-noise autocorrelation band."""


def output_error_stats(e: np.ndarray, ok: np.ndarray) -> OutputErrorStats:
    """:class:`OutputErrorStats` of the samples of ``e`` where ``ok`` holds; the lag-1 sum
    takes only pairs of consecutive samples that are both ``ok``."""
    e = np.asarray(e, dtype=np.float64)
    ok = np.asarray(ok, dtype=np.bool_) & np.isfinite(e)
    n = int(np.count_nonzero(ok))
    if n < 2:
        nan = math.nan
        return OutputErrorStats(n, nan, nan, nan, nan, nan)
    mean = float(np.mean(e[ok]))
    rms = float(np.sqrt(np.mean(e[ok] ** 2)))
    d = np.where(ok, e - mean, 0.0)
    pair = ok[1:] & ok[:-1]
    denom = float(np.sum(d * d))
    lag1 = float(np.sum((d[1:] * d[:-1])[pair]) / denom) if denom > 0 else math.nan
    return OutputErrorStats(
        samples=n,
        mean=mean,
        rms=rms,
        mean_over_rms=mean / rms if rms > 0 else math.nan,
        autocorr_lag1=lag1,
        autocorr_band=WHITE_BAND_Z / math.sqrt(n),
    )
