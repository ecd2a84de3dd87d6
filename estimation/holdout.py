"""Held-out prediction error: how well a learned map predicts measurements it never saw.

A real log has no true map, so map error cannot be scored. What can be scored is the
measured output itself (docs/tuning.md#held-out-prediction-error):

1. **Fit.** Run the map filter over the first ``fraction`` of the log (default 70 %),
   log samples ``0 … m−1``, and freeze its map ``T̂``.
2. **Predict.** For every later sample ``k ≥ m``, predict the measurement from the inputs
   alone, with no further update:

   * without sensor dynamics, ``ŷ_k = T̂(u_k)`` (bilinear interpolation, SKF (10));
   * with the sensor model of SKF (25) (docs/algorithms.md §2.6),
     ``ŷ_k = a·ŷ_{k−1} + (1−a)·T̂(u_{k−τ})``, started at the measured ``y_{m−1}``.

3. **Score.** ``e_k = y_k − ŷ_k`` over the held-out samples the run accepts (a sample gate's
   mask applies): RMSE, mean ``|e|`` and max ``|e|``, in the output's unit.

The same prediction with the filter's initial map ``θ0`` (the unadapted base map) is scored
beside it, so "the adapted map predicts better than the base map" is a number, not a claim.

This is the map filters' check. Each estimator kind has its own, named in the registry
(:data:`estimation.registry.HOLDOUT`): the LPV observer's is in
:mod:`estimation.holdout_observers`, the EKFs' in :mod:`estimation.holdout_ekf`; the torque
estimators have none, and :func:`unmeasured_input` says so in the run's metrics
(docs/tuning.md#which-runs-report-what).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import BaseModel

from estimation import kernels
from estimation.errors import ConfigError, ShapeError
from estimation.estimator import LogWindows
from estimation.filters.estimator import REGRESSOR_BLOCK, Prepared, TableFilter
from estimation.filters.functions import run_chunk
from estimation.filters.settings import FilterSettings
from estimation.filters.state import FilterState
from estimation.innovation import (
    InnovationStats,
    InnovationSums,
    map_filter,
    run_innovations,
    stats_of,
)
from estimation.metrics import ErrorSums, output_metrics
from estimation.signals import Signals
from estimation.table import Table

DEFAULT_FIT_FRACTION = 0.7


@dataclass(frozen=True, slots=True)
class HoldoutResult:
    """Held-out prediction error of the adapted map and of the base map.

    ``adapted`` and ``base`` hold ``rmse``, ``mae`` (mean ``|e|``) and ``max_abs_error`` in
    ``unit``; ``fit_samples`` and ``holdout_samples`` count log samples, ``scored`` the
    held-out samples scored. ``innovations`` are the statistics of the fit pass.
    """

    unit: str
    fraction: float
    fit_samples: int
    holdout_samples: int
    scored: int
    adapted: dict[str, float]
    base: dict[str, float]
    innovations: InnovationStats
    table: Table

    def metrics(self) -> dict[str, float]:
        """Flat metrics of a run: ``holdout:*`` (output unit) and ``nis:*`` (dimensionless)."""
        out = {f"holdout:{k}": v for k, v in self.adapted.items()}
        out |= {f"holdout:base_{k}": v for k, v in self.base.items()}
        out["holdout:samples"] = float(self.scored)
        return out | self.innovations.metrics()

    def to_dict(self) -> dict[str, Any]:
        return {
            "unit": self.unit,
            "fraction": self.fraction,
            "fit_samples": self.fit_samples,
            "holdout_samples": self.holdout_samples,
            "scored": self.scored,
            "adapted": self.adapted,
            "base": self.base,
            "innovations": self.innovations.to_dict(),
        }


NOT_APPLICABLE = "not_applicable"
"""Metric ``holdout:not_applicable:<reason>`` / ``nis:not_applicable:<reason>`` (value
``None``): the check does not exist for the run's estimator, and why."""


@dataclass(frozen=True, slots=True)
class NotApplicable:
    """A truth-free check that has no honest form for an estimator: ``reasons`` maps a metric
    prefix (``holdout``, ``nis``) to a short reason slug, ``detail`` says it in words."""

    reasons: dict[str, str]
    detail: str

    def metrics(self) -> dict[str, float | None]:
        """``{prefix}:not_applicable:{reason}: None`` per prefix: stored with the run, so its
        metrics say the check does not apply rather than leave it out."""
        return {f"{k}:{NOT_APPLICABLE}:{v}": None for k, v in self.reasons.items()}

    def to_dict(self) -> dict[str, Any]:
        return {"not_applicable": dict(self.reasons), "detail": self.detail}


UNMEASURED_INPUT = NotApplicable(
    {"holdout": "unmeasured_input", "nis": "no_innovation_covariance"},
    "a torque estimator estimates an unknown input (the engine torque), which no sensor "
    "measures: a frozen estimate predicts no measured quantity on the rest of the log, and "
    "its observers carry no error covariance, so neither held-out prediction error nor NIS "
    "exists for it",
)


def unmeasured_input(
    estimator: str,
    config: BaseModel | dict[str, Any],
    signals: Signals,
    *,
    fraction: float = DEFAULT_FIT_FRACTION,
    accept: np.ndarray | None = None,
) -> NotApplicable:
    """The torque estimators' truth-free check: none (:data:`UNMEASURED_INPUT`). The
    arguments are the common signature of :data:`estimation.registry.HOLDOUT`'s functions."""
    split_point(len(signals), fraction)
    return UNMEASURED_INPUT


def unmeasured_input_windows(
    estimator: str,
    config: BaseModel | dict[str, Any],
    log: LogWindows,
    *,
    unit: str = "",
    fraction: float = DEFAULT_FIT_FRACTION,
) -> NotApplicable:
    """:func:`unmeasured_input` of a log never held whole (nothing is read); the arguments are
    :func:`holdout_error_windows`'s."""
    split_point(log.n, fraction)
    return UNMEASURED_INPUT


def split_point(n: int, fraction: float) -> int:
    """``m = round(fraction · n)``, the first held-out sample; ``fraction`` in (0, 1)."""
    if not 0.0 < fraction < 1.0:
        raise ConfigError(f"holdout fraction must be in (0, 1), got {fraction:g}")
    return round(fraction * n)


def holdout_error(
    estimator: str,
    config: BaseModel | dict[str, Any],
    signals: Signals,
    *,
    fraction: float = DEFAULT_FIT_FRACTION,
    accept: np.ndarray | None = None,
) -> HoldoutResult:
    """Fit map filter ``estimator`` on the first ``fraction`` of ``signals`` and score its
    frozen map, and the base map, on the rest (module docstring)."""
    n = len(signals)
    m = split_point(n, fraction)
    mask = np.ones(n, dtype=np.bool_) if accept is None else np.asarray(accept, dtype=np.bool_)
    filt = map_filter(estimator, config)
    fit = run_innovations(filt, signals.slice(0, m), mask[:m])
    delay = fit.prepared.settings.delay
    if m - delay < 1 or n - m < 1:
        raise ConfigError(
            f"a log of {n} samples is too short to fit on {m} (sensor delay {delay}) and "
            "predict the rest"
        )
    table = fit.estimator.theta0.with_values(fit.state.theta.reshape(filt.grid.shape))
    inputs = [signals[a.name] for a in filt.config.axes]
    y = signals[filt.config.output]
    scored = mask[m:]
    adapted = _predict(table, inputs, y, m, fit.prepared)
    base = _predict(filt.theta0, inputs, y, m, fit.prepared)
    return HoldoutResult(
        unit=filt.config.output_unit or signals.units.get(filt.config.output, ""),
        fraction=fraction,
        fit_samples=m,
        holdout_samples=n - m,
        scored=int(np.count_nonzero(scored)),
        adapted=output_metrics((y[m:] - adapted)[scored]),
        base=output_metrics((y[m:] - base)[scored]),
        innovations=stats_of(fit),
        table=table,
    )


def _predict(
    table: Table, inputs: list[np.ndarray], y: np.ndarray, m: int, prepared: Prepared
) -> np.ndarray:
    """Open-loop prediction of ``y[m:]`` by a frozen ``table`` from its axes' channels
    ``inputs`` (step 2 of the module docstring), through the sensor model when the filter has
    one."""
    settings = prepared.settings
    tau = settings.delay if settings.has_sensor else 0
    x = _evaluate(table, inputs, m - tau, len(y) - tau)
    if not settings.has_sensor:
        return x
    out = np.empty(x.size)
    kernels.sensor.sensor_kernel(
        np.ascontiguousarray(x), 0, float(settings.lag), float(y[m - 1]), out
    )
    return out


def _evaluate(table: Table, inputs: list[np.ndarray], start: int, stop: int) -> np.ndarray:
    """``table`` at the samples ``start … stop−1`` of its axes' channels, a
    :data:`REGRESSOR_BLOCK` at a time (the regressor rows of a block are ``c`` indices and
    weights a sample: made for the whole held-out part at once they were its memory peak)."""
    out = np.empty(stop - start)
    for a in range(start, stop, REGRESSOR_BLOCK):
        z = min(a + REGRESSOR_BLOCK, stop)
        out[a - start : z - start] = table.evaluate(np.column_stack([u[a:z] for u in inputs]))
    return out


def holdout_error_windows(
    estimator: str,
    config: BaseModel | dict[str, Any],
    log: LogWindows,
    *,
    unit: str,
    fraction: float = DEFAULT_FIT_FRACTION,
) -> HoldoutResult:
    """:func:`holdout_error` of a ``log`` that is never held whole: its rows are read
    ``log.window`` at a time, once for the fit and once for the prediction; its time column
    only for a delay in seconds (as :meth:`TableFilter.run_windows`); ``log.accept`` is the
    mask of the samples fitted and scored (default: all). The statistics are running sums,
    equal to :func:`holdout_error`'s up to rounding (``tests/estimation/test_holdout.py``)."""
    read, n, window = log.read, log.n, log.window
    m = split_point(n, fraction)
    accept = log.accept
    mask = np.ones(n, dtype=np.bool_) if accept is None else np.asarray(accept, dtype=np.bool_)
    if mask.shape != (n,):
        raise ShapeError(f"accept mask has shape {mask.shape}, the log has {n} samples")
    filt = map_filter(estimator, config)
    settings = filt.settings_on(m, lambda: log.timeline()[:m])
    sums, state, settings = _fit_windows(filt, read, mask[:m], window, settings)
    delay = settings.delay
    if m - delay < 1 or n - m < 1:
        raise ConfigError(
            f"a log of {n} samples is too short to fit on {m} (sensor delay {delay}) and "
            "predict the rest"
        )
    table = filt.theta0.with_values(state.theta.reshape(filt.grid.shape))
    adapted, base = ErrorSums(), ErrorSums()
    tau = delay if settings.has_sensor else 0
    y_last = float(read(m - 1, m)[filt.config.output][0])
    last = {"adapted": y_last, "base": y_last}  # the sensor model's state of each map
    for a in range(m, n, window):
        z = min(a + window, n)
        rows = read(a - tau, z)  # operating points a−τ … z−τ−1, measurements a … z−1
        inputs = [rows[ax.name][: z - a] for ax in filt.config.axes]
        y = rows[filt.config.output][tau:]
        scored = mask[a:z]
        for name, frozen, sums_of in (("adapted", table, adapted), ("base", filt.theta0, base)):
            x = _evaluate(frozen, inputs, 0, z - a)
            if settings.has_sensor:
                out = np.empty(x.size)
                kernels.sensor.sensor_kernel(x, 0, float(settings.lag), last[name], out)
                last[name], x = float(out[-1]), out
            sums_of.add((y - x)[scored])
    return HoldoutResult(
        unit=unit,
        fraction=fraction,
        fit_samples=m,
        holdout_samples=n - m,
        scored=int(np.count_nonzero(mask[m:])),
        adapted=adapted.metrics(),
        base=base.metrics(),
        innovations=sums.stats(),
        table=table,
    )


def _fit_windows(
    filt: TableFilter,
    read: Callable[[int, int], Signals],
    accept: np.ndarray,
    window: int,
    settings: FilterSettings,
) -> tuple[InnovationSums, FilterState, FilterSettings]:
    """:func:`run_innovations` over rows ``0 … m−1`` (``m = len(accept)``) with
    ``settings``, a window at a time, keeping the sums of the accepted innovations instead
    of the series."""
    m = accept.size
    tau = settings.delay
    if tau >= m:
        raise ConfigError(f"sensor delay of {tau} samples is not shorter than the log ({m})")
    sums = InnovationSums()
    state: FilterState | None = None
    for a in range(0, m - tau, window):
        z = min(a + window, m - tau)
        prepared = filt.prepare(read(a, z + tau), accept[a : z + tau], window=(a, m, settings))
        if state is None:
            state = filt.initial_state(prepared)
        for b in range(0, z - a, REGRESSOR_BLOCK):
            c = min(b + REGRESSOR_BLOCK, z - a)
            idx, w = prepared.regressor(b, c)
            s = np.empty(c - b)
            state, yhat, status = run_chunk(
                state, idx, w, prepared.y[b:c], prepared.accept[b:c], settings, s_out=s
            )
            e = prepared.y[b:c] - yhat
            ok = (status == 0) & np.isfinite(e) & (s > 0)
            sums.add(e[ok], s[ok])
    assert state is not None
    return sums, state, settings
