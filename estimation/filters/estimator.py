"""The five map-updating filters behind the :class:`~estimation.estimator.Estimator` interface."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel

from estimation.errors import ConfigError, ShapeError, StateError
from estimation.estimator import EstimatorSpec, Snapshot
from estimation.filters.config import (
    KfConfig,
    NlmsConfig,
    RlsConfig,
    SkfConfig,
    SskfConfig,
    TableFilterConfig,
)
from estimation.filters.functions import initial_state, run_chunk, variance
from estimation.filters.settings import FilterSettings, grid_of, initial_table, resolve_settings
from estimation.filters.state import FilterState
from estimation.signals import Signals
from estimation.table import Table

STATUS_DELAY = 3

REJECTION_REASONS = ("mask", "innovation", "delay")


@dataclass(frozen=True, slots=True, eq=False)
class Prepared:
    """A log turned into kernel inputs: regressor rows paired with the measurements they
    explain (``y[k]`` with ``ψ(u[k−τ])``), the accept mask and the resolved settings."""

    idx: np.ndarray
    w: np.ndarray
    y: np.ndarray
    accept: np.ndarray
    time_s: np.ndarray
    measured: np.ndarray  # the output channel over the whole log, for residuals
    settings: FilterSettings


class TableFilter:
    """A map-updating filter over a look-up table whose axes and output are log channels."""

    def __init__(self, name: str, config: TableFilterConfig) -> None:
        self.name = name
        self.config = config
        self.grid = grid_of(config)
        self.theta0 = initial_table(config)
        resolve_settings(config, self.grid)  # fail on bad per-cell values before any data

    def required_signals(self) -> list[str]:
        return [a.name for a in self.config.axes] + [self.config.output]

    def prepare(self, signals: Signals, accept: np.ndarray | None = None) -> Prepared:
        """Regressor, aligned measurements and settings for a whole log.

        With a sensor delay of τ samples, kernel step ``i`` pairs the measurement ``y[i+τ]``
        with the operating point ``u[i]`` and is accepted only if both samples are.
        """
        signals.require(self.required_signals())
        sensor = getattr(self.config, "sensor", None)
        needs_period = sensor is not None and sensor.delay_samples is None and sensor.delay_s
        if needs_period and len(signals) < 2:
            raise ConfigError("sensor.delay_s needs at least two samples to know the rate")
        period = signals.sample_period() if needs_period else None
        settings = resolve_settings(self.config, self.grid, sample_period_s=period)
        n = len(signals)
        tau = settings.delay
        if tau >= n:
            raise ConfigError(f"sensor delay of {tau} samples is not shorter than the log ({n})")
        mask = np.ones(n, dtype=np.bool_) if accept is None else np.asarray(accept, dtype=bool)
        if mask.shape != (n,):
            raise ShapeError(f"accept mask has shape {mask.shape}, the log has {n} samples")
        idx, w = self.grid.regressor(signals.stack([a.name for a in self.config.axes])[: n - tau])
        return Prepared(
            idx=idx,
            w=w,
            y=np.ascontiguousarray(signals[self.config.output][tau:]),
            accept=mask[tau:] & mask[: n - tau],
            time_s=signals.time,
            measured=signals[self.config.output],
            settings=settings,
        )

    def initial_state(self, prepared: Prepared) -> FilterState:
        y_m0 = float(prepared.y[0]) if prepared.settings.has_sensor else None
        return initial_state(self.name, self.theta0.flat, prepared.settings, y_m0=y_m0)

    def run(
        self,
        signals: Signals,
        *,
        every: int | None = None,
        state: FilterState | None = None,
        accept: np.ndarray | None = None,
    ) -> Iterator[Snapshot]:
        """Filter the whole log in chunks of ``every`` samples, yielding a snapshot after each.

        ``state`` (from a snapshot, or :meth:`FilterState.load`) resumes where it stopped.
        """
        prepared = self.prepare(signals, accept)
        tau = prepared.settings.delay
        steps = prepared.y.size
        if state is None:
            state = self.initial_state(prepared)
        self._check_state(state, steps)
        chunk = steps if every is None else int(every)
        if chunk < 1:
            raise ConfigError(f"every must be >= 1 sample, got {every}")
        if state.step == steps:
            yield self._snapshot(state, prepared, state.step, np.empty(0), np.empty(0, np.int8))
            return
        while state.step < steps:
            start = state.step
            stop = min(start + chunk, steps)
            state, yhat, status = run_chunk(
                state,
                prepared.idx[start:stop],
                prepared.w[start:stop],
                prepared.y[start:stop],
                prepared.accept[start:stop],
                prepared.settings,
            )
            if start == 0 and tau:
                yhat = np.concatenate([np.full(tau, np.nan), yhat])
                status = np.concatenate([np.full(tau, STATUS_DELAY, np.int8), status])
            yield self._snapshot(state, prepared, start, yhat, status)

    def fit(self, signals: Signals, *, accept: np.ndarray | None = None) -> Snapshot:
        """Run over the whole log in one chunk and return the final snapshot."""
        last = None
        for last in self.run(signals, accept=accept):  # noqa: B007
            pass
        assert last is not None
        return last

    def _check_state(self, state: FilterState, steps: int) -> None:
        if state.kind != self.name:
            raise StateError(f"state of a {state.kind!r} filter cannot resume {self.name!r}")
        if state.theta.size != self.grid.size:
            raise StateError(f"state has {state.theta.size} cells, the table {self.grid.size}")
        if not 0 <= state.step <= steps:
            raise StateError(f"state is at step {state.step}, the log has {steps} usable steps")

    def _snapshot(
        self,
        state: FilterState,
        prepared: Prepared,
        start: int,
        yhat: np.ndarray,
        status: np.ndarray,
    ) -> Snapshot:
        tau = prepared.settings.delay
        n = prepared.time_s.size
        sample = state.step + tau
        first = 0 if start == 0 else start + tau
        measured = prepared.measured[first:sample]
        var = variance(state, prepared.settings)
        return Snapshot(
            estimator=self.name,
            sample=sample,
            n_samples=n,
            time_s=float(prepared.time_s[sample - 1]) if sample else float(prepared.time_s[0]),
            state=state,
            chunk_start=first,
            table=Table(self.grid.axes, state.theta.reshape(self.grid.shape)),
            variance=None if var is None else var.reshape(self.grid.shape),
            outputs={"prediction": yhat, "residual": measured - yhat},
            status=status,
            rejected={
                "mask": state.rejected_mask,
                "innovation": state.rejected_gate,
                "delay": tau,
            },
        )


def _filter_spec(
    name: str, title: str, description: str, config_model: type[TableFilterConfig]
) -> EstimatorSpec:
    def factory(config: BaseModel) -> TableFilter:
        assert isinstance(config, TableFilterConfig)
        return TableFilter(name, config)

    return EstimatorSpec(
        name=name,
        title=title,
        description=description,
        paper="Guardiola, Pla, Blanco-Rodriguez & Eriksson (2014), Control Engineering "
        "Practice — the SKF paper",
        config_model=config_model,
        factory=factory,
    )


FILTER_SPECS = (
    _filter_spec(
        "kf",
        "Kalman filter (full covariance)",
        "Optimal random-walk Kalman filter over every cell; O(p²) per sample. The reference "
        "the cheaper filters are judged against (SKF §4.4).",
        KfConfig,
    ),
    _filter_spec(
        "skf",
        "Simplified Kalman filter",
        "Kalman update of the active cell only, variances of all cells kept, cross-covariances "
        "forgotten when a cell leaves; cost independent of table size (SKF §4.7).",
        SkfConfig,
    ),
    _filter_spec(
        "sskf",
        "Steady-state Kalman filter",
        "Fixed gains from the steady state of the local filter; no covariance, fastest, "
        "but fragile under poor excitation (SKF §4.5).",
        SskfConfig,
    ),
    _filter_spec(
        "rls",
        "Recursive least squares (local, forgetting)",
        "RLS with exponential forgetting applied to the active cells only, so unexcited cells "
        "do not wind up (Peyton Jones & Muske style baseline).",
        RlsConfig,
    ),
    _filter_spec(
        "nlms",
        "Normalised LMS",
        "Distributes each error over the active cells in proportion to their weights; "
        "the classic ECU adaptation baseline.",
        NlmsConfig,
    ),
)
