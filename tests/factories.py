"""Builders of random map-estimation problems shared by the tests.

A :class:`Problem` holds everything one filter run needs in plain numpy form (irregular axes,
inputs partly outside the grid, measurements with outliers, accept mask, per-cell settings,
locked cells, sensor lag and delay) and turns itself into the config dict and the
:class:`~estimation.signals.Signals` the estimators take, so the implementation and the slow
references in ``tests/estimation/reference.py`` read exactly the same problem.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from estimation.filters.functions import run_chunk
from estimation.filters.state import FilterState
from estimation.registry import EstimatorKind, get_spec, names
from estimation.signals import Signals

KINDS = names(EstimatorKind.MAP_FILTER)
SENSOR_KINDS = tuple(k for k in KINDS if "sensor" in get_spec(k).config_model.model_fields)


@dataclass(frozen=True)
class Sensor:
    lag: float
    delay: int  # samples
    sigma_f: float


@dataclass(frozen=True)
class Problem:
    """A random table-estimation problem. Arrays over cells are flat (C order), length p."""

    breakpoints: list[np.ndarray]
    U: np.ndarray  # (n, d) inputs
    y: np.ndarray  # (n,) measured table output
    accept: np.ndarray | None  # (n,) bool or None
    theta0: np.ndarray  # (p,)
    p0: np.ndarray  # (p,) variances
    sigma_w: np.ndarray  # (p,) standard deviations
    sigma_v: float
    locked_cells: list[list[int]] = field(default_factory=list)
    gate_sigma: float | None = None
    limit: bool = False
    sensor: Sensor | None = None
    forgetting: float = 0.98
    mu: float = 0.7
    eps: float = 0.1

    @property
    def names(self) -> list[str]:
        return [f"u{a + 1}" for a in range(len(self.breakpoints))]

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(g.size for g in self.breakpoints)

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    @property
    def n(self) -> int:
        return int(self.y.size)

    @property
    def locked(self) -> np.ndarray:
        mask = np.zeros(self.size, dtype=bool)
        for cell in self.locked_cells:
            mask[np.ravel_multi_index(tuple(cell), self.shape)] = True
        return mask

    def signals(self) -> Signals:
        channels = {name: self.U[:, a] for a, name in enumerate(self.names)}
        channels["y"] = self.y
        return Signals(0.02 * np.arange(self.n), channels)

    def config(self, kind: str) -> dict[str, Any]:
        """The config dict of filter ``kind`` (nested lists in table shape for cell values):
        the common keys, and of the others those the filter's config model has."""
        if kind not in KINDS:
            raise ValueError(kind)
        shape = self.shape
        cfg: dict[str, Any] = {
            "axes": [
                {"name": name, "breakpoints": g.tolist()}
                for name, g in zip(self.names, self.breakpoints, strict=True)
            ],
            "output": "y",
            "theta0": self.theta0.reshape(shape).tolist(),
            "locked": [list(c) for c in self.locked_cells],
            "gate_sigma": self.gate_sigma,
            "sigma_v": self.sigma_v,
        }
        specific: dict[str, Any] = {
            "sigma_w": self.sigma_w.reshape(shape).tolist(),
            "p0": self.p0.reshape(shape).tolist(),
            "limit": "p0" if self.limit else "none",
            "forgetting": self.forgetting,
            "mu": self.mu,
            "eps": self.eps,
        }
        if self.sensor is not None:
            specific["sensor"] = {
                "lag": self.sensor.lag,
                "delay_samples": self.sensor.delay,
                "sigma_f": self.sensor.sigma_f,
            }
        fields = get_spec(kind).config_model.model_fields
        return cfg | {key: value for key, value in specific.items() if key in fields}

    def without_sensor(self) -> Problem:
        return replace(self, sensor=None)


def random_axis(rng: np.random.Generator, n: int, *, start: float, span: float) -> np.ndarray:
    """Strictly increasing, irregularly spaced breakpoints covering ``[start, start+span]``."""
    steps = rng.uniform(0.2, 1.0, n - 1)
    return start + span * np.concatenate([[0.0], np.cumsum(steps) / steps.sum()])


def wandering_inputs(
    rng: np.random.Generator, g: np.ndarray, n: int, *, outside: float = 0.15
) -> np.ndarray:
    """Inputs that dwell in a cell for a while, then jump; ~``outside`` of the span beyond
    each edge so that clamping is exercised."""
    lo, hi = g[0], g[-1]
    span = hi - lo
    u = np.empty(n)
    x = rng.uniform(lo, hi)
    for k in range(n):
        if rng.random() < 0.08:
            x = rng.uniform(lo - outside * span, hi + outside * span)  # jump
        else:
            x += rng.normal(0.0, 0.04 * span)
        x = float(np.clip(x, lo - outside * span, hi + outside * span))
        u[k] = x
    return u


def multilinear(breakpoints: list[np.ndarray], values: np.ndarray, u: np.ndarray) -> float:
    """Slow multilinear interpolation of one input (clamped), for generating measurements."""
    import itertools

    cells, etas = [], []
    for g, x in zip(breakpoints, u, strict=True):
        x = min(max(x, g[0]), g[-1])
        i = min(int(np.searchsorted(g, x, side="right")) - 1, g.size - 2)
        cells.append(i)
        etas.append((x - g[i]) / (g[i + 1] - g[i]))
    out = 0.0
    for corner in itertools.product((0, 1), repeat=len(breakpoints)):
        weight = math.prod(e if b else 1.0 - e for e, b in zip(etas, corner, strict=True))
        out += weight * values[tuple(i + b for i, b in zip(cells, corner, strict=True))]
    return out


def random_problem(
    seed: int,
    *,
    shape: tuple[int, ...] = (5, 4),
    n: int = 300,
    n_locked: int = 2,
    gate_sigma: float | None = 4.0,
    outlier_rate: float = 0.04,
    mask_rate: float = 0.1,
    limit: bool = False,
    sensor: Sensor | None = None,
) -> Problem:
    """A random problem on a table of ``shape`` with ``n`` samples (see the module docstring)."""
    rng = np.random.default_rng(seed)
    breakpoints = [
        random_axis(rng, m, start=rng.uniform(-100, 100), span=rng.uniform(1, 1000)) for m in shape
    ]
    p = math.prod(shape)
    U = np.column_stack([wandering_inputs(rng, g, n) for g in breakpoints])
    for a, g in enumerate(breakpoints):  # make sure both edges are crossed on every axis
        span = g[-1] - g[0]
        below, above = rng.choice(n, size=(2, 3), replace=False)
        U[below, a] = g[0] - rng.uniform(0.01, 0.2, 3) * span
        U[above, a] = g[-1] + rng.uniform(0.01, 0.2, 3) * span
    truth = rng.normal(5.0, 2.0, shape)
    y_table = np.array([multilinear(breakpoints, truth, u) for u in U])
    sigma_v = float(rng.uniform(0.1, 0.3))
    if sensor is not None:  # the sensor sees the table through its delay and lag
        y_m = np.empty(n)
        state = y_table[0]
        for k in range(n):
            state = sensor.lag * state + (1 - sensor.lag) * y_table[max(k - sensor.delay, 0)]
            y_m[k] = state
        y_table = y_m
    y = y_table + rng.normal(0.0, sigma_v, n)
    outliers = rng.random(n) < outlier_rate
    y[outliers] += rng.choice([-1.0, 1.0], outliers.sum()) * rng.uniform(30, 60) * sigma_v
    accept = rng.random(n) >= mask_rate if mask_rate > 0 else None
    flat_locked = rng.choice(p, size=n_locked, replace=False)
    locked_cells = [[int(i) for i in np.unravel_index(j, shape)] for j in sorted(flat_locked)]
    return Problem(
        breakpoints=breakpoints,
        U=U,
        y=y,
        accept=accept,
        theta0=(truth + rng.normal(0.0, 0.3, shape)).ravel(),
        p0=rng.uniform(0.02, 0.2, p) if limit else rng.uniform(0.5, 3.0, p),
        sigma_w=rng.uniform(0.02, 0.3, p),
        sigma_v=sigma_v,
        locked_cells=locked_cells,
        gate_sigma=gate_sigma,
        limit=limit,
        sensor=sensor,
    )


@dataclass(frozen=True)
class ChunkedRun:
    """A map filter run over a :class:`Problem` in chunks: the state after each chunk, each
    chunk's predictions, statuses and innovation variances, and the regressor's cells."""

    states: list[FilterState]
    outputs: list[tuple[np.ndarray, np.ndarray, np.ndarray]]
    idx: np.ndarray


def run_in_chunks(
    kind: str, problem: Problem, chunk: int, *, specialised: bool = True
) -> ChunkedRun:
    """Filter ``kind`` over ``problem``, one :func:`run_chunk` call per ``chunk`` samples,
    carrying the state between the calls."""
    estimator = get_spec(kind).build(problem.config(kind))
    prepared = estimator.prepare(problem.signals(), problem.accept)
    state = estimator.initial_state(prepared)
    n = prepared.y.size
    bounds = [*range(0, n, chunk), n]
    run = ChunkedRun([], [], prepared.idx)
    for start, stop in itertools.pairwise(bounds):
        sl = slice(start, stop)
        s_out = np.empty(stop - start)
        state, yhat, status = run_chunk(
            state,
            prepared.idx[sl],
            prepared.w[sl],
            prepared.y[sl],
            prepared.accept[sl],
            prepared.settings,
            s_out=s_out,
            specialised=specialised,
        )
        run.states.append(state)
        run.outputs.append((yhat, status, s_out))
    return run


def state_bytes(state: FilterState) -> dict[str, bytes | object]:
    """A filter state's fields, arrays as their bytes: equal only if bit-identical."""
    return {
        f.name: (v.tobytes() if isinstance(v, np.ndarray) else v)
        for f in dataclasses.fields(state)
        for v in [getattr(state, f.name)]
    }
