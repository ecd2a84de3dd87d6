"""LPV adaptive observer of a MAF-sensor error map behind the Estimator interface.

Zhang, Yang et al. (2015), Sensors — "the LPV paper": observer (26) with gain from the
vertex LMIs (28)/(35) (:mod:`estimation.observers.lmi`), adaptive law ``θ̂' = Γψ(y_m2 −
C2x̂ − ψᵀθ̂)`` on the active elements only (36); kernel and discretisation in
:mod:`estimation.kernels.lpv`. Unvisited cells are filled by the quadratic surface of
LPV (37) or by a smooth convex least-squares fill (:mod:`estimation.observers.lpv_fill`).

Three choices differ from a literal reading of the paper, each because the paper's
simulation is noise-free and continuous while our data are sampled, noisy logs:

- ``adaptation="normalised"`` (default): ``Γ = diag(g_j)``, ``g_j = (1/γ + ∫ψ_j² dt)⁻¹``
  (still a positive definite diagonal Γ as LPV (26)/(36) allow). The paper's ``Γ = 200 I``
  settles an element within a few ms, i.e. within one 0.1 s sample, so the map copies the
  last residual — with it the sensor noise (1 % of ~35 g/s against a ~1 g/s map). The
  normalised gain starts at ``γ`` and then averages every visit like a running mean. On our
  ``maf-ftp75`` the best constant γ reaches 7 % mean relative error, the normalised gain
  3 %. Theorem 1 is proved for a constant Γ; the normalised Γ(t) ⪯ γI is bounded and
  decreasing, and stability is checked on every cycle (``adaptation="constant"`` gives the
  paper's law, e.g. to track a drifting map).
- the gain ``L`` is designed ``structure="decoupled"`` (:mod:`estimation.observers.lmi`), so
  the ``p_im`` and MAF residuals are not fed into ``ω̂_t``, whose product ``ρ1 ω̂_t`` is the
  model flow the map is measured against;
- ``ρ1`` comes from the intake-manifold balance, which is well conditioned; the
  compressor-map value of LPV (3) (``rho1="rho1_compressor"``) is biased by several g/s
  under 1 kPa pressure noise.

Where ρ comes from (``rho_source``): ``"model"`` computes it from the measured pressures, turbo
speed, actuator positions, fuel and speed with the observer's own air-path model
(:class:`~estimation.observers.airpath_model.AirpathModelConfig`, ``model``), the same model
that gives ``a1`` and ``a2``; ``"channels"`` (default, for logs that carry an ECU's ρ) reads the
channels ``rho1``…``rho5`` of the log. The scenarios under ``mismatch="nominal"`` use
``"model"`` with a drawn model (docs/fidelity.md); nothing here reads the simulator's
parameters.

``E = (0, a2 W_f, P_tη_m/(J_t ω_t))``: ``P_tη_m`` is not measured. With
``turbine_power="derivative"`` (default) ``E3`` is taken from the measured turbo speed,
``E3 ≈ Δω_t/Δt + ρ5 ω_t`` (the ω_t equation of LPV (3) solved for its input, backward
difference); ``"zero"`` sets ``E3 = 0`` and leaves it to the ω_t output injection.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel

from estimation import kernels
from estimation.errors import ConfigError, ShapeError
from estimation.estimator import Chunk, ChunkedEstimator, LogWindows, WindowPlan
from estimation.observers.airpath_model import model_rho
from estimation.observers.lmi import (
    DEFAULT_OUTPUT_SCALE,
    DEFAULT_STATE_SCALE,
    GainDesign,
    synthesize_gain,
)
from estimation.observers.lpv_config import LpvConfig
from estimation.observers.lpv_state import LpvBox, LpvPrepared, LpvState
from estimation.registry import Cost, EstimatorKind, EstimatorSpec
from estimation.signals import Signals
from estimation.table import Axis, Grid, Table

RHO_CHANNELS = ("rho1", "rho2", "rho3", "rho4", "rho5")
_MODES = ("constant", "normalised")  # the kernel's adaptation modes, by name
OUTPUT_UNITS = {
    "p_im_pa": "Pa",
    "p_em_pa": "Pa",
    "omega_t_rad_s": "rad/s",
    "w_c_kg_s": "kg/s",
    "maf_error_kg_s": "kg/s",
    "residual": "kg/s",  # of the MAF reading
}


def _mode_code(adaptation: str) -> int:
    """The kernel's code of an adaptation mode named in :data:`_MODES`."""
    codes = {"constant": kernels.lpv.CONSTANT, "normalised": kernels.lpv.NORMALISED}
    return codes[adaptation]


def data_rho_box(rho: np.ndarray, *, rho4_floor: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """The ρ box of a log: per-channel min/max, the ρ4 minimum raised to ``rho4_floor·max``."""
    return _floored(rho.min(axis=0), rho.max(axis=0), rho4_floor)


def _floored(lo: np.ndarray, hi: np.ndarray, rho4_floor: float) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = lo.astype(np.float64), hi.astype(np.float64)
    lo[3] = max(lo[3], rho4_floor * hi[3])
    return lo, hi


class LpvObserver(ChunkedEstimator[LpvState, LpvPrepared]):
    """LPV adaptive observer (LPV (26)) estimating the MAF error map ``ΔW_c(u_δ, n_e)``;
    ``run``, ``fit`` and the state check are :class:`~estimation.estimator.ChunkedEstimator`'s.
    """

    name = "lpv"
    state_class = LpvState
    windowed = True

    def __init__(self, config: LpvConfig) -> None:
        self.config = config
        try:
            self.grid = Grid([Axis(a.name, a.unit, a.breakpoints) for a in config.axes])
        except (ValueError, ShapeError) as exc:
            raise ConfigError(f"lpv: bad axes: {exc}") from exc
        self.design: GainDesign | None = None

    def required_signals(self) -> list[str]:
        c = self.config
        names = [a.name for a in c.axes] + [c.p_im, c.omega_t, c.maf, c.fuel_flow]
        return list(dict.fromkeys(names + self._scheduling_inputs()))

    def signal_roles(self) -> dict[str, list[str]]:
        c = self.config
        return {
            "axis": [a.name for a in c.axes],
            "output": [c.p_im, c.omega_t, c.maf],
            "input": [c.fuel_flow, *self._scheduling_inputs()],
        }

    def output_names(self) -> tuple[str, ...]:
        return tuple(OUTPUT_UNITS)

    def rho_channels(self) -> list[str]:
        """The five channels read as ρ1…ρ5 (``rho_source="channels"``)."""
        return [self.config.rho1, *RHO_CHANNELS[1:]]

    def _model_columns(self) -> list[str]:
        c = self.config
        return [c.p_im, c.p_em or "p_em_pa", c.omega_t, c.u_egr, c.u_vgt, c.fuel, c.speed]

    def _scheduling_inputs(self) -> list[str]:
        if self.config.rho_source == "model":
            return self._model_columns()
        return self.rho_channels()

    def scheduling(self, signals: Signals) -> tuple[np.ndarray, float]:
        """ρ (n, 5) and the mean exhaust temperature [K] the observer runs on.

        ``rho_source="model"``: both from the observer's model
        (:func:`~estimation.observers.airpath_model.model_rho`), ρ1 by the manifold balance or,
        with ``rho1="rho1_compressor"``, the compressor map; ``"channels"``: the log's ρ
        channels and its ``t_em`` channel (700 K without one).
        """
        rho, t_em = self._scheduling_rows(signals)
        return rho, 700.0 if t_em is None else float(np.mean(t_em))

    def _scheduling_rows(self, signals: Signals) -> tuple[np.ndarray, np.ndarray | None]:
        """ρ (n, 5) and the exhaust temperature [K] of every sample (``None``: no channel)."""
        c = self.config
        if c.rho_source == "model":
            signals.require(self._model_columns())
            cols = tuple(signals[name] for name in self._model_columns())
            rho, rho1_compressor, t_em = model_rho(cols, signals.time, c.model)
            if c.rho1 == "rho1_compressor":
                rho[:, 0] = rho1_compressor
            return np.ascontiguousarray(rho), t_em
        signals.require(self.rho_channels())
        rho = np.ascontiguousarray(signals.stack(self.rho_channels()))
        return rho, (signals[c.t_em] if c.t_em and c.t_em in signals else None)

    def plan_windows(self, log: LogWindows) -> WindowPlan:
        """A pass over the log a window at a time for what :meth:`prepare` takes from all of
        it (:class:`LpvBox`: 8 bytes a sample for the mean T_em, as ``np.mean`` sums it, and
        the accept mask), ``log.window`` rows at a time; each window reads the row before it,
        for ``ṗ_im``, ``h`` and ``Δω_t``."""
        n = log.n
        lo, hi = np.full(5, np.inf), np.full(5, -np.inf)
        t_em: np.ndarray | None = np.empty(n)
        mask = np.ones(n, dtype=np.bool_) if log.accept is None else np.array(log.accept, bool)
        for a in range(0, n, log.window):
            lead = min(a, 1)
            rows = log.read(a - lead, min(a + log.window, n))
            rows.require(self.required_signals())
            rho, temperature = self._scheduling_rows(rows)
            rho = rho[lead:]
            lo, hi = np.minimum(lo, rho.min(axis=0)), np.maximum(hi, rho.max(axis=0))
            if self.config.adapt_only_with_flow:
                mask[a : a + rho.shape[0]] &= rho[:, 0] > 0.0
            if temperature is None:
                t_em = None
            elif t_em is not None:
                t_em[a : a + rho.shape[0]] = temperature[lead:]
        mean = 700.0 if t_em is None else float(np.mean(t_em))
        return WindowPlan(steps=n, extra_rows=0, context=LpvBox(lo, hi, mean, mask), rows_before=1)

    def prepare_window(
        self, signals: Signals, accept: np.ndarray | None, offset: int, n: int, context: LpvBox
    ) -> LpvPrepared:
        lead = min(offset, 1)
        whole = self._prepared(signals, accept, context.t_em_k)
        keep = slice(lead, None)
        return dataclasses.replace(
            whole,
            idx=whole.idx[keep],
            w=whole.w[keep],
            y=whole.y[keep],
            rho=whole.rho[keep],
            e=whole.e[keep],
            h=whole.h[keep],
            accept=whole.accept[keep],
            time_s=whole.time_s[keep],
            offset=offset,
            total=n,
            rejected_before=int(np.count_nonzero(~context.accept[:offset])),
            box=context,
        )

    def prepare(self, signals: Signals, accept: np.ndarray | None = None) -> LpvPrepared:
        return self._prepared(signals, accept, None)

    def _prepared(
        self, signals: Signals, accept: np.ndarray | None, t_em_k: float | None
    ) -> LpvPrepared:
        """Kernel inputs of ``signals``; ``a2`` at ``t_em_k`` (``None``: these rows' mean)."""
        c = self.config
        signals.require(self.required_signals())
        n = len(signals)
        mask = np.ones(n, dtype=np.bool_) if accept is None else np.asarray(accept, dtype=bool)
        if mask.shape != (n,):
            raise ShapeError(f"accept mask has shape {mask.shape}, the log has {n} samples")
        idx, w = self.grid.regressor(signals.stack([a.name for a in c.axes]))
        rho, t_em = self.scheduling(signals)
        whole = t_em_k is None  # these rows are the log: its box is theirs
        if not whole:
            t_em = t_em_k
        if c.adapt_only_with_flow:
            mask = mask & (rho[:, 0] > 0.0)
        omega = signals[c.omega_t]
        y = np.ascontiguousarray(np.column_stack([signals[c.p_im], omega, signals[c.maf]]))
        t = signals.time
        h = np.zeros(n)
        h[1:] = np.diff(t)
        a2 = self._a2(t_em)
        e = np.zeros((n, 3))
        e[:, 1] = a2 * signals[c.fuel_flow]
        if c.turbine_power == "derivative":
            e[:, 2] = rho[:, 4] * omega
            e[1:, 2] += np.diff(omega) / h[1:]
        p_em0 = signals[c.p_em][0] if c.p_em and c.p_em in signals else signals[c.p_im][0]
        x0 = np.array([signals[c.p_im][0], p_em0, omega[0]], dtype=np.float64)
        # The gain design reads the box from here rather than computing ρ over the log again
        # (design_gain), which cost a third of a run.
        box = LpvBox(rho.min(axis=0), rho.max(axis=0), t_em, mask) if whole and n else None
        return LpvPrepared(idx, w, y, rho, e, h, mask, t, x0, box=box)

    def _a1(self) -> float:
        return self.config.a1 if self.config.a1 is not None else self.config.model.a1()

    def _a2(self, t_em_k: float) -> float:
        return self.config.a2 if self.config.a2 is not None else self.config.model.a2(t_em_k)

    def design_gain(self, signals: Signals) -> GainDesign:
        """Solve the LMIs on the configured ρ box, or the log's (:func:`data_rho_box`)."""
        rho, t_em = self.scheduling(signals)
        return self._design(rho.min(axis=0), rho.max(axis=0), t_em)

    def _design(self, rho_min: np.ndarray, rho_max: np.ndarray, t_em: float) -> GainDesign:
        """The LMI gain on the configured ρ box, or on the log's ``rho_min … rho_max``."""
        c = self.config
        if c.rho_min is not None and c.rho_max is not None:
            lo, hi = np.array(c.rho_min), np.array(c.rho_max)
        else:
            lo, hi = _floored(rho_min, rho_max, c.rho4_floor)
        return synthesize_gain(
            lo,
            hi,
            self._a1(),
            self._a2(t_em),
            eps1=c.eps1,
            eps2=c.eps2,
            structure=c.gain_structure,
        )

    def initial_state(self, signals: Signals, prepared: LpvPrepared) -> LpvState:
        box = prepared.box
        if box is None:
            design = self.design_gain(signals)
        else:
            design = self._design(box.rho_min, box.rho_max, box.t_em_k)
        self.design = design
        lo, hi = design.vertices.min(axis=0), design.vertices.max(axis=0)
        return LpvState(
            kind=self.name,
            step=0,
            a1=design.a1,
            a2=design.a2,
            x_hat=prepared.x0.copy(),
            theta=np.zeros(self.grid.size),
            weight_sum=np.zeros(self.grid.size),
            excitation=np.zeros(self.grid.size),
            L_scaled=design.L_scaled.copy(),
            state_scale=np.asarray(DEFAULT_STATE_SCALE, dtype=np.float64),
            output_scale=np.asarray(DEFAULT_OUTPUT_SCALE, dtype=np.float64),
            rho_lo=lo,
            rho_hi=hi,
        )

    def steps(self, prepared: LpvPrepared) -> int:
        return prepared.offset + int(prepared.y.shape[0])

    def start(self, signals: Signals, prepared: LpvPrepared) -> LpvState:
        return self.initial_state(signals, prepared)

    def advance(
        self, state: LpvState, prepared: LpvPrepared, stop: int
    ) -> tuple[LpvState, dict[str, np.ndarray], np.ndarray]:
        start = state.step
        state, x_out, wc, dwc = lpv_run(
            state,
            prepared,
            start,
            stop,
            gamma=self.config.gamma,
            adaptation=self.config.adaptation,
        )
        outputs = {
            "p_im_pa": x_out[:, 0],
            "p_em_pa": x_out[:, 1],
            "omega_t_rad_s": x_out[:, 2],
            "w_c_kg_s": wc,
            "maf_error_kg_s": dwc,
            "residual": prepared.y[start - prepared.offset : stop - prepared.offset, 2] - wc - dwc,
        }
        accepted = prepared.accept[start - prepared.offset : stop - prepared.offset]
        status = np.where(accepted, 0, 1).astype(np.int8)
        return state, outputs, status

    def times(self, prepared: LpvPrepared) -> np.ndarray:
        return prepared.time_s

    def n_samples(self, prepared: LpvPrepared) -> int:
        return prepared.total or int(prepared.time_s.size)

    def time_of(self, prepared: LpvPrepared, sample: int) -> float:
        return float(prepared.time_s[max(sample - 1, 0) - prepared.offset])

    def report(self, state: LpvState, prepared: LpvPrepared, chunk: Chunk) -> dict[str, Any]:
        table = Table(self.grid.axes, state.theta.reshape(self.grid.shape))
        if chunk.sample >= self.n_samples(prepared):
            table = self.filled(table, state)
        masked = np.count_nonzero(~prepared.accept[: chunk.sample - prepared.offset])
        return {
            "table": table,
            "outputs": chunk.outputs,
            "rejected": {"mask": prepared.rejected_before + int(masked)},
        }

    def filled(self, table: Table, state: LpvState) -> Table:
        """The finished map with its unvisited cells filled as ``config.fill`` says (LPV (37)
        or the smooth fill of :mod:`estimation.observers.lpv_fill`). Only the reported map is
        filled, once, at the end of the log: a resumed or continued run adapts the raw θ̂.
        A map the fill cannot take (too few visited cells, or a quadratic fill of a map that
        is not 2-D) is reported unfilled, as every cell a fill would have to invent is
        unvisited anyway."""
        if self.config.fill == "none":
            return table
        from estimation.observers.lpv_fill import fill_quadratic, fill_smooth, visited_cells

        visited = visited_cells(state.weight_sum)
        if visited.all():
            return table
        try:
            if self.config.fill == "quadratic":
                return fill_quadratic(table, visited)[0]
            return fill_smooth(table, visited)[0]
        except (ConfigError, ShapeError):
            return table


def lpv_run(
    state: LpvState,
    prepared: LpvPrepared,
    start: int,
    stop: int,
    *,
    gamma: float,
    adaptation: Literal["normalised", "constant"] = "normalised",
) -> tuple[LpvState, np.ndarray, np.ndarray, np.ndarray]:
    """Advance ``state`` over samples ``start:stop`` (pure: returns a new state).

    Returns the new state, ``x̂`` (m, 3) [Pa, Pa, rad/s], the estimated true compressor flow
    ``ρ1 x̂3`` (m,) and the estimated MAF error ``ψᵀθ̂`` (m,) [kg/s] after each sample.
    """
    if adaptation not in _MODES:
        raise ConfigError(f"adaptation must be 'normalised' or 'constant', got {adaptation!r}")
    out = state.copy()
    m = stop - start
    x_out = np.empty((m, 3))
    wc = np.empty(m)
    dwc = np.empty(m)
    sl = slice(start - prepared.offset, stop - prepared.offset)
    kernels.lpv.lpv_observer_kernel(
        out.x_hat, out.theta, out.weight_sum, out.excitation,
        prepared.idx[sl], prepared.w[sl], prepared.y[sl], prepared.rho[sl], prepared.e[sl],
        prepared.h[sl], prepared.accept[sl], out.L_scaled, out.state_scale, out.output_scale,
        out.rho_lo, out.rho_hi, out.a1, out.a2, float(gamma), _mode_code(adaptation),
        x_out, wc, dwc,
    )  # fmt: skip
    return dataclasses.replace(out, step=stop), x_out, wc, dwc


def _factory(config: BaseModel) -> LpvObserver:
    assert isinstance(config, LpvConfig)
    return LpvObserver(config)


LPV_COST = Cost(
    # x̂ (3), θ̂, the ψ weights and the excitation per element (3p), the gain and ρ box
    state_floats=lambda p, c: 3 * p + 64,
    # six output series, the prepared y, ρ (5), e, h, accept (9), the regressor twice (4c)
    # and the kernel's chunk outputs (5)
    sample_floats=lambda c: 20 + 4 * c,
    ops_per_sample=lambda p, c: 40 * c + 200,
    # the streamed check's fit output error and mask, with the temporaries of its statistics
    # (about 35 bytes a fit sample, the first 70 % of the log)
    stream_sample_bytes=25.0,
)

LPV = EstimatorSpec(
    name="lpv",
    title="LPV adaptive observer (MAF error map)",
    description="Air-path LPV observer with an LMI gain over the ρ box and a gradient "
    "law on the active map elements; estimates the additive MAF error ΔW_c(u_δ, n_e).",
    paper="Zhang et al. (2015), Sensors 15 — the LPV paper",
    kind=EstimatorKind.MAP_OBSERVER,
    config_model=LpvConfig,
    factory=_factory,
    state_class=LpvState,
    output_units=OUTPUT_UNITS,
    cost=LPV_COST,
)
LPV_SPECS = (LPV,)
