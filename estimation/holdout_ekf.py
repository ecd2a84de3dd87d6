"""Held-out prediction error and innovation statistics of the EKFs.

The map filters' check (:mod:`estimation.holdout`) for the three EKFs
(docs/tuning.md#which-runs-report-what); the fit/predict split and the result,
:class:`~estimation.holdout_observers.ObserverHoldout`, are the LPV observer's.

**EKF** (docs/algorithms.md §4). Fit: the filter over the first part, with its innovations
``e_j`` and variances ``S_j`` per used output (kept by :func:`~estimation.kernels.ekf.ekf_kernel`);
NIS of the MAF updates the χ² gate accepted, as :mod:`estimation.innovation`. Predict: the
filter continues from its posterior at ``m − 1`` with every sample masked, i.e. the model
propagated open loop from the inputs with the bias ``b`` (Aug) or map ``θ`` (Map) frozen;
``ŷ_k`` is its prior output (MAF, and the other outputs in ``outputs``). The base resets
``b = 0`` / ``θ = θ0`` at ``m``; Def has no parameters and no base.

**A log never held whole** (a streamed service run, docs/data-formats.md#streamed-runs):
:func:`ekf_holdout_windows` reads the log a window at a time and the row before each (the
filter's propagation), adding to running sums: its figures equal :func:`ekf_holdout`'s up to
rounding.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import BaseModel

from estimation.estimator import LogWindows
from estimation.holdout import DEFAULT_FIT_FRACTION
from estimation.holdout_observers import ObserverHoldout, built_observer, fit_split
from estimation.innovation import InnovationStats, InnovationSums, innovation_stats
from estimation.kernels import ekf as kern
from estimation.metrics import ErrorSums, output_metrics
from estimation.observers.ekf import EkfModel, EkfObserver, EkfSettings, EkfState, ekf_run
from estimation.observers.ekf_config import OUTPUT_NAMES
from estimation.signals import Signals


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
    obs = built_observer(estimator, config, EkfObserver, "an EKF")
    m, mask = fit_split(len(signals), fraction, accept)
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
    obs = built_observer(estimator, config, EkfObserver, "an EKF")
    read, n, window = log.read, log.n, log.window
    m, mask = fit_split(n, fraction, log.accept)
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
