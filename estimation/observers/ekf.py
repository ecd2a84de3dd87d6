"""Joint state and MAF-map EKF on the 3-state diesel air path (docs/algorithms.md §4; EKF §2–5).

Höckerdal, Frisk & Eriksson (2009), "EKF-based adaptation of look-up tables with an air
mass-flow sensor application" — the EKF paper. The model is the W&E (2011) air path
(LPV (1)–(2)) with the observer's own parameters (``config.model``,
:mod:`estimation.observers.airpath_model`; under ``mismatch="nominal"`` they differ from the
simulator's, docs/fidelity.md) with the states ``x = [p_im, p_em, ω_t]`` (Pa, Pa, rad/s), driven by
the measured actuator positions ``ũ_egr, ũ_vgt`` [%], fuel ``u_δ`` [mg/cycle] and engine
speed ``n_e`` [rpm]. Flows are evaluated at the EKF's own state estimate (that is what the
EKF propagates), so nothing is computed from the measured pressures; the MAF reading
``W_c,meas`` [kg/s] is the output (EKF §5.2: "all observers use only feedback from the air
mass-flow sensor"); the pressure and turbo-speed sensors can be added with ``outputs``.

Variants (EKF §5.1):

* ``ekf-def`` — ``y = W_c(x)``: the default model, MAF error not modelled;
* ``ekf-aug`` — ``y = W_c(x) + b``, ``b_{k+1} = b_k + w_b``: one random-walk bias [kg/s];
* ``ekf-map`` — ``y = (1 + q(W_c(x), θ)) W_c(x)``, ``θ_{k+1} = θ_k + w_θ``: a 1-D relative
  correction map over ``W`` (EKF (4), (6)), ``q`` the linear interpolation of the grid
  values ``θ`` (clamped, as :meth:`estimation.table.Grid.regressor`).

Discretisation (exponential Euler at ``max_step_s``, stable for the stiff manifolds),
Jacobians (the variational equation along the steps; central differences of the plant's
right-hand side, verified in the tests), the χ² innovation gate, the line search of the
update and the PSD-preserving covariance limiting are in :mod:`estimation.kernels.ekf`.
The ``w_c_kg_s`` output of every snapshot is ``W_c(x̂)``, the estimate of the *true*
compressor flow, on which Def, Aug and Map compare (EKF Table 1); ``p_im_pa``, ``p_em_pa``,
``omega_t_rad_s`` are the state estimates (Table 1's other rows). Counts of gated and
damped updates per output and of state clamps are in each snapshot's ``metrics``. The settings
of each variant are in :mod:`estimation.observers.ekf_config`. A log read a window at a time
(:meth:`~estimation.estimator.ChunkedEstimator.run_windows`) gives each window the row before
it, from which the kernel propagates; the run is the whole log's bit for bit.

Defaults (``maf-1d-whtc``, seeds 0–2, whole WHTC): RMS error of ``W_c`` ≈ 0.45 g/s (Def),
0.10 g/s (Aug and Map) against a MAF error of 1.8 g/s RMS; Map's ``q`` is within
1.6–2.4 % (mean relative error) of the truth along the trajectory. The model being the
simulator's own, the air path run open loop (no feedback) is as good as Aug and Map on
``W_c`` (0.097 g/s): what the MAF feedback buys here is the map, and what Def loses is
its pull towards the biased sensor — larger the more the state noise lets the MAF in.

Example
-------
>>> from estimation.scenarios import get_scenario
>>> data = get_scenario("maf-1d-whtc").build(seed=0, duration_s=60.0)
>>> snap = EKF_SPECS[2].build({}).fit(data.signals)
>>> snap.table.shape, snap.outputs["w_c_kg_s"].shape
((11,), (601,))
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from pydantic import BaseModel

from estimation import kernels
from estimation.errors import ConfigError, ShapeError, StateError
from estimation.estimator import Chunk, ChunkedEstimator, LogWindows, WindowPlan
from estimation.observers.ekf_config import (
    OUTPUT_NAMES,
    EkfAugConfig,
    EkfConfig,
    EkfDefConfig,
    EkfMapConfig,
)
from estimation.observers.ekf_state import EkfModel, EkfSettings, EkfState
from estimation.registry import Cost, EstimatorKind, family
from estimation.signals import Signals
from estimation.table import Axis, Table

__all__ = [
    "EKF_SPECS",
    "EkfModel",
    "EkfObserver",
    "EkfSettings",
    "EkfState",
    "ekf_run",
    "initial_state",
    "prepare_model",
    "resolve_settings",
]

VARIANTS = ("ekf-def", "ekf-aug", "ekf-map")
NO_INNOVATIONS = np.empty((0, 0))  # ekf_kernel's e_out, s_out when a run keeps no innovations


def _mode_code(kind: str) -> int:
    """The kernel's code of an EKF variant named in :data:`VARIANTS`."""
    k = kernels.ekf
    return {"ekf-def": k.MODE_DEF, "ekf-aug": k.MODE_AUG, "ekf-map": k.MODE_MAP}[kind]


def prepare_model(
    signals: Signals,
    config: EkfConfig,
    *,
    accept: np.ndarray | None = None,
    offset: int = 0,
    total: int | None = None,
) -> EkfModel:
    """Kernel inputs for a log, or for its rows ``offset …`` of ``total`` (validates
    channels, ranges and the accept mask; a message names the sample in the whole log)."""
    ch = config.channels
    signals.require(ch.inputs() + [ch.output(o) for o in config.outputs])
    n = len(signals)
    if (n if total is None else total) < 2:
        raise ConfigError(
            f"the EKF needs at least two samples, got {n if total is None else total}"
        )
    mask = np.ones(n, dtype=np.bool_) if accept is None else np.asarray(accept, dtype=bool)
    if mask.shape != (n,):
        raise ShapeError(f"accept mask has shape {mask.shape}, the log has {n} samples")
    for name in (ch.speed, *(ch.output(o) for o in config.outputs if o != "maf")):
        values = signals[name]
        if np.any(values <= 0):
            k = int(np.argmax(values <= 0))
            raise ConfigError(f"{name!r} must be > 0, got {values[k]:g} at sample {k + offset}")
    fuel = signals[ch.fuel]
    if np.any(fuel < 0):
        k = int(np.argmax(fuel < 0))
        raise ConfigError(f"{ch.fuel!r} must be ≥ 0, got {fuel[k]:g} at sample {k + offset}")
    Y = np.full((n, kernels.ekf.N_Y), np.nan)
    for o in config.outputs:
        Y[:, OUTPUT_NAMES.index(o)] = signals[ch.output(o)]
    return EkfModel(
        U=np.ascontiguousarray(signals.stack(ch.inputs())),
        Y=Y,
        accept=mask,
        time_s=signals.time,
        offset=offset,
        total=n if total is None else total,
    )


def _limit_code(limit: str) -> int:
    """The kernel's code of a covariance limit (``config.limit``)."""
    k = kernels.ekf
    return {"none": k.LIMIT_NONE, "p0": k.LIMIT_PSD, "diag": k.LIMIT_DIAG}[limit]


def resolve_settings(kind: str, config: EkfConfig) -> EkfSettings:
    """Kernel arguments of variant ``kind`` from its config (noise settings and the observer's
    own air-path model, ``config.model``)."""
    mode = _mode_code(kind)
    q = list(np.square(config.sigma_state))
    p0 = list(np.square(config.sigma0_state))
    g = np.zeros(2)
    theta0 = 0.0
    if isinstance(config, EkfAugConfig):
        q.append(config.sigma_bias**2)
        p0.append(config.sigma0_bias**2)
    elif isinstance(config, EkfMapConfig):
        g = np.array(config.breakpoints, dtype=np.float64)
        q += [config.sigma_theta**2] * g.size
        p0 += [config.sigma0_theta**2] * g.size
        theta0 = config.theta0
    use = np.array([o in config.outputs for o in OUTPUT_NAMES])
    r_abs2 = np.array([config.sigma_maf_abs, config.sigma_p_im, config.sigma_p_em, 0.0]) ** 2
    r_rel2 = np.array([config.sigma_maf_rel, 0.0, 0.0, config.sigma_omega_t_rel]) ** 2
    return EkfSettings(
        mode=mode,
        g=g,
        use=use,
        r_abs2=r_abs2,
        r_rel2=r_rel2,
        q_rate=np.array(q),
        p0_diag=np.array(p0),
        limit=_limit_code(config.limit),
        gate2=np.inf if config.gate_sigma is None else config.gate_sigma**2,
        max_step_s=config.max_step_s,
        theta0=theta0,
        prm=config.model.vector(),
    )


def initial_state(kind: str, model: EkfModel, settings: EkfSettings, config: EkfConfig) -> EkfState:
    """``x0`` from ``config.x0`` or the model settled at the first sample's inputs (from
    ambient manifolds and a slow turbo, as the simulator starts); ``b = 0`` / ``θ = θ0``;
    ``P0 = diag(σ0²)``; Seiliger memory ``(T_im, 0.03)`` settled alongside."""
    prm = settings.prm
    p_amb = float(prm[kernels.ekf.apk.P_AMB])
    x_s = np.array([p_amb, 1.05 * p_amb, 0.2 * float(prm[kernels.ekf.apk.OMEGA_T_MAX])])
    mem = np.array([float(prm[kernels.ekf.apk.T_IM]), 0.03])
    kernels.ekf.settle(x_s, mem, np.ascontiguousarray(model.U[0]), config.settle_s, prm)
    if config.x0 is not None:
        x_s = np.array(config.x0, dtype=np.float64)
    m = settings.q_rate.size
    x = np.full(m, settings.theta0 if settings.mode == kernels.ekf.MODE_MAP else 0.0)
    x[: kernels.ekf.N_X] = x_s
    return EkfState(
        kind=kind,
        step=0,
        rejected_mask=0,
        rejected_gate=0,
        counts=np.zeros(kernels.ekf.N_COUNTS, dtype=np.int64),
        x=x,
        P=np.diag(settings.p0_diag),
        mem=mem,
    )


def ekf_run(
    state: EkfState, model: EkfModel, settings: EkfSettings, stop: int
) -> tuple[EkfState, dict[str, np.ndarray], np.ndarray]:
    """Advance a copy of ``state`` from sample ``state.step`` to ``stop`` in one kernel call.

    Returns the new state, the chunk's per-sample outputs — ``w_c_kg_s`` (``W_c(x̂)``, the
    true-flow estimate), the posterior states ``p_im_pa``, ``p_em_pa``, ``omega_t_rad_s``,
    the MAF prediction ``maf_prediction`` (prior, kg/s) and ``residual`` (measured −
    predicted), the MAF correction ``maf_bias_kg_s`` (Aug) or ``maf_q`` (Map) — and the
    per-sample status (0 accepted, 1 masked, 2 gated).
    """
    start = state.step
    first = model.offset + (1 if model.offset else 0)  # a window's row before is not a step
    if not first <= start <= stop <= model.end:
        raise StateError(f"cannot run from sample {start} to {stop} of {first} … {model.end}")
    out = state.copy()
    n = stop - start
    x_out = np.empty((n, kernels.ekf.N_X))
    w_c = np.empty(n)
    yhat = np.empty((n, kernels.ekf.N_Y))
    corr = np.empty(n)
    status = np.empty(n, dtype=np.int8)
    kernels.ekf.ekf_kernel(
        out.x,
        out.P,
        out.mem,
        out.counts,
        settings.mode,
        settings.g,
        model.time_s,
        model.U,
        model.Y,
        settings.use,
        settings.r_abs2,
        settings.r_rel2,
        model.accept,
        settings.q_rate,
        settings.p0_diag,
        settings.limit,
        settings.gate2,
        settings.max_step_s,
        settings.prm,
        start - model.offset,  # k > 0 in the window iff in the log: it holds the row before
        stop - model.offset,
        x_out,
        w_c,
        yhat,
        corr,
        status,
        NO_INNOVATIONS,
        NO_INNOVATIONS,
    )
    new = dataclasses.replace(
        out,
        step=stop,
        rejected_mask=state.rejected_mask
        + int(np.count_nonzero(status == kernels.ekf.REJECTED_MASK)),
        rejected_gate=state.rejected_gate
        + int(np.count_nonzero(status == kernels.ekf.REJECTED_GATE)),
    )
    outputs = {
        "w_c_kg_s": w_c,
        "p_im_pa": x_out[:, 0],
        "p_em_pa": x_out[:, 1],
        "omega_t_rad_s": x_out[:, 2],
        "maf_prediction": yhat[:, kernels.ekf.Y_MAF],
        "residual": model.Y[start - model.offset : stop - model.offset, kernels.ekf.Y_MAF]
        - yhat[:, kernels.ekf.Y_MAF],
    }
    if settings.mode == kernels.ekf.MODE_AUG:
        outputs["maf_bias_kg_s"] = corr
    elif settings.mode == kernels.ekf.MODE_MAP:
        outputs["maf_q"] = corr
    return new, outputs, status


class EkfObserver(ChunkedEstimator[EkfState, EkfModel]):
    """One EKF variant behind the :class:`~estimation.estimator.Estimator` interface;
    ``run``, ``fit`` and the state check are :class:`~estimation.estimator.ChunkedEstimator`'s
    (``state`` from a snapshot or :meth:`EkfState.load` resumes bit-identically)."""

    state_class = EkfState
    windowed = True

    def __init__(self, name: str, config: EkfConfig) -> None:
        if name not in VARIANTS:
            raise ConfigError(f"unknown EKF variant {name!r}; choose one of {list(VARIANTS)}")
        self.name = name
        self.config = config
        self.settings = resolve_settings(name, config)

    def required_signals(self) -> list[str]:
        ch = self.config.channels
        return ch.inputs() + [ch.output(o) for o in self.config.outputs]

    def signal_roles(self) -> dict[str, list[str]]:
        ch = self.config.channels
        return {
            "axis": [ch.maf] if self.settings.mode == kernels.ekf.MODE_MAP else [],
            "output": [ch.output(o) for o in self.config.outputs],
            "input": ch.inputs(),
        }

    def output_names(self) -> tuple[str, ...]:
        return tuple(output_units(self.name))

    def prepare(self, signals: Signals, accept: np.ndarray | None = None) -> EkfModel:
        return prepare_model(signals, self.config, accept=accept)

    def plan_windows(self, log: LogWindows) -> WindowPlan:
        """Nothing of the whole log: each window reads the row before it, from which the
        kernel propagates its first sample."""
        if log.n < 2:
            raise ConfigError(f"the EKF needs at least two samples, got {log.n}")
        return WindowPlan(steps=log.n, extra_rows=0, context=None, rows_before=1)

    def prepare_window(
        self, signals: Signals, accept: np.ndarray | None, offset: int, n: int, context: None
    ) -> EkfModel:
        first = offset - min(offset, 1)
        return prepare_model(signals, self.config, accept=accept, offset=first, total=n)

    def initial_state(self, model: EkfModel) -> EkfState:
        return initial_state(self.name, model, self.settings, self.config)

    def steps(self, prepared: EkfModel) -> int:
        return prepared.end

    def start(self, signals: Signals, prepared: EkfModel) -> EkfState:
        return self.initial_state(prepared)

    def advance(
        self, state: EkfState, prepared: EkfModel, stop: int
    ) -> tuple[EkfState, dict[str, np.ndarray], np.ndarray]:
        return ekf_run(state, prepared, self.settings, stop)

    def map_table(self, state: EkfState) -> Table | None:
        """The correction map ``q`` over ``W`` [kg/s] (Map only)."""
        if self.settings.mode != kernels.ekf.MODE_MAP:
            return None
        axis = Axis(self.config.channels.maf, "kg/s", self.settings.g)
        return Table([axis], state.x[kernels.ekf.N_X :].copy())

    def check_fit(self, state: EkfState) -> None:
        m = self.settings.q_rate.size
        if state.x.shape != (m,) or state.P.shape != (m, m):
            raise StateError(f"state has x {state.x.shape}, P {state.P.shape}; expected m = {m}")
        if state.mem.shape != (2,) or state.counts.shape != (kernels.ekf.N_COUNTS,):
            raise StateError(f"state has mem {state.mem.shape}, counts {state.counts.shape}")

    def times(self, prepared: EkfModel) -> np.ndarray:
        return prepared.time_s

    def n_samples(self, prepared: EkfModel) -> int:
        return prepared.total

    def time_of(self, prepared: EkfModel, sample: int) -> float:
        return float(prepared.time_s[max(sample - 1, 0) - prepared.offset])

    def report(self, state: EkfState, prepared: EkfModel, chunk: Chunk) -> dict[str, Any]:
        table = self.map_table(state)
        diagnostics: dict[str, float] = {}
        for o in self.config.outputs:
            j = OUTPUT_NAMES.index(o)
            diagnostics[f"gated_{o}"] = float(state.counts[kernels.ekf.C_GATE + j])
            diagnostics[f"damped_{o}"] = float(state.counts[kernels.ekf.C_DAMPED + j])
        diagnostics["state_clamps"] = float(state.counts[kernels.ekf.C_CLAMP])
        return {
            "table": table,
            "variance": None if table is None else np.diag(state.P)[kernels.ekf.N_X :].copy(),
            "outputs": chunk.outputs,
            "rejected": {"mask": state.rejected_mask, "innovation": state.rejected_gate},
            "metrics": diagnostics,
        }


_PAPER = (
    "Höckerdal, Frisk & Eriksson (2009), EKF-based adaptation of look-up tables with an air "
    "mass-flow sensor application — the EKF paper"
)


_BASE_UNITS = {
    "w_c_kg_s": "kg/s",
    "p_im_pa": "Pa",
    "p_em_pa": "Pa",
    "omega_t_rad_s": "rad/s",
    "maf_prediction": "kg/s",
    "residual": "kg/s",  # of the MAF reading
}
_EXTRA_UNITS = {"ekf-def": {}, "ekf-aug": {"maf_bias_kg_s": "kg/s"}, "ekf-map": {"maf_q": ""}}


def output_units(name: str) -> dict[str, str]:
    """The per-sample series of variant ``name`` and their units (``maf_q`` is relative)."""
    return _BASE_UNITS | _EXTRA_UNITS[name]


def _ekf_size(config: BaseModel) -> tuple[int, int]:
    """The map's grid values (Map) as cells, two active per sample; none for Def and Aug."""
    breakpoints = getattr(config, "breakpoints", None)
    return (len(breakpoints), 2) if breakpoints else (0, 1)


EKF_COST = Cost(
    # x and P over m = 3 plant states + a bias (Aug) or the map's p values (Map): m² + m,
    # the Seiliger memory and the counts
    state_floats=lambda p, c: (p + 4) ** 2 + (p + 4) + 32,
    # U and Y (4 + 4), accept and time (2), seven output series, scoring temporaries (8)
    # and, for a map, the worker's regressor rows (2c)
    sample_floats=lambda c: 25 + 2 * c,
    # the covariance propagation F P Fᵀ and the update (about 4 m³), the model (~500)
    ops_per_sample=lambda p, c: 4 * (p + 4) ** 3 + 500,
    max_cells=200,  # m³ per sample: a 200-value map is already ~3·10⁷ operations a sample
    size=_ekf_size,
    # a streamed run's RSS grows by about 87 bytes a sample (ekf-aug, scripts/run_memory.py
    # from 1 M to 2.6 M rows), 20 beyond its outputs, status codes and final residual copy:
    # not itemised (the check keeps only sums), the allocator's; counted so as not to under-
    # predict a long log (docs/benchmarks.md#run-memory)
    stream_sample_bytes=32.0,
)

_spec = family(
    EkfObserver,
    EkfConfig,
    kind=EstimatorKind.JOINT_EKF,
    paper=_PAPER,
    produces_map=False,
    cost=EKF_COST,
)

EKF_DEF = _spec(
    "ekf-def",
    "EKF, default model",
    "Air-path EKF (p_im, p_em, ω_t) on the W&E model fed back by the MAF; the MAF error "
    "is not modelled (EKF §5.1 Def).",
    EkfDefConfig,
    EkfState,
    output_units("ekf-def"),
)
EKF_AUG = _spec(
    "ekf-aug",
    "EKF with a MAF bias state",
    "The air-path EKF plus one random-walk bias on the MAF output (EKF §5.1 Aug).",
    EkfAugConfig,
    EkfState,
    output_units("ekf-aug"),
)
EKF_MAP = _spec(
    "ekf-map",
    "EKF with a MAF correction map",
    "The air-path EKF plus a 1-D relative correction map q(W) on the MAF, its grid values "
    "as random-walk states, covariance-limited at P0 (EKF §5.1 Map).",
    EkfMapConfig,
    EkfState,
    output_units("ekf-map"),
    produces_map=True,
)
EKF_SPECS = (EKF_DEF, EKF_AUG, EKF_MAP)
