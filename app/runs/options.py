"""A run's service-level options (pace, version cadence, gates), parsed from its config.

Validated when the run is planned (``POST /api/runs``) and again by every worker that
executes it, so both read the config the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from app.domain import Dataset
from app.errors import InvalidRequestError
from app.io.errors import InputError
from app.io.resample import Raster, parse_raster
from estimation.estimator import ChunkedEstimator, Estimator
from estimation.registry import EstimatorSpec

MAX_VERSIONS = 1000  # persisted versions per run (each carries the map and estimator state)
MIN_PACE = 0.01  # slowest replay, × real time: a slower one holds a worker for ages


@dataclass(frozen=True, slots=True)
class RunOptions:
    """Service-level settings of a run (not the estimator's)."""

    pace: float | None  # real-time multiple; None: as fast as possible
    version_every: int  # samples between persisted map versions
    gates: list[dict[str, Any]]


def streams_input(
    spec: EstimatorSpec, dataset: Dataset, estimator: Estimator | None = None
) -> bool:
    """Whether a run reads its log a window at a time from the store, never whole
    (`docs/data-formats.md#streamed-runs`): when nothing in it needs the whole log — an
    estimator that plans windows
    (:meth:`~estimation.estimator.ChunkedEstimator.run_windows`; ``None``: not built yet,
    as its spec says), of a spec with a windowed check
    (:attr:`~estimation.registry.EstimatorSpec.streams`): every built-in one, on an
    uploaded dataset, dense or stored as recorded (put on its raster a window at a time,
    :class:`~app.store.raster_rows.RasterRows`); a simulated one is read whole, as its truth
    is scored on the whole log. Its sample gates are scanned a window at a time too
    (:func:`app.runs.gates.scan_gates`)."""
    windowed = estimator is None or (isinstance(estimator, ChunkedEstimator) and estimator.windowed)
    return windowed and spec.streams and dataset.scenario is None


def run_raster(config: dict[str, Any]) -> Raster | None:
    """The raster a run asks for (``config.raster``: ``"100Hz"``, ``"10ms"``,
    ``"channel:NAME"``), ``None`` without one: the slowest among its channels. It applies to
    a dataset stored as recorded (`docs/data-formats.md#multi-rate`); 422 on
    ``config.raster`` for anything :func:`~app.io.resample.parse_raster` refuses."""
    value = config.get("raster")
    if value is None:
        return None
    if not isinstance(value, str):
        raise InvalidRequestError(
            f"raster must be a string such as '10ms' or 'channel:NAME', got {value!r}",
            field="config.raster",
        )
    try:
        raster = parse_raster(value)
    except InputError as exc:
        raise InvalidRequestError(str(exc), field="config.raster") from None
    return None if raster == Raster() else raster


def run_options(config: dict[str, Any], rows: int, rate_hz: float, fraction: float) -> RunOptions:
    """Parse the service keys of a run config (validated again by every worker)."""
    pace_raw = config.get("pace", "max")
    if pace_raw == "max" or pace_raw is None:
        pace = None
    elif isinstance(pace_raw, int | float) and not isinstance(pace_raw, bool):
        if not (math.isfinite(pace_raw) and pace_raw >= MIN_PACE):
            raise InvalidRequestError(
                f"pace must be 'max' or a finite real-time multiple >= {MIN_PACE:g}, "
                f"got {pace_raw!r}",
                field="config.pace",
            )
        pace = float(pace_raw)
    else:
        raise InvalidRequestError(
            f"pace must be 'max' or a finite real-time multiple >= {MIN_PACE:g}, got {pace_raw!r}",
            field="config.pace",
        )
    every_raw = config.get("version_every")
    if every_raw is None:
        every = max(1, math.ceil(rows * fraction))
    elif isinstance(every_raw, dict) and set(every_raw) == {"samples"}:
        n = every_raw["samples"]
        if not isinstance(n, int) or isinstance(n, bool) or n < 1:
            raise InvalidRequestError(
                f"version_every.samples must be an integer >= 1, got {n!r}",
                field="config.version_every.samples",
            )
        every = n
    elif isinstance(every_raw, dict) and set(every_raw) == {"seconds"}:
        sec = every_raw["seconds"]
        if not isinstance(sec, int | float) or isinstance(sec, bool) or not sec > 0:
            raise InvalidRequestError(
                f"version_every.seconds must be > 0, got {sec!r}",
                field="config.version_every.seconds",
            )
        every = max(1, round(sec * rate_hz))
    else:
        raise InvalidRequestError(
            'version_every must be {"samples": N} or {"seconds": S}',
            field="config.version_every",
        )
    if math.ceil(rows / every) > MAX_VERSIONS:
        raise InvalidRequestError(
            f"a version every {every} samples gives {math.ceil(rows / every)} versions of this "
            f"{rows}-sample log; at most {MAX_VERSIONS} per run (every >= "
            f"{math.ceil(rows / MAX_VERSIONS)} samples)",
            field="config.version_every",
        )
    gates = config.get("gates") or []
    if not isinstance(gates, list):
        raise InvalidRequestError("gates must be a list of gate objects", field="config.gates")
    return RunOptions(pace=pace, version_every=every, gates=gates)
