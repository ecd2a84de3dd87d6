"""Numeric settings of a filter, resolved from its config against a table grid."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation.errors import ConfigError
from estimation.filters.config import SensorConfig, TableFilterConfig
from estimation.signals import delay_samples as seconds_to_samples
from estimation.table import Axis, Grid, Table, broadcast_cells


@dataclass(frozen=True, slots=True, eq=False)
class FilterSettings:
    """Per-cell arrays and scalars the kernels take.

    ``sigma_w2`` is zero on locked cells (they are known constants); ``gate2`` is
    ``gate_sigma²`` or ``inf`` when the gate is off; ``delay`` is in samples.
    """

    sigma_w2: np.ndarray  # (p,) process noise variance per cell and sample
    sigma_v2: float  # measurement noise variance
    p0: np.ndarray  # (p,) initial variance / covariance cap
    limit: bool
    locked: np.ndarray  # (p,) bool
    gate2: float
    n_corners: int  # 2^d active elements per sample
    has_sensor: bool = False
    lag: float = 0.0
    sigma_f2: float = 0.0
    delay: int = 0
    forgetting: float = 1.0
    mu: float = 0.5
    eps: float = 1e-6


def grid_of(config: TableFilterConfig) -> Grid:
    return Grid([Axis(a.name, a.unit, a.breakpoints) for a in config.axes])


def initial_table(config: TableFilterConfig) -> Table:
    grid = grid_of(config)
    return Table(grid.axes, broadcast_cells(config.theta0, grid.shape, what="theta0"))


def resolve_settings(
    config: TableFilterConfig, grid: Grid, *, sample_period_s: float | None = None
) -> FilterSettings:
    """Turn a config into kernel settings; ``sample_period_s`` converts a delay in seconds.

    Per-cell values are checked here (shape, finiteness, signs), so building an estimator
    calls this once with ``sample_period_s=None`` to fail before any data is loaded; a delay
    given in seconds is then resolved to 0 until the log's sample period is known.
    """
    shape = grid.shape
    locked = np.zeros(grid.size, dtype=np.bool_)
    for cell in config.locked:
        locked[grid.cell_index(cell)] = True
    sigma_w = broadcast_cells(getattr(config, "sigma_w", 0.0), shape, what="sigma_w").ravel()
    if np.any(sigma_w < 0):
        raise ConfigError(f"sigma_w must be >= 0, got {sigma_w.min():g}")
    sigma_w2 = np.where(locked, 0.0, sigma_w**2)
    p0 = broadcast_cells(getattr(config, "p0", 0.0), shape, what="p0").ravel()
    if np.any(p0 < 0):
        raise ConfigError(f"p0 is a variance and must be >= 0, got {p0.min():g}")
    limit = getattr(config, "limit", "none") == "p0"
    if limit and np.any((p0 <= 0) & ~locked):
        raise ConfigError("limit='p0' caps each variance at P0, so P0 must be > 0 on every cell")
    gate2 = math.inf if config.gate_sigma is None else float(config.gate_sigma) ** 2
    settings = {
        "sigma_w2": sigma_w2,
        "sigma_v2": float(config.sigma_v) ** 2,
        "p0": p0,
        "limit": limit,
        "locked": locked,
        "gate2": gate2,
        "n_corners": grid.n_corners,
        "forgetting": float(getattr(config, "forgetting", 1.0)),
        "mu": float(getattr(config, "mu", 0.5)),
        "eps": float(getattr(config, "eps", 1e-6)),
    }
    sensor: SensorConfig | None = getattr(config, "sensor", None)
    if sensor is not None:
        settings |= {
            "has_sensor": True,
            "lag": float(sensor.lag),
            "sigma_f2": float(sensor.sigma_f) ** 2,
            "delay": delay_samples(sensor, sample_period_s),
        }
    return FilterSettings(**settings)


def delay_samples(sensor: SensorConfig, sample_period_s: float | None) -> int:
    """The sensor delay τ in samples: ``delay_samples`` if given, else ``delay_s/Ts`` rounded
    (0 while the sample period is unknown)."""
    if sensor.delay_samples is not None:
        return int(sensor.delay_samples)
    if not sensor.delay_s or sample_period_s is None:
        return 0
    return seconds_to_samples(sensor.delay_s, sample_period_s)
