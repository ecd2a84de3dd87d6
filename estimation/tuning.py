"""Noise settings from the log itself: maximum innovation likelihood (``mapwise tune``).

A map filter's noise settings — the random walk σw of each cell, the measurement noise σv
and, with sensor dynamics, the sensor-state noise σf — are chosen to maximise the
innovation log-likelihood of the log (docs/tuning.md#tuning; the prediction-error
decomposition of Schweppe 1965, Harvey 1989 §3.4)::

    ℓ(σ) = Σ_k −½ (log 2π S_k(σ) + e_k(σ)² / S_k(σ))

over the accepted kernel steps, ``e_k`` and ``S_k`` the filter's innovation and its variance
(:mod:`estimation.innovation`). It needs no truth: only the inputs and the measured output.

The search runs over ``x = log σ`` (scale-free, and every σ stays positive), each
coordinate bounded to ``[log σ₀ − log 1000, log σ₀ + log 1000]`` around its start ``σ₀``:

1. a coarse grid, the start times ``{1/10, 1, 10}`` in each coordinate (``3^d`` points);
2. Nelder–Mead (``scipy.optimize.minimize``, bounded) from the best grid point, with
   steps of ×3, until ``x`` settles to 1 % or the evaluation budget is spent.

Every evaluation is one pass of the filter built by its registry spec through the compiled
kernels. The starts ``σ₀`` not given come from the log: σv₀ is the noise scale of the
measured output, ``1.4826·MAD(Δy)/√2`` (the median absolute deviation of the first
difference: white noise of σ has ``std(Δv) = √2 σ``; a smooth signal adds little), σw₀ is
σv₀/10 and σf₀ is σv₀. The innovation gate is off while tuning, so every setting is scored
on the same samples.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimation.errors import ConfigError
from estimation.innovation import (
    InnovationStats,
    log_likelihood,
    map_filter,
    run_innovations,
    stats_of,
)
from estimation.signals import Signals

MAX_SAMPLES = 1_000_000
"""Longest log ``tune`` accepts: each evaluation is a full pass over it."""
MAX_EVALUATIONS = 1000
"""Most filter passes one tuning may ask for."""
DEFAULT_EVALUATIONS = 120
SEARCH_DECADES = 3.0
"""Each σ is searched within ×/÷ 10^3 of its start."""
GRID_FACTORS = (0.1, 1.0, 10.0)
SIMPLEX_STEP = math.log(3.0)
X_TOLERANCE = 0.01  # in log σ: 1 %

PARAMETERS = ("sigma_w", "sigma_v", "sigma_f")
"""The noise settings tune chooses, where the filter has them (σf: with a sensor model)."""


@dataclass(frozen=True, slots=True)
class TuneResult:
    """The chosen settings (``parameters``, in the output's unit), where the search started,
    the log-likelihood at the optimum, the passes spent, and the innovation statistics
    there. ``config`` is the filter config with the chosen settings."""

    estimator: str
    parameters: dict[str, float]
    start: dict[str, float]
    log_likelihood: float
    evaluations: int
    max_evaluations: int
    samples: int
    stats: InnovationStats
    config: dict[str, Any]
    at_bound: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "estimator": self.estimator,
            "parameters": self.parameters,
            "start": self.start,
            "log_likelihood": self.log_likelihood,
            "evaluations": self.evaluations,
            "max_evaluations": self.max_evaluations,
            "samples": self.samples,
            "at_bound": list(self.at_bound),
            "innovation": self.stats.to_dict(),
        }


def tunable(config: dict[str, Any], fields: set[str]) -> tuple[str, ...]:
    """The :data:`PARAMETERS` a filter with config model ``fields`` and ``config`` has."""
    names = [p for p in ("sigma_w", "sigma_v") if p in fields]
    if config.get("sensor") is not None:
        names.append("sigma_f")
    return tuple(names)


def noise_scale(y: np.ndarray) -> float:
    """``1.4826·MAD(Δy)/√2``: the white-noise σ of ``y`` (module docstring); 0 if flat."""
    dy = np.diff(np.asarray(y, dtype=np.float64))
    if dy.size == 0:
        return 0.0
    mad = float(np.median(np.abs(dy - np.median(dy))))
    return 1.4826 * mad / math.sqrt(2.0)


def with_settings(config: dict[str, Any], values: dict[str, float]) -> dict[str, Any]:
    """``config`` with the noise settings ``values`` (σf inside ``sensor``), gate off."""
    out = copy.deepcopy(config)
    for name, value in values.items():
        if name == "sigma_f":
            out["sensor"] = dict(out["sensor"]) | {"sigma_f": value}
        else:
            out[name] = value
    out["gate_sigma"] = None
    return out


def tune(
    estimator: str,
    config: dict[str, Any],
    signals: Signals,
    *,
    accept: np.ndarray | None = None,
    start: dict[str, float] | None = None,
    max_evaluations: int = DEFAULT_EVALUATIONS,
) -> TuneResult:
    """Choose the noise settings of map filter ``estimator`` on ``signals`` by maximum
    innovation likelihood (module docstring); ``start`` overrides the log-derived starts."""
    if len(signals) > MAX_SAMPLES:
        raise ConfigError(
            f"the log has {len(signals)} samples; tune takes at most {MAX_SAMPLES} "
            "(cut the log or decimate it)"
        )
    if not 1 <= max_evaluations <= MAX_EVALUATIONS:
        raise ConfigError(
            f"max evaluations must be in [1, {MAX_EVALUATIONS}], got {max_evaluations}"
        )
    fields = set(type(map_filter(estimator, config).config).model_fields)
    names = tunable(config, fields)
    if not names:
        raise ConfigError(f"{estimator!r} has no noise settings to tune")
    starts = {name: _start(name, signals, config, start or {}) for name in names}
    x0 = np.log(list(starts.values()))
    lower, upper = x0 - SEARCH_DECADES * math.log(10.0), x0 + SEARCH_DECADES * math.log(10.0)
    search = _Search(estimator, config, signals, accept, names, max_evaluations)

    best = x0
    for point in _grid(x0):
        if search.spent():
            break
        if search(point) < search(best):
            best = point
    if not search.spent():
        from scipy.optimize import minimize  # imported here: keeps CLI start-up fast

        simplex = np.vstack([best, best + SIMPLEX_STEP * np.eye(len(names))])
        minimize(
            search,
            best,
            method="Nelder-Mead",
            bounds=list(zip(lower, upper, strict=True)),
            options={
                "initial_simplex": np.clip(simplex, lower, upper),
                "maxfev": max_evaluations - search.evaluations,
                "xatol": X_TOLERANCE,
                "fatol": 1e-9,
            },
        )
    x_best = search.best_x
    values = dict(zip(names, (float(v) for v in np.exp(x_best)), strict=True))
    tuned = with_settings(config, values)
    final = run_innovations(map_filter(estimator, tuned), signals, accept)
    stats = stats_of(final)
    edge = np.isclose(x_best, lower, atol=X_TOLERANCE) | np.isclose(x_best, upper, atol=X_TOLERANCE)
    return TuneResult(
        estimator=estimator,
        parameters=values,
        start=starts,
        log_likelihood=stats.log_likelihood,
        evaluations=search.evaluations,
        max_evaluations=max_evaluations,
        samples=len(signals),
        stats=stats,
        config=tuned,
        at_bound=tuple(n for n, e in zip(names, edge, strict=True) if e),
    )


def _start(name: str, signals: Signals, config: dict[str, Any], given: dict[str, float]) -> float:
    if name in given:
        value = float(given[name])
        if not (math.isfinite(value) and value > 0):
            raise ConfigError(f"the start of {name} must be a positive number, got {value!r}")
        return value
    scale = noise_scale(signals[config["output"]])
    if scale <= 0:
        scale = float(np.std(signals[config["output"]])) or 1.0
    return {"sigma_w": 0.1 * scale, "sigma_v": scale, "sigma_f": scale}[name]


def _grid(x0: np.ndarray) -> list[np.ndarray]:
    """The coarse stage: ``x0 + log f`` for every combination of :data:`GRID_FACTORS`."""
    steps = np.log(GRID_FACTORS)
    mesh = np.meshgrid(*[steps] * x0.size, indexing="ij")
    return [x0 + np.array(p) for p in zip(*(m.ravel() for m in mesh), strict=True)]


class _Search:
    """The objective ``−ℓ/N`` over ``x = log σ``, counting (and caching) filter passes and
    refusing new ones once the budget is spent."""

    def __init__(
        self,
        estimator: str,
        config: dict[str, Any],
        signals: Signals,
        accept: np.ndarray | None,
        names: tuple[str, ...],
        budget: int,
    ) -> None:
        self.estimator, self.config, self.signals = estimator, config, signals
        self.accept, self.names, self.budget = accept, names, budget
        self.evaluations = 0
        self.cache: dict[tuple[float, ...], float] = {}
        self.best_x = np.zeros(len(names))
        self.best = math.inf

    def spent(self) -> bool:
        return self.evaluations >= self.budget

    def __call__(self, x: np.ndarray) -> float:
        key = tuple(np.round(np.asarray(x, dtype=np.float64), 12))
        if key in self.cache:
            return self.cache[key]
        if self.spent():
            return math.inf
        self.evaluations += 1
        values = dict(zip(self.names, (float(v) for v in np.exp(key)), strict=True))
        run = run_innovations(
            map_filter(self.estimator, with_settings(self.config, values)),
            self.signals,
            self.accept,
        )
        ok = run.accepted
        n = int(np.count_nonzero(ok))
        ll = log_likelihood(run.e[ok], run.s[ok]) if n else -math.inf
        cost = -ll / n if math.isfinite(ll) else math.inf
        self.cache[key] = cost
        if cost < self.best:
            self.best, self.best_x = cost, np.array(key)
        return cost
