"""Engine torque estimators (TQ §III, §V) behind the :class:`~estimation.estimator.Estimator`
interface.

``uio`` (TQ (9), (14)), ``smo`` (TQ (19)–(21)), ``dirty`` (TQ (23)–(24)), ``adaptive-const``
(TQ (50)) and ``adaptive-tv`` (TQ (52), (54)) read the measured speed ``N`` [rpm], load torque
``τ_l`` [N·m] and (adaptive laws) the air mass flow ``ṁ_ai`` [kg/s], and output the effective
torque estimate ``torque_nm`` per sample; the adaptive laws also output ``theta1``
[N·m/rpm], ``theta2`` [N·m per ``air_unit`` of ṁ_ai] and ``pe_lambda_min`` = ``λ_min(P)``
(the persistent excitation monitor of TQ Remark 9, in the mixed units of P: rpm², (air
unit)², rpm·(air unit), times s). Discretisation: :mod:`estimation.kernels.torque`.

State is explicit (:class:`TorqueState`): frozen, serialisable, with the step count, so
``run(..., state=snapshot.state)`` resumes bit-identically. :func:`initial_state` and
:func:`run_chunk` are the procedure form; :class:`TorqueEstimator` the thin class.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from estimation import kernels
from estimation.errors import ConfigError, ShapeError, StateError
from estimation.estimator import ChunkedEstimator, LogWindows, WindowPlan
from estimation.registry import Cost, EstimatorKind, EstimatorSpec, family
from estimation.signals import Signals, uniform_period
from estimation.state import EstimatorState
from estimation.torque.config import (
    AIR_UNIT_SCALE,
    AdaptiveConfig,
    AdaptiveConstConfig,
    AdaptiveTvConfig,
    DirtyConfig,
    SmoConfig,
    TorqueEstimatorConfig,
    UioConfig,
)

TQ_PAPER = (
    "Na, Chen, Herrmann, Burke & Brace (2018), Vehicle engine torque estimation via unknown "
    "input observer and adaptive parameter estimation, IEEE Transactions on Vehicular "
    "Technology 67(1) — the torque paper (TQ)"
)

ADAPTIVE = ("adaptive-const", "adaptive-tv")
CONFIGS: dict[str, type[TorqueEstimatorConfig]] = {
    "uio": UioConfig,
    "smo": SmoConfig,
    "dirty": DirtyConfig,
    "adaptive-const": AdaptiveConstConfig,
    "adaptive-tv": AdaptiveTvConfig,
}


@dataclass(frozen=True, slots=True, eq=False)
class TorqueState(EstimatorState):
    """State of every torque estimator at sample ``step`` (samples consumed so far).

    ``x`` holds the observer states: ``[N_f, τ_lf]`` (uio), ``[N_f]`` (dirty), ``[N̂, τ̂_e]``
    (smo), ``[N_f, τ_lf, Φ_f1, Φ_f2]`` (adaptive). The adaptive laws add ``P`` (2, 2),
    ``Q`` (2,), ``R = K⁻¹`` (2, 2) and ``theta = Θ̂`` (2,); the others hold them empty.
    """

    x: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    theta: np.ndarray

    ARRAYS: ClassVar[tuple[str, ...]] = ("x", "P", "Q", "R", "theta")


OUTPUT_UNITS = {
    "torque_nm": "N·m",
    "theta1": "N·m/rpm",
    "theta2": "",  # N·m per air_unit of ṁ_ai: depends on the config
    "pe_lambda_min": "",  # λ_min(P) in the mixed units of P
}
"""Units of the outputs; the adaptive laws yield all four, the others ``torque_nm``."""
_TORQUE_ONLY = {"torque_nm": OUTPUT_UNITS["torque_nm"]}

_EMPTY = np.zeros(0)
_X_SIZE = {"uio": 2, "dirty": 1, "smo": 2, "adaptive-const": 4, "adaptive-tv": 4}


def initial_state(kind: str, config: TorqueEstimatorConfig) -> TorqueState:
    """Zero initial conditions (TQ §VI); ``Θ̂(0) = theta0``, ``K(0)⁻¹ = diag(K0)``."""
    if kind not in CONFIGS:
        raise ConfigError(f"unknown torque estimator {kind!r}; choose one of {sorted(CONFIGS)}")
    x = np.zeros(_X_SIZE[kind])
    if kind not in ADAPTIVE:
        return TorqueState(kind, 0, x, _EMPTY.reshape(0, 0), _EMPTY, _EMPTY.reshape(0, 0), _EMPTY)
    assert isinstance(config, AdaptiveConfig)
    k0 = config.K0 if isinstance(config, AdaptiveTvConfig) else (1.0, 1.0)
    return TorqueState(
        kind,
        0,
        x,
        np.zeros((2, 2)),
        np.zeros(2),
        np.diag(np.array(k0, dtype=np.float64)),
        np.array(config.theta0, dtype=np.float64),
    )


def run_chunk(
    state: TorqueState,
    config: TorqueEstimatorConfig,
    inputs: dict[str, np.ndarray],
    *,
    sample_period_s: float,
) -> tuple[TorqueState, dict[str, np.ndarray]]:
    """Advance ``state`` over one chunk of samples; return the new state and the outputs.

    ``inputs`` maps ``speed_rpm``, ``load_nm`` (and ``air_kg_s`` for the adaptive laws) to
    contiguous float64 arrays of equal length ``n``. Outputs are (n,) arrays: ``torque_nm``,
    and for the adaptive laws ``theta1``, ``theta2``, ``pe_lambda_min``. ``state`` is not
    modified.
    """
    new = state.copy()
    speed = np.ascontiguousarray(inputs["speed_rpm"], dtype=np.float64)
    load = np.ascontiguousarray(inputs["load_nm"], dtype=np.float64)
    n = speed.size
    if load.shape != (n,):
        raise ShapeError(f"load has shape {load.shape}, speed ({n},)")
    ts = float(sample_period_s)
    J = float(config.J_nm_s_per_rpm)
    k = float(config.k)
    torque = np.empty(n)
    out = {"torque_nm": torque}
    kind = state.kind
    if kind == "uio":
        kernels.torque.uio_kernel(new.x, speed, load, J, k, ts, torque)
    elif kind == "dirty":
        kernels.torque.dirty_kernel(new.x, speed, load, J, k, ts, torque)
    elif kind == "smo":
        assert isinstance(config, SmoConfig)
        kernels.torque.smo_kernel(new.x, speed, load, J, k, float(config.lambda1), ts, torque)
    elif kind in ADAPTIVE:
        assert isinstance(config, AdaptiveConfig)
        air = np.ascontiguousarray(inputs["air_kg_s"], dtype=np.float64)
        if air.shape != (n,):
            raise ShapeError(f"air flow has shape {air.shape}, speed ({n},)")
        out |= {"theta1": np.empty(n), "theta2": np.empty(n), "pe_lambda_min": np.empty(n)}
        kernels.torque.adaptive_kernel(
            new.x,
            new.P,
            new.Q,
            new.R,
            new.theta,
            speed,
            load,
            air,
            AIR_UNIT_SCALE[config.air_unit],
            J,
            k,
            float(config.ell),
            float(config.gamma[0]),
            float(config.gamma[1]),
            float(config.kappa),
            kind == "adaptive-tv",
            ts,
            torque,
            out["theta1"],
            out["theta2"],
            out["pe_lambda_min"],
        )
    else:
        raise StateError(f"unknown torque estimator state kind {kind!r}")
    return dataclasses.replace(new, step=state.step + n), out


@dataclass(frozen=True, slots=True, eq=False)
class TorquePrepared:
    """A log turned into kernel inputs: ``speed_rpm``, ``load_nm`` (and ``air_kg_s``) as
    contiguous float64 arrays, the sample times and the (uniform) sample period; a window of
    :meth:`~estimation.estimator.ChunkedEstimator.run_windows` holds rows ``offset …`` of a
    log of ``total`` samples (0: these rows are the log)."""

    inputs: dict[str, np.ndarray]
    time_s: np.ndarray
    sample_period_s: float
    offset: int = 0
    total: int = 0


class TorqueEstimator(ChunkedEstimator[TorqueState, TorquePrepared]):
    """One of the TQ torque estimators; ``name`` selects the law, ``config`` its constants.

    ``run``, ``fit`` and the state check are :class:`~estimation.estimator.ChunkedEstimator`'s.
    The observers integrate every sample, so an ``accept`` mask may not reject any.
    """

    state_class = TorqueState
    windowed = True

    def __init__(self, name: str, config: TorqueEstimatorConfig) -> None:
        if name not in CONFIGS:
            raise ConfigError(f"unknown torque estimator {name!r}; choose one of {sorted(CONFIGS)}")
        if not isinstance(config, CONFIGS[name]):
            raise ConfigError(
                f"{name} needs a {CONFIGS[name].__name__}, got {type(config).__name__}"
            )
        if isinstance(config, AdaptiveConfig):
            bad = [g for g in config.gamma if not g > 0]
            if bad:
                raise ConfigError(f"gamma must be positive, got {list(config.gamma)}")
        if isinstance(config, AdaptiveTvConfig) and not all(v > 0 for v in config.K0):
            raise ConfigError(f"K0 must be positive definite, got diag{tuple(config.K0)}")
        self.name = name
        self.config = config

    def required_signals(self) -> list[str]:
        c = self.config
        names = [c.speed_channel, c.load_channel]
        if isinstance(c, AdaptiveConfig):
            names.append(c.air_channel)
        return names

    def signal_roles(self) -> dict[str, list[str]]:
        return {"input": self.required_signals()}

    def output_names(self) -> tuple[str, ...]:
        return tuple(OUTPUT_UNITS if self.name in ADAPTIVE else _TORQUE_ONLY)

    def initial_state(self) -> TorqueState:
        return initial_state(self.name, self.config)

    def prepare(self, signals: Signals, accept: np.ndarray | None = None) -> TorquePrepared:
        return self._prepared(signals, accept, signals.sample_period())

    def plan_windows(self, log: LogWindows) -> WindowPlan:
        """Every window is prepared with the whole log's sample period (``log.timeline()``)."""
        time = log.timeline()
        if time.size != log.n:
            raise ConfigError(f"the time column has {time.size} samples, the log {log.n}")
        return WindowPlan(steps=log.n, extra_rows=0, context=uniform_period(time))

    def prepare_window(
        self, signals: Signals, accept: np.ndarray | None, offset: int, n: int, context: float
    ) -> TorquePrepared:
        prepared = self._prepared(signals, accept, context)
        return dataclasses.replace(prepared, offset=offset, total=n)

    def _prepared(self, signals: Signals, accept: np.ndarray | None, ts: float) -> TorquePrepared:
        signals.require(self.required_signals())
        n = len(signals)
        if accept is not None:
            mask = np.asarray(accept, dtype=bool)
            if mask.shape != (n,):
                raise ShapeError(f"accept mask has shape {mask.shape}, the log has {n} samples")
            if not mask.all():
                raise ConfigError(
                    f"{self.name} integrates every sample; the accept mask rejects "
                    f"{int(np.count_nonzero(~mask))} of them"
                )
        c = self.config
        inputs = {"speed_rpm": signals[c.speed_channel], "load_nm": signals[c.load_channel]}
        if isinstance(c, AdaptiveConfig):
            inputs["air_kg_s"] = signals[c.air_channel]
        inputs = {name: np.ascontiguousarray(v, dtype=np.float64) for name, v in inputs.items()}
        return TorquePrepared(inputs, signals.time, ts)

    def steps(self, prepared: TorquePrepared) -> int:
        return prepared.offset + int(prepared.time_s.size)

    def start(self, signals: Signals, prepared: TorquePrepared) -> TorqueState:
        return self.initial_state()

    def check_fit(self, state: TorqueState) -> None:
        if state.x.shape != (_X_SIZE[self.name],):
            raise StateError(
                f"state x has shape {state.x.shape}, {self.name} needs ({_X_SIZE[self.name]},)"
            )
        if self.name in ADAPTIVE and (
            state.P.shape != (2, 2)
            or state.Q.shape != (2,)
            or state.R.shape != (2, 2)
            or state.theta.shape != (2,)
        ):
            raise StateError(f"state arrays do not fit {self.name} (P, R (2, 2); Q, theta (2,))")

    def advance(
        self, state: TorqueState, prepared: TorquePrepared, stop: int
    ) -> tuple[TorqueState, dict[str, np.ndarray], np.ndarray]:
        start = state.step
        a, z = start - prepared.offset, stop - prepared.offset
        part = {name: v[a:z] for name, v in prepared.inputs.items()}
        state, outputs = run_chunk(
            state, self.config, part, sample_period_s=prepared.sample_period_s
        )
        return state, outputs, np.zeros(stop - start, dtype=np.int8)

    def times(self, prepared: TorquePrepared) -> np.ndarray:
        return prepared.time_s

    def n_samples(self, prepared: TorquePrepared) -> int:
        return prepared.total or int(prepared.time_s.size)

    def time_of(self, prepared: TorquePrepared, sample: int) -> float:
        return float(prepared.time_s[max(sample - 1, 0) - prepared.offset])


TORQUE_COST = Cost(
    # x (≤ 4), P (2, 2), Q (2,), R (2, 2), Θ̂ (2,): no table
    state_floats=lambda p, c: 16,
    # time, speed, load, air (4) and their prepared copies (4), four output series, status
    # and scoring temporaries (8)
    sample_floats=lambda c: 20,
    ops_per_sample=lambda p, c: 100,
    holdout_passes=0.0,  # an unmeasured input: no held-out check to run (estimation/holdout.py)
)

_spec = family(
    TorqueEstimator,
    TorqueEstimatorConfig,
    kind=EstimatorKind.TORQUE,
    paper=TQ_PAPER,
    produces_map=False,
    cost=TORQUE_COST,
)


UIO = _spec(
    "uio",
    "Unknown input observer (torque)",
    "Filters speed and load with 1/(ks+1) and estimates τ_e = J(N − N_f)/k + τ_lf; one "
    "constant k, no derivative, no switching (TQ (9), (14)).",
    UioConfig,
    TorqueState,
    _TORQUE_ONLY,
)
SMO = _spec(
    "smo",
    "Sliding-mode observer (torque)",
    "Speed observer with switching gain λ1; the low-passed switching term is the "
    "equivalent-control torque estimate; chatters (TQ (19)–(21)).",
    SmoConfig,
    TorqueState,
    _TORQUE_ONLY,
)
DIRTY = _spec(
    "dirty",
    "Dirty differentiation (torque)",
    "τ_e = J·s/(ks+1)[N] + τ_l: a filtered speed derivative plus the raw load; sensitive "
    "to noise and to N̈ (TQ (23)–(24)).",
    DirtyConfig,
    TorqueState,
    _TORQUE_ONLY,
)
ADAPTIVE_CONST = _spec(
    "adaptive-const",
    "Adaptive law, constant gain (torque)",
    "τ_e = [N, ṁ_ai]Θ(t) with Θ adapted from the filtered-error variables W1, W2 under a "
    "constant gain Γ; reports λ_min(P) as the excitation monitor (TQ (41)–(50)).",
    AdaptiveConstConfig,
    TorqueState,
    OUTPUT_UNITS,
)
ADAPTIVE_TV = _spec(
    "adaptive-tv",
    "Adaptive law, time-varying gain (torque)",
    "As the constant-gain law but with the least-squares-like gain K → P⁻¹ that "
    "compensates the excitation level (TQ (52)–(54)).",
    AdaptiveTvConfig,
    TorqueState,
    OUTPUT_UNITS,
)
TORQUE_SPECS: tuple[EstimatorSpec, ...] = (UIO, SMO, DIRTY, ADAPTIVE_CONST, ADAPTIVE_TV)
