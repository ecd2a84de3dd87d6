"""Admission control: refuse, before anything is stored, work the host cannot afford.

Every run — alone, in a sweep or in a batch — and every base-map import is checked against
the service's limits (:class:`Limits`, from ``MAPWISE_RUN_MEMORY_MB``, ``MAPWISE_MAX_CELLS``,
``MAPWISE_RUN_VERSIONS_MB`` and ``MAPWISE_RUN_MAX_S``) with the estimator's declared cost
(:class:`estimation.registry.Cost`); a sweep's or batch's runs together, against
``MAPWISE_SWEEP_VERSIONS_MB`` (:class:`GroupBudget`). A refusal is a 422 ``over_budget``
naming the field to change, the limit and the predicted figure ("predicted 7.3 TiB > 2.9 GiB
run budget").

The predicted memory of a run is::

    WORKER_BASE_BYTES + (1 + h) · cost.memory_bytes(p, n, c) + 2 · 8 · channels · n

and of a streamed run (any estimator on an uploaded log, reading it a window at a time from
the store, :func:`app.runs.options.streams_input`), with
``w = min(n, STREAM_ROWS)`` the rows it holds::

    WORKER_BASE_BYTES + (1 + h) · cost.memory_bytes(p, w, c) + 2 · 8 · channels · w
        + (8 · outputs + 11 + s + 8 · r) · n

the worker process itself, the estimator's declared cost for the run and for its held-out
refit (``h = cost.holdout_passes``: 1, or 0 for an estimator without a truth-free check,
since the refit runs while the run's own data are held), and the dataset (its Parquet object
as read from the artifact store, and the unpacked channels); a streamed run keeps only its
per-sample outputs and status codes for the whole log, at its end the RMSE's copy of the
accepted residuals, and what else it keeps a sample (``s =
cost.stream_sample_bytes``: the LPV check's fit output error, an EKF's measured excess), and
on a dataset stored as recorded (``r = 1``) its raster's time column. A run
with ``g`` sample gates holds ``(2 · g + 3) · n`` bytes more: each gate's mask and first-gate
share, the accept mask and the first gate rejecting each sample (a streamed run scans its
gates a window at a time, :func:`app.runs.gates.scan_gates`).
The compute time counts the refit's work the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from app.config import Settings
from app.errors import InvalidRequestError
from estimation.registry import EstimatorSpec

WORKER_BASE_BYTES = 256 * 2**20
"""A run worker before any run: Python, NumPy, SQLAlchemy and the compiled kernels
(measured at about 140 MiB after imports and 250 MiB with every kernel loaded)."""
OPS_PER_S_CEILING = 1e10
"""More arithmetic a second than one core does: ``work / OPS_PER_S_CEILING`` is a lower
bound on a run's duration, so only runs that cannot finish in the budget are refused."""
FLOAT_BYTES = 8
STREAM_SAMPLE_BYTES = 11
"""What a streamed run keeps per sample besides its outputs: the status code (1 byte), and at
its end the RMSE's copy of the accepted residuals (8) and its two masks (2)."""
GATE_MASK_BYTES = 2
"""What each sample gate keeps per sample: its mask and its first-gate share (1 byte each)."""
GATES_SAMPLE_BYTES = 3
"""What a gated run keeps per sample besides the masks: the accept mask (1 byte) and the
index of the first gate rejecting each sample (2)."""
STREAM_ROWS = 1 << 20
"""Rows a streamed run holds at most: its window (``WINDOW_STEPS`` of
:mod:`estimation.filters.estimator`), the decoded row groups it caches
(:data:`app.store.log_rows.CACHED_GROUPS`) and a live tick's span, rounded up."""


class OverBudgetError(InvalidRequestError):
    """The request would exceed one of the service's resource limits."""

    code = "over_budget"


@dataclass(frozen=True, slots=True)
class Limits:
    """The resource limits of one run (and of a base map's size)."""

    run_memory_bytes: int
    max_cells: int
    versions_bytes: int
    run_max_s: float
    group_versions_bytes: int = 8192 * 2**20  # a sweep's or batch's runs in all

    @classmethod
    def from_settings(cls, settings: Settings) -> Limits:
        return cls(
            run_memory_bytes=int(settings.run_memory_mb * 2**20),
            max_cells=settings.max_cells,
            versions_bytes=int(settings.run_versions_mb * 2**20),
            run_max_s=settings.run_max_s,
            group_versions_bytes=int(settings.sweep_versions_mb * 2**20),
        )


@dataclass(frozen=True, slots=True)
class Prediction:
    """What admission predicted for an admitted run."""

    memory_bytes: int
    versions_bytes: int
    duration_s: float


def human_bytes(n: float) -> str:
    """``7.3 TiB``, ``512 MiB``, ``80 B``."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


def human_seconds(s: float) -> str:
    """``45 s``, ``12.5 min``, ``6.0 h``, ``3.2e+04 years``."""
    if s < 120:
        return f"{s:.0f} s"
    if s < 7200:
        return f"{s / 60:.1f} min"
    if s < 3 * 86400 * 365:
        return f"{s / 3600:.1f} h"
    return f"{s / (86400 * 365):.3g} years"


def cell_cap(spec: EstimatorSpec | None, limits: Limits) -> int:
    """The most cells ``spec``'s table may have (the global cap, or the estimator's)."""
    declared = None if spec is None else spec.cost.max_cells
    return limits.max_cells if declared is None else min(declared, limits.max_cells)


def check_cells(
    cells: int, limits: Limits, *, field: str, spec: EstimatorSpec | None = None, what: str = ""
) -> None:
    """Refuse a table (or base map) over the cell cap, before anything of its size exists."""
    cap = cell_cap(spec, limits)
    if cells > cap:
        owner = (
            f"{spec.name}'s cap"
            if spec is not None and spec.cost.max_cells == cap
            else "the cap (MAPWISE_MAX_CELLS)"
        )
        raise OverBudgetError(
            f"{what or 'the table'} has {cells:,} cells > {cap:,}, {owner}", field=field
        )


def admit_run(
    spec: EstimatorSpec,
    *,
    cells: int,
    corners: int,
    samples: int,
    channels: int,
    version_every: int,
    log_duration_s: float,
    pace: float | None,
    limits: Limits,
    table_field: str = "table.axes",
    streamed: bool = False,
    gates: int = 0,
    raster: bool = False,
    samples_field: str = "dataset_id",
) -> Prediction:
    """Check a planned run against ``limits``; an :class:`OverBudgetError` naming the field
    to change if it does not fit (``samples_field`` where the samples are too many: the
    dataset, or the raster that made them), else the predicted figures."""
    check_cells(cells, limits, field=table_field, spec=spec)
    cost = spec.cost
    held = min(samples, STREAM_ROWS) if streamed else samples  # rows in memory at once
    data = FLOAT_BYTES * 2 * channels * held
    if streamed:
        per_sample = FLOAT_BYTES * len(spec.output_units) + STREAM_SAMPLE_BYTES
        if raster:  # stored as recorded: the raster's time column (app.store.raster_rows)
            per_sample += FLOAT_BYTES
        data += int((per_sample + cost.stream_sample_bytes) * samples)
    if gates:
        data += (GATE_MASK_BYTES * gates + GATES_SAMPLE_BYTES) * samples
    memory = WORKER_BASE_BYTES + cost.run_memory_bytes(cells, held, corners=corners) + data
    if memory > limits.run_memory_bytes:
        grows_with_table = cost.run_memory_bytes(cells, 0, corners=corners) > data
        raise OverBudgetError(
            f"{spec.name} on {cells:,} cells and {samples:,} samples: predicted "
            f"{human_bytes(memory)} > {human_bytes(limits.run_memory_bytes)} run budget "
            "(MAPWISE_RUN_MEMORY_MB)",
            field=table_field if grows_with_table else samples_field,
        )
    versions = math.ceil(samples / version_every) + 1  # the cadence's versions and the final
    segments = FLOAT_BYTES * (len(spec.output_units) + 1) * samples
    per_version = cost.version_bytes(cells, corners=corners)
    stored = versions * per_version + segments
    if stored > limits.versions_bytes:
        fits = (limits.versions_bytes - segments) // max(per_version, 1) - 1
        hint = (
            f"; a version every {math.ceil(samples / fits):,} samples or more fits"
            if fits >= 1
            else "; one version of this table does not fit"
        )
        raise OverBudgetError(
            f"{versions:,} map versions of {human_bytes(per_version)}: predicted "
            f"{human_bytes(stored)} stored > {human_bytes(limits.versions_bytes)} version "
            f"budget (MAPWISE_RUN_VERSIONS_MB){hint}",
            field="config.version_every" if fits >= 1 else table_field,
        )
    compute_s = cost.run_work(cells, samples, corners=corners) / OPS_PER_S_CEILING
    if compute_s > limits.run_max_s:
        raise OverBudgetError(
            f"{spec.name} on {cells:,} cells and {samples:,} samples: at least "
            f"{human_seconds(compute_s)} of computation > {human_seconds(limits.run_max_s)} "
            "run budget (MAPWISE_RUN_MAX_S)",
            field=table_field if cells else samples_field,
        )
    duration = compute_s
    if pace is not None:
        paced_s = log_duration_s / pace
        if paced_s > limits.run_max_s:
            raise OverBudgetError(
                f"a {human_seconds(log_duration_s)} log at pace {pace:g} takes "
                f"{human_seconds(paced_s)} > {human_seconds(limits.run_max_s)} run budget "
                f"(MAPWISE_RUN_MAX_S); pace >= {log_duration_s / limits.run_max_s:.3g} fits",
                field="config.pace",
            )
        duration = max(duration, paced_s)
    return Prediction(memory_bytes=memory, versions_bytes=stored, duration_s=duration)


class GroupBudget:
    """The map versions a sweep's or batch's runs may store in all: each member's predicted
    bytes are added as it is planned, and :meth:`check` refuses the sum over
    ``limits.group_versions_bytes`` (a sweep of 2000 runs each within its own 512 MiB could
    otherwise store 1000 GiB)."""

    def __init__(self, limits: Limits, *, what: str, field: str) -> None:
        self.limit, self.what, self.field = limits.group_versions_bytes, what, field
        self.runs = 0
        self.costed = 0  # members with a prediction (that store versions)
        self.total = 0

    def add(self, prediction: Prediction | None) -> None:
        self.runs += 1
        if prediction is not None:
            self.costed += 1
            self.total += prediction.versions_bytes

    def check(self) -> None:
        """:class:`OverBudgetError` naming the predicted sum, the budget and how many such
        runs fit."""
        if self.total <= self.limit:
            return
        fits = int(self.limit // max(self.total / max(self.costed, 1), 1))
        raise OverBudgetError(
            f"the {self.what}'s {self.runs:,} runs would store {human_bytes(self.total)} of map "
            f"versions in all (predicted) > {human_bytes(self.limit)} {self.what} budget "
            f"(MAPWISE_SWEEP_VERSIONS_MB); {fits:,} such runs fit, or version less often "
            "(config.version_every)",
            field=self.field,
        )
