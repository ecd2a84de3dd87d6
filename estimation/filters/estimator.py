"""The five map-updating filters behind the :class:`~estimation.estimator.Estimator` interface
and their registry specs."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from estimation.errors import ConfigError, ShapeError
from estimation.estimator import Chunk, ChunkedEstimator, LogWindows, WindowPlan
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
from estimation.filters.state import FilterState, KfState, LocalState, ThetaState
from estimation.registry import Cost, EstimatorKind, family
from estimation.signals import Signals
from estimation.table import Grid, Table

STATUS_DELAY = 3

REJECTION_REASONS = ("mask", "innovation", "delay")


#: Kernel steps per regressor block in :meth:`TableFilter.advance`. A chunk's regressor rows
#: (``2·2^d`` numbers a step) are made a block at a time, so a run never holds the whole
#: log's rows (64 B a step in 2-D), and a long fit does not fault in fresh pages for them,
#: which on a VM costs more than the kernel itself.
REGRESSOR_BLOCK = 1 << 16


@dataclass(frozen=True, eq=False)
class Prepared:
    """A log turned into kernel inputs: operating points ``u[k−τ]`` paired with the
    measurements ``y[k]`` they explain, the accept mask and the resolved settings. The
    regressor rows ``ψ(u)`` are made from the axis channels when needed
    (:meth:`regressor`)."""

    inputs: tuple[np.ndarray, ...]  # the axis channels over the steps, in axis order
    grid: Grid
    y: np.ndarray
    accept: np.ndarray
    time_s: np.ndarray
    measured: np.ndarray  # the output channel over the whole log, for residuals
    settings: FilterSettings
    offset: int = 0  # a window of a longer log: its first step's (and row's) index in it
    total: int = 0  # that log's samples (0: this is the whole log)

    def regressor(self, start: int = 0, stop: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(idx, w)`` of steps ``start:stop`` (:meth:`Grid.regressor`)."""
        return self.grid.regressor(np.column_stack([u[start:stop] for u in self.inputs]))

    @cached_property
    def rows(self) -> tuple[np.ndarray, np.ndarray]:
        """``(idx, w)`` of the whole log, made once on first use (benchmarks, tuning)."""
        return self.regressor()

    @property
    def idx(self) -> np.ndarray:
        return self.rows[0]

    @property
    def w(self) -> np.ndarray:
        return self.rows[1]


class TableFilter(ChunkedEstimator[FilterState, Prepared]):
    """A map-updating filter over a look-up table whose axes and output are log channels.

    ``run``, ``fit`` and the state check are :class:`~estimation.estimator.ChunkedEstimator`'s;
    a kernel step pairs a measurement with the operating point ``τ`` samples before it.
    """

    state_class = FilterState
    noun = "filter"
    windowed = True

    def __init__(self, name: str, config: TableFilterConfig) -> None:
        self.name = name
        self.config = config
        self.grid = grid_of(config)
        self.theta0 = initial_table(config)
        resolve_settings(config, self.grid)  # fail on bad per-cell values before any data

    def required_signals(self) -> list[str]:
        return [a.name for a in self.config.axes] + [self.config.output]

    def signal_roles(self) -> dict[str, list[str]]:
        return {"axis": [a.name for a in self.config.axes], "output": [self.config.output]}

    def output_names(self) -> tuple[str, ...]:
        return ("prediction", "residual")

    def prepare(
        self,
        signals: Signals,
        accept: np.ndarray | None = None,
        *,
        window: tuple[int, int, FilterSettings] | None = None,
    ) -> Prepared:
        """Regressor, aligned measurements and settings for a whole log, or with ``window =
        (offset, total, settings)`` for rows ``offset …`` of a log of ``total`` samples whose
        settings are resolved (:meth:`run_windows`).

        With a sensor delay of τ samples, kernel step ``i`` pairs the measurement ``y[i+τ]``
        with the operating point ``u[i]`` and is accepted only if both samples are.
        """
        signals.require(self.required_signals())
        offset, total = 0, 0
        if window is None:
            settings = self.settings_for(signals)
        else:
            offset, total, settings = window
        n = len(signals)
        tau = settings.delay
        if tau >= n:
            raise ConfigError(f"sensor delay of {tau} samples is not shorter than the log ({n})")
        mask = np.ones(n, dtype=np.bool_) if accept is None else np.asarray(accept, dtype=bool)
        if mask.shape != (n,):
            raise ShapeError(f"accept mask has shape {mask.shape}, the log has {n} samples")
        return Prepared(
            inputs=tuple(signals[a.name][: n - tau] for a in self.config.axes),
            grid=self.grid,
            y=np.ascontiguousarray(signals[self.config.output][tau:]),
            accept=mask[tau:] & mask[: n - tau],
            time_s=signals.time,
            measured=signals[self.config.output],
            settings=settings,
            offset=offset,
            total=total,
        )

    def needs_period(self) -> bool:
        """A sensor delay given in seconds: the log's sample period turns it into samples."""
        sensor = getattr(self.config, "sensor", None)
        return bool(sensor is not None and sensor.delay_samples is None and sensor.delay_s)

    def settings_for(self, signals: Signals) -> FilterSettings:
        """The kernel settings on a log: a delay in seconds needs its sample period."""
        needs_period = self.needs_period()
        if needs_period and len(signals) < 2:
            raise ConfigError("sensor.delay_s needs at least two samples to know the rate")
        period = signals.sample_period() if needs_period else None
        return resolve_settings(self.config, self.grid, sample_period_s=period)

    def plan_windows(self, log: LogWindows) -> WindowPlan:
        """A window of :meth:`run_windows` reads the τ rows after its last step, which its
        last measurements need (sensor delay); a delay in seconds is resolved, as by
        :meth:`run`, on the whole log's sample period (``log.timeline()``)."""
        settings = self.settings_on(log.n, log.timeline)
        tau = settings.delay
        if tau >= log.n:
            raise ConfigError(
                f"sensor delay of {tau} samples is not shorter than the log ({log.n})"
            )
        return WindowPlan(steps=log.n - tau, extra_rows=tau, context=settings)

    def prepare_window(
        self,
        signals: Signals,
        accept: np.ndarray | None,
        offset: int,
        n: int,
        context: FilterSettings,
    ) -> Prepared:
        return self.prepare(signals, accept, window=(offset, n, context))

    def settings_on(self, n: int, timeline: Callable[[], np.ndarray]) -> FilterSettings:
        """:meth:`settings_for` a log of ``n`` samples whose time column ``timeline()`` gives,
        read only when a delay in seconds needs the sample period."""
        if not self.needs_period():
            return resolve_settings(self.config, self.grid)
        time = timeline()
        if time.size != n:
            raise ConfigError(f"the time column has {time.size} samples, the log {n}")
        return self.settings_for(Signals(time, {}, copy=False))

    def initial_state(self, prepared: Prepared) -> FilterState:
        y_m0 = float(prepared.y[0]) if prepared.settings.has_sensor else None
        return initial_state(self.name, self.theta0.flat, prepared.settings, y_m0=y_m0)

    def steps(self, prepared: Prepared) -> int:
        return prepared.offset + int(prepared.y.size)

    def start(self, signals: Signals, prepared: Prepared) -> FilterState:
        return self.initial_state(prepared)

    def advance(
        self, state: FilterState, prepared: Prepared, stop: int
    ) -> tuple[FilterState, dict[str, np.ndarray], np.ndarray]:
        """:func:`run_chunk` over the steps, a :data:`REGRESSOR_BLOCK` at a time (the kernel
        carries its state across blocks, so the result is that of one call); the first chunk
        is padded with the ``τ`` delay samples, which have no prediction (status 3)."""
        start = state.step
        tau = prepared.settings.delay
        yhat = np.empty(stop - start)
        status = np.empty(stop - start, dtype=np.int8)
        off = prepared.offset  # steps a..z of the log are a−off..z−off of a window
        for a in range(start, stop, REGRESSOR_BLOCK):
            z = min(a + REGRESSOR_BLOCK, stop)
            idx, w = prepared.regressor(a - off, z - off)
            state, yhat[a - start : z - start], status[a - start : z - start] = run_chunk(
                state,
                idx,
                w,
                prepared.y[a - off : z - off],
                prepared.accept[a - off : z - off],
                prepared.settings,
            )
        if start == 0 and tau:
            yhat = np.concatenate([np.full(tau, np.nan), yhat])
            status = np.concatenate([np.full(tau, STATUS_DELAY, np.int8), status])
        return state, {"prediction": yhat}, status

    def times(self, prepared: Prepared) -> np.ndarray:
        return prepared.time_s

    def n_samples(self, prepared: Prepared) -> int:
        return prepared.total or int(prepared.time_s.size)

    def time_of(self, prepared: Prepared, sample: int) -> float:
        return float(prepared.time_s[max(sample - 1, 0) - prepared.offset])

    def log_sample(self, step: int, prepared: Prepared) -> int:
        return step + prepared.settings.delay if step else 0

    def report(self, state: FilterState, prepared: Prepared, chunk: Chunk) -> dict[str, Any]:
        yhat = chunk.outputs.get("prediction", np.empty(0))
        var = variance(state, prepared.settings)
        return {
            "table": Table(self.grid.axes, state.theta.reshape(self.grid.shape)),
            "variance": None if var is None else var.reshape(self.grid.shape),
            "outputs": {
                "prediction": yhat,
                "residual": prepared.measured[
                    chunk.first - prepared.offset : chunk.sample - prepared.offset
                ]
                - yhat,
            },
            "rejected": {
                "mask": state.rejected_mask,
                "innovation": state.rejected_gate,
                "delay": prepared.settings.delay,
            },
        }


# Per sample, every filter keeps: prediction and residual (2), the aligned measurement (1),
# status and accept codes (1), scoring temporaries (8), and 4c for regressor rows (c indices
# and c weights), kept from when the estimator and the worker each held the whole log's; both
# now make them per block or chunk, so this bound is loose by that much (test_cost.py).
_SAMPLE_FLOATS = 12


def _filter_samples(c: int) -> float:
    return _SAMPLE_FLOATS + 4 * c


KF_COST = Cost(
    # θ and P over the cells plus the sensor state: (p+1)² + (p+1)
    state_floats=lambda p, c: (p + 1) ** 2 + p + 1,
    sample_floats=_filter_samples,
    # P w (p·c), the rank-one update of P (2p²), the gain (4p)
    ops_per_sample=lambda p, c: 2 * p * p + p * c + 4 * p,
    max_cells=2000,  # P alone is 32 MB and a run's versions about 350 MB at this size
)
LOCAL_COST = Cost(
    # θ, the variances and the lazy-aging marks (3p); the active block with the sensor
    state_floats=lambda p, c: 3 * p + (c + 1) ** 2 + c,
    sample_floats=_filter_samples,
    ops_per_sample=lambda p, c: 4 * (c + 1) ** 2 + 20 * c,
)
GAIN_COST = Cost(
    state_floats=lambda p, c: p,  # θ is the whole state
    sample_floats=_filter_samples,
    ops_per_sample=lambda p, c: 6 * c,
)

_spec = family(
    TableFilter,
    TableFilterConfig,
    kind=EstimatorKind.MAP_FILTER,
    cost=LOCAL_COST,
    paper="Guardiola, Pla, Blanco-Rodriguez & Eriksson (2014), Control Engineering Practice "
    "— the SKF paper",
)
_UNITS = {"prediction": "", "residual": ""}  # both in the unit of the table's output

KF = _spec(
    "kf",
    "Kalman filter (full covariance)",
    "Optimal random-walk Kalman filter over every cell; O(p²) per sample. The reference "
    "the cheaper filters are judged against (SKF §4.4).",
    KfConfig,
    KfState,
    _UNITS,
    cost=KF_COST,
)
SKF = _spec(
    "skf",
    "Simplified Kalman filter",
    "Kalman update of the active cell only, variances of all cells kept, cross-covariances "
    "forgotten when a cell leaves; cost independent of table size (SKF §4.7).",
    SkfConfig,
    LocalState,
    _UNITS,
)
SSKF = _spec(
    "sskf",
    "Steady-state Kalman filter",
    "Fixed gains from the steady state of the local filter; no covariance, fastest, "
    "but fragile under poor excitation (SKF §4.5).",
    SskfConfig,
    ThetaState,
    _UNITS,
    cost=GAIN_COST,
)
RLS = _spec(
    "rls",
    "Recursive least squares (local, forgetting)",
    "RLS with exponential forgetting applied to the active cells only, so unexcited cells "
    "do not wind up (Peyton Jones & Muske style baseline).",
    RlsConfig,
    LocalState,
    _UNITS,
    # Not from the SKF paper: the textbook exponentially weighted RLS, restricted to the
    # active cells as Peyton Jones & Muske do for look-up tables.
    paper="Ljung & Söderström (1983), Theory and Practice of Recursive Identification, MIT "
    "Press; Haykin (2002), Adaptive Filter Theory, 4th ed., Prentice Hall; active cells only "
    "as in Peyton Jones & Muske (2009), ISA Transactions — exponentially weighted RLS baseline",
)
NLMS = _spec(
    "nlms",
    "Normalised LMS",
    "Distributes each error over the active cells in proportion to their weights; "
    "the classic ECU adaptation baseline.",
    NlmsConfig,
    ThetaState,
    _UNITS,
    cost=GAIN_COST,
    paper="Haykin (2002), Adaptive Filter Theory, 4th ed., Prentice Hall — normalised LMS baseline",
)
FILTER_SPECS = (KF, SKF, SSKF, RLS, NLMS)
