"""Held-out prediction error and innovation statistics of the air-path observers.

The map filters' check (:mod:`estimation.holdout`) for the LPV observer and the three EKFs
(docs/tuning.md#which-runs-report-what). Each fits on log samples ``0 … m−1``
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

**EKF** (docs/algorithms.md §4). Fit: the filter over the first part, with its innovations
``e_j`` and variances ``S_j`` per used output (kept by :func:`~estimation.kernels.ekf.ekf_kernel`);
NIS of the MAF updates the χ² gate accepted, as :mod:`estimation.innovation`. Predict: the
filter continues from its posterior at ``m − 1`` with every sample masked, i.e. the model
propagated open loop from the inputs with the bias ``b`` (Aug) or map ``θ`` (Map) frozen;
``ŷ_k`` is its prior output (MAF, and the other outputs in ``outputs``). The base resets
``b = 0`` / ``θ = θ0`` at ``m``; Def has no parameters and no base.

**A log never held whole** (a streamed service run, docs/data-formats.md#streamed-runs):
:func:`lpv_holdout_windows` and :func:`ekf_holdout_windows` read the log a window at a time
and the row before each (the observers' backward differences and propagation). The LPV form
keeps the fit's output error and the scored errors, so its figures are bit for bit; the EKF
form adds to running sums, equal up to rounding.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np
from pydantic import BaseModel

from estimation.errors import ConfigError
from estimation.estimator import LogWindows
from estimation.holdout import DEFAULT_FIT_FRACTION, NotApplicable, split_point
from estimation.innovation import (
    InnovationStats,
    InnovationSums,
    OutputErrorStats,
    innovation_stats,
    output_error_stats,
)
from estimation.kernels import ekf as kern
from estimation.metrics import ErrorSums, output_metrics
from estimation.observers.ekf import EkfModel, EkfObserver, EkfSettings, EkfState, ekf_run
from estimation.observers.ekf_config import OUTPUT_NAMES
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


def _built(estimator: str, config: BaseModel | dict[str, Any], kind: type[Obs], noun: str) -> Obs:
    """``estimator`` built from ``config``; a :class:`ConfigError` unless it is a ``kind``."""
    obs = get_spec(estimator).build(config)
    if not isinstance(obs, kind):
        raise ConfigError(f"{estimator!r} is not {noun}")
    return obs


def _split(n: int, fraction: float, accept: np.ndarray | None) -> tuple[int, np.ndarray]:
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
    obs = _built(estimator, config, LpvObserver, "the LPV observer")
    m, mask = _split(len(signals), fraction, accept)
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
    obs = _built(estimator, config, LpvObserver, "the LPV observer")
    read, n, window = log.read, log.n, log.window
    m, mask = _split(n, fraction, log.accept)
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


# -- EKF --------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class EkfInnovations:
    """An EKF pass with its innovations: the state after it, per sample and output ``e``,
    ``S`` (n, 4) in ``Y_*`` order (NaN where not used or masked) and the status codes."""

    state: EkfState
    e: np.ndarray
    s: np.ndarray
    status: np.ndarray
    outputs: dict[str, np.ndarray]


def ekf_innovations(
    state: EkfState, model: EkfModel, settings: EkfSettings, stop: int
) -> EkfInnovations:
    """:func:`~estimation.observers.ekf.ekf_run` from ``state`` to ``stop``, keeping every
    scalar update's ``e`` and ``S`` (the ``e_out``, ``s_out`` of
    :func:`~estimation.kernels.ekf.ekf_kernel`)."""
    start = state.step
    out = state.copy()
    k = stop - start
    x_out = np.empty((k, kern.N_X))
    w_c, corr = np.empty(k), np.empty(k)
    yhat = np.empty((k, kern.N_Y))
    status = np.empty(k, dtype=np.int8)
    e, s = np.empty((k, kern.N_Y)), np.empty((k, kern.N_Y))
    kern.ekf_kernel(
        out.x, out.P, out.mem, out.counts, settings.mode, settings.g, model.time_s, model.U,
        model.Y, settings.use, settings.r_abs2, settings.r_rel2, model.accept,
        settings.q_rate, settings.p0_diag, settings.limit, settings.gate2,
        settings.max_step_s, settings.prm, start - model.offset, stop - model.offset, x_out,
        w_c, yhat, corr, status, e, s,
    )  # fmt: skip
    outputs = {"w_c_kg_s": w_c, "x": x_out, "yhat": yhat}
    return EkfInnovations(dataclasses.replace(out, step=stop), e, s, status, outputs)


def ekf_holdout(
    estimator: str,
    config: BaseModel | dict[str, Any],
    signals: Signals,
    *,
    fraction: float = DEFAULT_FIT_FRACTION,
    accept: np.ndarray | None = None,
) -> ObserverHoldout:
    """Fit EKF ``estimator`` on the first ``fraction`` of ``signals``, with its NIS, and
    score its open-loop prediction with frozen parameters on the rest (module docstring)."""
    obs = _built(estimator, config, EkfObserver, "an EKF")
    m, mask = _split(len(signals), fraction, accept)
    n = len(signals)
    settings = obs.settings
    model = obs.prepare(signals, mask)  # sample k reads only samples ≤ k
    fit = ekf_innovations(obs.initial_state(model), model, settings, m)
    used, primary = _ekf_outputs(settings)
    stats = {}
    for j in used:
        ok = _gate_passed(fit.e[:, j], fit.s[:, j], settings.gate2)
        stats[j] = innovation_stats(fit.e[ok, j], fit.s[ok, j])
    adapted = ekf_predict(fit.state, model, settings, reset=False)
    base = None if settings.mode == kern.MODE_DEF else ekf_predict(fit.state, model, settings)
    scored = mask[m:]

    def errors(prediction: np.ndarray, j: int) -> dict[str, float]:
        return output_metrics((model.Y[m:, j] - prediction[:, j])[scored])

    return _ekf_result(
        settings,
        fraction=fraction,
        split=(m, n, int(np.count_nonzero(scored))),
        stats=stats,
        adapted={j: errors(adapted, j) for j in used},
        base=None if base is None else errors(base, primary),
    )


def _ekf_outputs(settings: EkfSettings) -> tuple[list[int], int]:
    """The used outputs (``Y_*`` indices) and the one scored first: the MAF if used."""
    used = [j for j, name in enumerate(OUTPUT_NAMES) if settings.use[j]]
    return used, kern.Y_MAF if settings.use[kern.Y_MAF] else used[0]


def _gate_passed(e: np.ndarray, s: np.ndarray, gate2: float) -> np.ndarray:
    """The scalar updates the χ² gate accepted (the kernel's test)."""
    return np.isfinite(e) & (s > 0) & ~(e * e > gate2 * s)


def _ekf_result(
    settings: EkfSettings,
    *,
    fraction: float,
    split: tuple[int, int, int],
    stats: dict[int, InnovationStats],
    adapted: dict[int, dict[str, float]],
    base: dict[str, float] | None,
) -> ObserverHoldout:
    """The EKF check's report from the fit's NIS statistics and the held-out errors per
    used output (``split``: the first held-out sample, the log's samples, those scored)."""
    used, primary = _ekf_outputs(settings)
    m, n, scored = split
    units = {"maf": "kg/s", "p_im": "Pa", "p_em": "Pa", "omega_t": "rad/s"}
    return ObserverHoldout(
        unit=units[OUTPUT_NAMES[primary]],
        fraction=fraction,
        fit_samples=m,
        holdout_samples=n - m,
        scored=scored,
        adapted=adapted[primary],
        base=base,
        other={OUTPUT_NAMES[j]: adapted[j] for j in used if j != primary},
        innovations=stats[primary],
        other_nis={OUTPUT_NAMES[j]: stats[j].mean_nis for j in used if j != primary},
    )


def ekf_holdout_windows(
    estimator: str,
    config: BaseModel | dict[str, Any],
    log: LogWindows,
    *,
    unit: str = "",
    fraction: float = DEFAULT_FIT_FRACTION,
) -> ObserverHoldout:
    """:func:`ekf_holdout` of a ``log`` that is never held whole: its rows are read
    ``log.window`` at a time and the row before (from which the kernel propagates). The fit
    carries the filter across the windows of the first part, adding each window's gated
    innovations to running sums; the prediction carries the open-loop filter (and its base)
    across the rest, adding the scored errors to running sums. The figures equal
    :func:`ekf_holdout`'s up to rounding (``tests/estimation/test_holdout_observers.py``);
    nothing is kept a sample. ``unit`` is in the common signature of
    :data:`estimation.registry.HOLDOUT_WINDOWS`'s functions (the unit is the output's)."""
    obs = _built(estimator, config, EkfObserver, "an EKF")
    read, n, window = log.read, log.n, log.window
    m, mask = _split(n, fraction, log.accept)
    settings = obs.settings
    used, primary = _ekf_outputs(settings)

    def window_model(a: int, z: int, keep: np.ndarray | None) -> EkfModel:
        """Rows ``a … z−1`` and the row before; ``keep=None``: every sample masked."""
        first = a - min(a, 1)
        accept = np.zeros(z - first, dtype=np.bool_) if keep is None else keep[first:z]
        return obs.prepare_window(read(first, z), accept, a, n, None)

    nis = {j: InnovationSums() for j in used}
    state: EkfState | None = None
    for a in range(0, m, window):
        model = window_model(a, min(a + window, m), mask)
        start = obs.initial_state(model) if state is None else state
        fit = ekf_innovations(start, model, settings, model.end)
        for j in used:
            ok = _gate_passed(fit.e[:, j], fit.s[:, j], settings.gate2)
            nis[j].add(fit.e[ok, j], fit.s[ok, j])
        state = fit.state
    assert state is not None
    states = [state] if settings.mode == kern.MODE_DEF else [state, _reset(state, settings)]
    adapted = {j: ErrorSums() for j in used}
    base = ErrorSums()
    for a in range(m, n, window):
        model = window_model(a, min(a + window, n), None)  # the prediction updates on nothing
        scored = mask[a : model.end]
        for i, start in enumerate(states):
            states[i], outputs, _ = ekf_run(start, model, settings, model.end)
            prediction = _prior_outputs(outputs)
            for j in used if i == 0 else [primary]:
                error = (model.Y[1:, j] - prediction[:, j])[scored]
                (adapted[j] if i == 0 else base).add(error)
    return _ekf_result(
        settings,
        fraction=fraction,
        split=(m, n, int(np.count_nonzero(mask[m:]))),
        stats={j: sums.stats() for j, sums in nis.items()},
        adapted={j: sums.metrics() for j, sums in adapted.items()},
        base=None if len(states) == 1 else base.metrics(),
    )


def ekf_predict(
    state: EkfState, model: EkfModel, settings: EkfSettings, *, reset: bool = True
) -> np.ndarray:
    """``(n − m, 4)`` prior outputs (``Y_*`` order) of the filter run open loop (every sample
    masked) from ``state`` (step ``m``) to the end of ``model``; with ``reset`` the bias or
    map states start at their initial value (``0`` / ``θ0``) instead of the fitted one."""
    if reset:
        state = _reset(state, settings)
    frozen = dataclasses.replace(model, accept=np.zeros_like(model.accept))
    _, outputs, _ = ekf_run(state, frozen, settings, model.end)
    return _prior_outputs(outputs)


def _reset(state: EkfState, settings: EkfSettings) -> EkfState:
    """``state`` with the bias or map states at their initial value (``0`` / ``θ0``)."""
    x = state.x.copy()
    x[kern.N_X :] = settings.theta0 if settings.mode == kern.MODE_MAP else 0.0
    return dataclasses.replace(state, x=x)


def _prior_outputs(outputs: dict[str, np.ndarray]) -> np.ndarray:
    """``(k, 4)`` prior outputs (``Y_*`` order) of a masked :func:`ekf_run`'s outputs."""
    out = np.full((outputs["maf_prediction"].size, kern.N_Y), math.nan)
    out[:, kern.Y_MAF] = outputs["maf_prediction"]
    out[:, kern.Y_P_IM] = outputs["p_im_pa"]  # masked: the posterior is the prior
    out[:, kern.Y_P_EM] = outputs["p_em_pa"]
    out[:, kern.Y_OMEGA_T] = outputs["omega_t_rad_s"]
    return out
