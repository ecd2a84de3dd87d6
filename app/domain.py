"""Domain objects the repositories return and the services and routers use (not ORM rows)."""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass, field
from datetime import datetime
from enum import StrEnum
from typing import Any, Generic, TypeVar

import numpy as np

T = TypeVar("T")


class RunStatus(StrEnum):
    """A run's status; the values are what the database and the JSON carry."""

    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"
    INTERRUPTED = "interrupted"


FINISHED = (RunStatus.SUCCEEDED, RunStatus.FAILED, RunStatus.CANCELLED, RunStatus.INTERRUPTED)
RESUMABLE = (RunStatus.INTERRUPTED, RunStatus.CANCELLED)


class SeriesRole(StrEnum):
    """What a result series is: an operating-point input channel, the measured output, an
    estimator output (estimate), a simulated truth, the error truth − estimate, or the
    rejection mask (1 where a gate or the estimator rejected the sample, 0 where accepted)."""

    INPUT = "input"
    MEASURED = "measured"
    OUTPUT = "output"
    TRUTH = "truth"
    ERROR = "error"
    REJECTED = "rejected"


@dataclass(frozen=True, slots=True)
class Channel:
    """A dataset's channel; ``masked``: its samples masked on upload (non-finite or flagged
    invalid, filled from the valid neighbours, `docs/data-formats.md#multi-rate`);
    ``timing``: in a dataset stored as recorded, ``(start_s, stop_s, step_s)``: its first
    and last valid sample and its median time step."""

    name: str
    unit: str
    masked: int = 0
    timing: tuple[float, float, float] | None = None


@dataclass(frozen=True, slots=True)
class StoredSamples:
    """Where a dataset's samples are in the artifact store (:mod:`app.store`), and their
    SHA-256."""

    dataset_id: int
    key: str
    sha256: str


@dataclass(frozen=True, slots=True)
class Dataset:
    id: int
    name: str
    source: str
    rows: int
    rate_hz: float
    duration_s: float
    time_column: str
    channels: list[Channel]
    scenario: str | None
    seed: int | None
    has_truth: bool
    created_at: datetime
    # What ingest said about the upload (channels skipped, dropped, masked, resampled).
    notes: tuple[str, ...] = ()

    @property
    def masked(self) -> dict[str, int]:
        """The masked samples of each channel that has any."""
        return {c.name: c.masked for c in self.channels if c.masked}

    def unit_of(self, name: str) -> str:
        return next((c.unit for c in self.channels if c.name == name), "")

    @property
    def recorded(self) -> bool:
        """Stored as recorded: its channels on their own timestamps, resampled when read."""
        return any(c.timing is not None for c in self.channels)

    def timing_of(self, name: str) -> tuple[float, float, float] | None:
        return next((c.timing for c in self.channels if c.name == name), None)

    def rows_for(self, names: Collection[str], step_s: float | None = None) -> tuple[int, float]:
        """Rows and rate (Hz) of a read of the channels ``names``: the dataset's own, unless
        it is stored as recorded, where the read is on the raster of step ``step_s``
        (default: the slowest among them) over the span they all cover
        (`docs/data-formats.md#multi-rate`): ``rows = ⌊(min stop − max start) / step⌋ + 1``,
        exact for a uniform raster."""
        timings = [c.timing for c in self.channels if c.name in names and c.timing is not None]
        if not timings:
            return self.rows, self.rate_hz
        step = step_s if step_s is not None else max(t[2] for t in timings)
        span = min(t[1] for t in timings) - max(t[0] for t in timings)
        if not (step > 0 and span > 0):
            return self.rows, self.rate_hz
        return math.floor(span / step * (1 + 1e-12)) + 1, 1.0 / step

    def has_channel(self, name: str) -> bool:
        return any(c.name == name for c in self.channels)


@dataclass(frozen=True, slots=True)
class Run:
    id: int
    dataset_id: int
    name: str
    estimator: str
    status: RunStatus
    progress: float
    sample: int
    n_samples: int
    error: str | None
    signals: dict[str, str]
    table: dict[str, Any] | None
    config: dict[str, Any]
    estimator_config: dict[str, Any]
    rejected: dict[str, int]
    produces_map: bool
    base_map_id: int | None
    stop_request: str | None
    attempt: int
    lost_attempts: int
    owner: str | None
    heartbeat_at: datetime | None
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    metrics: dict[str, float | None] = field(default_factory=dict)
    n_versions: int = 0
    group_id: int | None = None
    params: dict[str, Any] | None = None

    @property
    def finished(self) -> bool:
        return self.status in FINISHED


@dataclass(frozen=True, slots=True)
class RunGroup:
    """A sweep or a fleet batch (see ``RunGroupRow``)."""

    id: int
    kind: str
    name: str
    estimator: str
    request: dict[str, Any]
    metric: str | None
    order: str | None
    created_at: datetime


@dataclass(frozen=True, slots=True)
class VersionSummary:
    """A stored version in short. ``id`` is the database's (unique over all runs);
    ``number`` is its place 1…n in its run by step, what people, URLs and exports call it
    ("run 12 version 3"). Derived, not stored: a resumed run that drops its later versions
    numbers the new ones on from the last kept."""

    id: int
    run_id: int
    step: int
    time_s: float
    label: str | None
    final: bool
    created_at: datetime
    number: int


@dataclass(frozen=True, slots=True)
class MapVersion:
    """A version with its arrays (``values`` is ``None`` for estimators without a map)."""

    summary: VersionSummary
    axes: list[dict[str, Any]] | None
    values: np.ndarray | None
    variances: np.ndarray | None
    visits: np.ndarray | None
    cell_rejections: dict[str, np.ndarray]
    rejected: dict[str, int]


@dataclass(frozen=True, slots=True)
class ResumePoint:
    """What a resumed run continues from: the last version's state and accumulators."""

    version_id: int
    step: int
    state: dict[str, Any]
    visits: np.ndarray | None
    cell_rejections: dict[str, np.ndarray]
    segments: list[dict[str, np.ndarray]]


@dataclass(frozen=True, slots=True)
class Series:
    """A result series. ``name`` is its key, unique within the run (the channel or output
    name, qualified as ``role:name`` only where two roles share a name); ``role`` is ``None``
    for a series stored before roles were recorded."""

    name: str
    unit: str
    time: np.ndarray
    values: np.ndarray
    role: SeriesRole | None = None


@dataclass(frozen=True, slots=True)
class BaseMap:
    id: int
    name: str
    source: str
    axes: list[dict[str, Any]]
    values: np.ndarray
    run_id: int | None
    version_id: int | None
    dataset_id: int | None
    estimator: str | None
    config: dict[str, Any] | None
    parent_base_map_id: int | None
    metrics: dict[str, Any]
    created_at: datetime
    # The promoted version's number 1…n in its run; None for a file or a version since deleted.
    version_number: int | None = None


@dataclass(frozen=True, slots=True)
class Ecu:
    """An uploaded A2L with the ECU's current values (``values_format`` ``None``: none)."""

    id: int
    name: str
    a2l_sha256: str
    characteristics: int
    values_format: str | None
    created_at: datetime


SCOPES = ("read", "run", "admin")  # what a token may do; see docs/security.md
DEFAULT_SCOPES = ("read", "run")  # a new token's scopes unless the admin names them


@dataclass(frozen=True, slots=True)
class ApiToken:
    id: int
    name: str
    prefix: str
    created_at: datetime
    last_used_at: datetime | None
    revoked_at: datetime | None
    scopes: tuple[str, ...] = SCOPES


@dataclass(frozen=True, slots=True)
class Page(Generic[T]):
    items: list[T]
    total: int
    limit: int
    offset: int
