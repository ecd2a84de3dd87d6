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

The joint EKFs (``ekf-def``, ``ekf-aug``, ``ekf-map``; :func:`tune_ekf`) are scored the same
way on the innovations of their **MAF** updates only (``e_k``, ``S_k`` of
:func:`estimation.holdout_ekf.ekf_innovations`, EKF §3: ``S = H P⁻ Hᵀ + R`` with
``R = σ_abs² + (σ_rel y)²``); the noise of the other outputs stays as configured. Tuned:
the MAF's ``sigma_maf_rel`` and ``sigma_maf_abs`` and, for Aug and Map, the random walk of
their parameters (``sigma_bias``, ``sigma_theta``): with that walk held at its default the
filter tracks the reading's noise as bias and ℓ is highest at ``R → 0`` (docs/tuning.md#ekf).
The starts are the config's values.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimation.errors import ConfigError
from estimation.innovation import (
    InnovationStats,
    innovation_stats,
    log_likelihood,
    map_filter,
    run_innovations,
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
EKF_PARAMETERS = {
    "ekf-def": ("sigma_maf_rel", "sigma_maf_abs"),
    "ekf-aug": ("sigma_maf_rel", "sigma_maf_abs", "sigma_bias"),
    "ekf-map": ("sigma_maf_rel", "sigma_maf_abs", "sigma_theta"),
}
"""The settings :func:`tune_ekf` chooses per EKF variant (module docstring)."""

Evaluate = Callable[[dict[str, float]], tuple[np.ndarray, np.ndarray]]
"""One pass at the given settings: the accepted innovations ``e`` and their variances ``S``."""


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
    _check_size(signals, max_evaluations)
    fields = set(type(map_filter(estimator, config).config).model_fields)
    names = tunable(config, fields)
    if not names:
        raise ConfigError(f"{estimator!r} has no noise settings to tune")
    starts = {name: _start(name, signals, config, start or {}) for name in names}

    def evaluate(values: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
        run = run_innovations(map_filter(estimator, with_settings(config, values)), signals, accept)
        return run.e[run.accepted], run.s[run.accepted]

    return _maximise(estimator, config, starts, evaluate, max_evaluations, len(signals))


def tune_ekf(
    estimator: str,
    config: dict[str, Any],
    signals: Signals,
    *,
    accept: np.ndarray | None = None,
    start: dict[str, float] | None = None,
    max_evaluations: int = DEFAULT_EVALUATIONS,
) -> TuneResult:
    """Choose the MAF noise (and parameter walk) of EKF ``estimator`` on ``signals`` by
    maximum likelihood of its MAF innovations (module docstring); ``start`` overrides the
    config's values as starts."""
    from estimation.holdout_ekf import ekf_innovations
    from estimation.kernels.ekf import Y_MAF
    from estimation.observers.ekf import EkfObserver
    from estimation.registry import get_spec

    if estimator not in EKF_PARAMETERS:
        raise ConfigError(f"{estimator!r} is not an EKF; choose one of {list(EKF_PARAMETERS)}")
    _check_size(signals, max_evaluations)
    spec = get_spec(estimator)
    base = spec.build(config)
    assert isinstance(base, EkfObserver)
    if not base.settings.use[Y_MAF]:
        raise ConfigError(f"{estimator!r} does not feed back the MAF: nothing to tune")
    full = base.config.model_dump(mode="json")
    given = start or {}
    unknown = sorted(set(given) - set(EKF_PARAMETERS[estimator]))
    if unknown:
        raise ConfigError(f"{estimator!r} tunes {list(EKF_PARAMETERS[estimator])}, not {unknown}")
    starts = {
        name: _positive(name, given.get(name, full[name])) for name in EKF_PARAMETERS[estimator]
    }
    model = base.prepare(signals, accept)

    def evaluate(values: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
        obs = spec.build(full | values | {"gate_sigma": None})
        assert isinstance(obs, EkfObserver)
        run = ekf_innovations(obs.initial_state(model), model, obs.settings, len(signals))
        e, s = run.e[:, Y_MAF], run.s[:, Y_MAF]
        ok = np.isfinite(e)
        return e[ok], s[ok]

    return _maximise(estimator, full, starts, evaluate, max_evaluations, len(signals))


def _check_size(signals: Signals, max_evaluations: int) -> None:
    if len(signals) > MAX_SAMPLES:
        raise ConfigError(
            f"the log has {len(signals)} samples; tune takes at most {MAX_SAMPLES} "
            "(cut the log or decimate it)"
        )
    if not 1 <= max_evaluations <= MAX_EVALUATIONS:
        raise ConfigError(
            f"max evaluations must be in [1, {MAX_EVALUATIONS}], got {max_evaluations}"
        )


def _maximise(
    estimator: str,
    config: dict[str, Any],
    starts: dict[str, float],
    evaluate: Evaluate,
    max_evaluations: int,
    samples: int,
) -> TuneResult:
    """The search of the module docstring over ``x = log σ`` from ``starts``: the grid, then
    bounded Nelder–Mead from its best point; ``evaluate`` is one filter pass."""
    names = tuple(starts)
    x0 = np.log(list(starts.values()))
    lower, upper = x0 - SEARCH_DECADES * math.log(10.0), x0 + SEARCH_DECADES * math.log(10.0)
    search = _Search(evaluate, names, max_evaluations)

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
    e, s = evaluate(values)
    stats = innovation_stats(e, s)
    edge = np.isclose(x_best, lower, atol=X_TOLERANCE) | np.isclose(x_best, upper, atol=X_TOLERANCE)
    return TuneResult(
        estimator=estimator,
        parameters=values,
        start=starts,
        log_likelihood=stats.log_likelihood,
        evaluations=search.evaluations,
        max_evaluations=max_evaluations,
        samples=samples,
        stats=stats,
        config=with_settings(config, values),
        at_bound=tuple(n for n, e in zip(names, edge, strict=True) if e),
    )


def _positive(name: str, value: Any) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ConfigError(f"the start of {name} must be a positive number, got {value!r}")
    return value


def _start(name: str, signals: Signals, config: dict[str, Any], given: dict[str, float]) -> float:
    if name in given:
        return _positive(name, given[name])
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

    def __init__(self, evaluate: Evaluate, names: tuple[str, ...], budget: int) -> None:
        self.evaluate, self.names, self.budget = evaluate, names, budget
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
        e, s = self.evaluate(values)
        ll = log_likelihood(e, s) if e.size else -math.inf
        cost = -ll / e.size if math.isfinite(ll) else math.inf
        self.cache[key] = cost
        if cost < self.best:
            self.best, self.best_x = cost, np.array(key)
        return cost
