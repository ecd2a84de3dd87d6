"""Held-out prediction error of the air-path observers, and the LPV observer's check.

The map filters' check (:mod:`estimation.holdout`) for the LPV observer here and the three
EKFs (:mod:`estimation.holdout_ekf`, which shares :class:`ObserverHoldout` and the split),
docs/tuning.md#which-runs-report-what. Each fits on log samples ``0 … m−1``
(``m = round(fraction · n)``, default 70 %), freezes what it learned and predicts the
measured MAF reading ``y`` [kg/s] on samples ``m … n−1`` without ever reading it there;
``e_k = y_k − ŷ_k`` is scored (RMSE, mean ``|e|``, max ``|e|``) on the held-out samples the
run accepts, beside the same prediction with the unadapted parameters (the base).

**LPV observer** (LPV (26), docs/algorithms.md §3). Fit: the observer over the first part
(its LMI gain designed on that part's ρ box). Predict: the observer continues from its
state at ``m`` with ``θ̂`` frozen (every sample rejected: no adaptation) and the MAF column
of its gain ``L`` set to zero, so the MAF reading enters neither ``x̂`` nor ``θ̂``; it still
follows the measured ``p_im`` and ``ω_t``. ``ŷ_k = ρ1,k x̂3,k + ψ_kᵀθ̂`` (LPV (24)–(25)), the
base ``θ̂ = 0`` (the observer's start: the model flow alone). The observer has no error
covariance, so NIS does not exist for it; its output error of the fit pass,
``ε_k = y_k − ρ1,k x̂3,k − ψ_kᵀθ̂_k`` (the term of the adaptive law, at the end of each
backward-Euler sample), is summarised by :func:`~estimation.innovation.output_error_stats`.

**A log never held whole** (a streamed service run, docs/data-formats.md#streamed-runs):
:func:`lpv_holdout_windows` reads the log a window at a time and the row before each (the
observer's backward differences). It keeps the fit's output error and the scored errors, so
its figures are bit for bit.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np
from pydantic import BaseModel

from estimation.errors import ConfigError
from estimation.estimator import LogWindows
from estimation.holdout import DEFAULT_FIT_FRACTION, NotApplicable, split_point
from estimation.innovation import (
    InnovationStats,
    OutputErrorStats,
    output_error_stats,
)
from estimation.metrics import output_metrics
from estimation.observers.ekf import EkfObserver
from estimation.observers.lpv import LpvObserver, LpvPrepared, LpvState, lpv_run
from estimation.registry import get_spec
from estimation.signals import Signals

NO_COVARIANCE = NotApplicable(
    {"nis": "no_innovation_covariance"},
    "the LPV observer carries no error covariance, so its output error has no variance S "
    "to normalise by; its normalised output-error statistics (residual:*) stand in",
)


@dataclass(frozen=True, slots=True)
class ObserverHoldout:
    """An observer's held-out prediction error (module docstring).

    ``adapted``/``base`` hold ``rmse``, ``mae``, ``max_abs_error`` of the MAF prediction in
    ``unit`` (``base`` is ``None`` without parameters: EKF Def); ``other`` the same per
    further measured output (EKF ``outputs``, in its own unit); ``innovations`` the NIS of
    the fit pass's MAF updates and ``other_nis`` the mean NIS per further output (EKF);
    ``residual`` the fit pass's output-error statistics and ``not_applicable`` the checks
    that do not exist (LPV: NIS).
    """

    unit: str
    fraction: float
    fit_samples: int
    holdout_samples: int
    scored: int
    adapted: dict[str, float]
    base: dict[str, float] | None
    other: dict[str, dict[str, float]] = field(default_factory=dict)
    innovations: InnovationStats | None = None
    other_nis: dict[str, float] = field(default_factory=dict)
    residual: OutputErrorStats | None = None
    not_applicable: NotApplicable | None = None

    def metrics(self) -> dict[str, float | None]:
        """Flat run metrics: ``holdout:*`` (the map filters' names, MAF in kg/s;
        ``holdout:<output>_rmse`` for a further output), ``nis:*`` (EKF), ``residual:*``
        (LPV) and ``…:not_applicable:<reason>`` (``None``) for a check that does not exist."""
        out: dict[str, float | None] = {f"holdout:{k}": v for k, v in self.adapted.items()}
        if self.base is not None:
            out |= {f"holdout:base_{k}": v for k, v in self.base.items()}
        out["holdout:samples"] = float(self.scored)
        for name, errors in self.other.items():
            out[f"holdout:{name}_rmse"] = errors["rmse"]
        if self.innovations is not None:
            out |= self.innovations.metrics()
        out |= {f"nis:{name}_mean": v for name, v in self.other_nis.items()}
        if self.residual is not None:
            r = self.residual
            out |= {
                "residual:mean": r.mean,
                "residual:rms": r.rms,
                "residual:mean_over_rms": r.mean_over_rms,
                "residual:autocorr_lag1": r.autocorr_lag1,
                "residual:autocorr_band": r.autocorr_band,
            }
        if self.not_applicable is not None:
            out |= self.not_applicable.metrics()
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "unit": self.unit,
            "fraction": self.fraction,
            "fit_samples": self.fit_samples,
            "holdout_samples": self.holdout_samples,
            "scored": self.scored,
            "adapted": self.adapted,
            "base": self.base,
            "other": self.other,
            "innovations": None if self.innovations is None else self.innovations.to_dict(),
            "other_nis": self.other_nis,
            "residual": None if self.residual is None else self.residual.to_dict(),
            "not_applicable": None
            if self.not_applicable is None
            else self.not_applicable.to_dict(),
        }


Obs = TypeVar("Obs", LpvObserver, EkfObserver)


def built_observer(
    estimator: str, config: BaseModel | dict[str, Any], kind: type[Obs], noun: str
) -> Obs:
    """``estimator`` built from ``config``; a :class:`ConfigError` unless it is a ``kind``."""
    obs = get_spec(estimator).build(config)
    if not isinstance(obs, kind):
        raise ConfigError(f"{estimator!r} is not {noun}")
    return obs


def fit_split(n: int, fraction: float, accept: np.ndarray | None) -> tuple[int, np.ndarray]:
    """The first held-out sample of a log of ``n`` samples and its accept mask (all: ``None``)."""
    m = split_point(n, fraction)
    if m < 2 or n - m < 1:
        raise ConfigError(f"a log of {n} samples is too short to fit on {m} and predict the rest")
    mask = np.ones(n, dtype=np.bool_) if accept is None else np.asarray(accept, dtype=np.bool_)
    if mask.shape != (n,):
        raise ConfigError(f"accept mask has shape {mask.shape}, the log has {n} samples")
    return m, mask


# -- LPV --------------------------------------------------------------------------------------


def lpv_holdout(
    estimator: str,
    config: BaseModel | dict[str, Any],
    signals: Signals,
    *,
    fraction: float = DEFAULT_FIT_FRACTION,
    accept: np.ndarray | None = None,
) -> ObserverHoldout:
    """Fit the LPV observer ``estimator`` on the first ``fraction`` of ``signals`` and score
    its frozen map, and the zero map, on the rest (module docstring)."""
    obs = built_observer(estimator, config, LpvObserver, "the LPV observer")
    m, mask = fit_split(len(signals), fraction, accept)
    n = len(signals)
    c = obs.config
    fit_signals = signals.slice(0, m)
    fit_prep = obs.prepare(fit_signals, mask[:m])
    state = obs.initial_state(fit_signals, fit_prep)
    state, _, wc, dwc = lpv_run(state, fit_prep, 0, m, gamma=c.gamma, adaptation=c.adaptation)
    residual = fit_prep.y[:, 2] - wc - dwc
    adapted_y, base_y, prep = lpv_predict(obs, state, signals, mask)
    y = signals[c.maf]
    scored = prep.accept[m:]
    return ObserverHoldout(
        unit="kg/s",
        fraction=fraction,
        fit_samples=m,
        holdout_samples=n - m,
        scored=int(np.count_nonzero(scored)),
        adapted=output_metrics((y[m:] - adapted_y)[scored]),
        base=output_metrics((y[m:] - base_y)[scored]),
        residual=output_error_stats(residual, fit_prep.accept),
        not_applicable=NO_COVARIANCE,
    )


def lpv_predict(
    obs: LpvObserver, state: LpvState, signals: Signals, accept: np.ndarray
) -> tuple[np.ndarray, np.ndarray, LpvPrepared]:
    """The MAF reading predicted on samples ``state.step … n−1`` by the observer frozen at
    ``state``, and by the same observer with ``θ̂ = 0``: ``(adapted, base, prepared)``, the
    prepared log with the observer's own accept mask (the gates and, with
    ``adapt_only_with_flow``, ``ρ1 > 0``). ``E2 = a2 W_f`` uses the fitted ``a2``."""
    c = obs.config
    m, n = state.step, len(signals)
    prep = obs.prepare(signals, accept)
    frozen = _frozen(prep, state, signals[c.fuel_flow])
    out = []
    for start in _frozen_states(state):
        _, _, wc, dwc = lpv_run(start, frozen, m, n, gamma=c.gamma, adaptation=c.adaptation)
        out.append(wc + dwc)
    return out[0], out[1], prep


def _frozen(prepared: LpvPrepared, state: LpvState, fuel_flow: np.ndarray) -> LpvPrepared:
    """``prepared`` for a prediction from ``state``: every sample rejected (no adaptation) and
    ``E2 = a2 W_f`` with the fitted ``a2``."""
    e = prepared.e.copy()
    e[:, 1] = state.a2 * fuel_flow
    return dataclasses.replace(prepared, e=e, accept=np.zeros_like(prepared.accept))


def _frozen_states(state: LpvState) -> tuple[LpvState, LpvState]:
    """The adapted and the base (``θ̂ = 0``) observer a prediction runs from ``state``, with
    the MAF column of ``L`` set to zero so the MAF reading feeds nothing."""
    L = state.L_scaled.copy()
    L[:, 2] = 0.0
    return (
        dataclasses.replace(state, L_scaled=L, theta=state.theta.copy()),
        dataclasses.replace(state, L_scaled=L.copy(), theta=np.zeros_like(state.theta)),
    )


def lpv_holdout_windows(
    estimator: str,
    config: BaseModel | dict[str, Any],
    log: LogWindows,
    *,
    unit: str = "kg/s",
    fraction: float = DEFAULT_FIT_FRACTION,
) -> ObserverHoldout:
    """:func:`lpv_holdout` of a ``log`` that is never held whole: its rows are read
    ``log.window`` at a time (and the row before, for the backward differences). The fit is
    :meth:`~estimation.estimator.ChunkedEstimator.run_windows` over the first ``m`` rows,
    whose plan designs the gain on their ρ box as the whole-log fit does; the prediction
    carries the two frozen observers across the windows of the rest.
    The fit's output error and accept mask (about 35 bytes a fit sample while its
    statistics are taken) and then the scored prediction errors (16 bytes a held-out sample)
    are kept, so the metrics are :func:`lpv_holdout`'s bit for bit
    (``tests/estimation/test_holdout_observers.py``). ``unit`` is in the common signature of
    :data:`estimation.registry.HOLDOUT_WINDOWS`'s functions: the MAF error is in kg/s."""
    obs = built_observer(estimator, config, LpvObserver, "the LPV observer")
    read, n, window = log.read, log.n, log.window
    m, mask = fit_split(n, fraction, log.accept)
    c = obs.config
    residual, fit_accept = np.empty(m), np.empty(m, dtype=np.bool_)
    state: LpvState | None = None
    for snap in obs.run_windows(read, m, every=window, window=window, accept=mask[:m]):
        part = slice(snap.chunk_start, snap.sample)
        residual[part] = snap.outputs["residual"]
        fit_accept[part] = snap.status == 0
        state = snap.state
    assert state is not None
    residual_stats = output_error_stats(residual, fit_accept)
    del residual, fit_accept  # held no longer than the fit's statistics need them
    observers = list(_frozen_states(state))
    gains = {"gamma": c.gamma, "adaptation": c.adaptation}
    errors: list[list[np.ndarray]] = [[], []]  # the adapted and the base map's, scored
    for a in range(m, n, window):
        z = min(a + window, n)
        rows = read(a - 1, z)  # the row before: the backward differences of sample a
        prep = obs.prepare(rows, mask[a - 1 : z])
        frozen = dataclasses.replace(_frozen(prep, state, rows[c.fuel_flow]), offset=a - 1)
        y, scored = rows[c.maf][1:], prep.accept[1:]
        for i, observer in enumerate(observers):
            observers[i], _, wc, dwc = lpv_run(observer, frozen, a, z, **gains)
            errors[i].append((y - (wc + dwc))[scored])
    adapted, base = np.concatenate(errors[0]), np.concatenate(errors[1])
    return ObserverHoldout(
        unit=unit,
        fraction=fraction,
        fit_samples=m,
        holdout_samples=n - m,
        scored=int(adapted.size),
        adapted=output_metrics(adapted),
        base=output_metrics(base),
        residual=residual_stats,
        not_applicable=NO_COVARIANCE,
    )
