"""Response and request bodies of the HTTP API (what OpenAPI documents).

Routers build these from domain objects; arrays are nested lists with ``null`` for NaN.
"""

from __future__ import annotations

import json
from datetime import datetime
from typing import Annotated, Any, Generic, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, field_validator

from app.domain import BaseMap, Dataset, MapVersion, Run, RunStatus, SeriesRole, VersionSummary
from app.io.decimate import nested_or_none
from app.io.names import name_schema
from app.services.catalog import ScenarioName

MAX_EDITS_BYTES = 256 * 1024  # a base map's edit lineage, as compact JSON

T = TypeVar("T")

Nested = list[Any]


class ErrorBody(BaseModel):
    code: str = Field(description="validation_error, not_found, conflict, payload_too_large, …")
    message: str
    field: str | None = Field(description="The offending field, column or channel.")


class ErrorOut(BaseModel):
    error: ErrorBody


ERRORS: dict[int | str, dict[str, Any]] = {
    code: {"model": ErrorOut} for code in (400, 401, 403, 404, 405, 409, 413, 415, 422)
}


class PageOut(BaseModel, Generic[T]):
    items: list[T]
    total: int
    limit: int
    offset: int


class HealthOut(BaseModel):
    status: Literal["ok"]
    database: Literal["sqlite", "postgresql"]
    revision: str | None
    version: str
    auth_required: bool
    workers: int
    workers_alive: int | None = Field(
        description="Run worker processes alive now (local executor; null on Dask): fewer "
        "than workers before the first runs with MAPWISE_RUN_WORKERS_PRESTART=false."
    )
    loop_lag_ms: float = Field(
        description="Worst lateness of the event loop over the last 30 s, in milliseconds."
    )
    loop_cpu_s: float = Field(
        description="CPU seconds the event loop's thread has used since the server started "
        "(sampled every 20 ms); its growth over a wall-clock interval is the share of it "
        "the loop was busy."
    )


class ChannelOut(BaseModel):
    name: str
    unit: str


class DatasetOut(BaseModel):
    id: int
    name: str
    source: str
    rows: int
    rate_hz: float
    duration_s: float
    channels: list[ChannelOut]
    time_column: str
    has_truth: bool
    scenario: str | None
    seed: int | None
    created_at: datetime
    # What ingest did on upload, and the masked (non-finite or invalid) samples per channel
    # that had any (docs/data-formats.md#multi-rate); null when there is nothing to say.
    notes: list[str] | None = None
    masked: dict[str, int] | None = None
    # Stored as recorded (channels on their own timestamps): a run may then choose its raster
    # (config.raster, docs/rest-api.md#run-config); ``timing`` gives each channel's own time
    # base [start_s, stop_s, step_s] (docs/data-formats.md#multi-rate), null otherwise.
    recorded: bool = False
    timing: dict[str, list[float]] | None = None

    @classmethod
    def of(cls, d: Dataset) -> DatasetOut:
        return cls(
            id=d.id,
            name=d.name,
            source=d.source,
            rows=d.rows,
            rate_hz=d.rate_hz,
            duration_s=d.duration_s,
            channels=[ChannelOut(name=c.name, unit=c.unit) for c in d.channels],
            time_column=d.time_column,
            has_truth=d.has_truth,
            scenario=d.scenario,
            seed=d.seed,
            created_at=d.created_at,
            notes=list(d.notes) or None,
            masked=d.masked or None,
            recorded=d.recorded,
            timing={c.name: [float(v) for v in c.timing] for c in d.channels if c.timing} or None,
        )


def _duration_per_scenario(schema: dict[str, Any]) -> None:
    """Each scenario's own ``duration_s`` range in the schema: at least two samples, at most
    its length (what the service checks)."""
    from estimation.scenarios import scenarios

    schema["anyOf"] = [
        {
            "properties": {
                "scenario": {"const": name},
                "duration_s": {
                    "anyOf": [
                        {"type": "number", "minimum": 1 / s.rate_hz, "maximum": s.duration_s},
                        {"type": "null"},
                    ]
                },
            }
        }
        for name, s in sorted(scenarios().items())
    ]


class SimulateIn(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra=_duration_per_scenario)

    scenario: ScenarioName
    seed: int = Field(0, ge=0, le=2**31 - 1, strict=True)  # not `false` as 0
    name: Annotated[str, Field(max_length=200, json_schema_extra=name_schema)] | None = None
    duration_s: float | None = Field(
        None, gt=0, strict=True, description="Simulate only the first S s."
    )
    mismatch: Literal["none", "nominal", "severe"] = Field(
        "nominal",
        description="Plant/estimator model mismatch (docs/fidelity.md); none: perfect model.",
    )


class PreviewChannel(BaseModel):
    unit: str
    values: list[float | None]


class PreviewOut(BaseModel):
    time: list[float | None]
    channels: dict[str, PreviewChannel]


class RunGroupRefOut(BaseModel):
    """The sweep or batch a run belongs to (in ``GET /api/runs`` lists)."""

    id: int
    kind: Literal["sweep", "batch"]
    name: str
    size: int = Field(description="How many runs the group holds now.")


class RunOut(BaseModel):
    id: int
    dataset_id: int
    estimator: str
    name: str
    status: RunStatus
    progress: float
    sample: int
    n_samples: int
    error: str | None
    signals: dict[str, str]
    table: dict[str, Any] | None
    config: dict[str, Any]
    estimator_config: dict[str, Any]
    produces_map: bool
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    metrics: dict[str, float | None]
    rejected: dict[str, int]
    n_versions: int
    base_map_id: int | None
    attempt: int = Field(description="Executions so far; each checks its number on every write.")
    lost_attempts: int = Field(description="Attempts whose worker died (failed after a few).")
    heartbeat_at: datetime | None = Field(description="Last sign of life of the attempt.")
    group_id: int | None = Field(None, description="The sweep or batch the run belongs to.")
    group: RunGroupRefOut | None = Field(
        None, description="That sweep or batch, named (in GET /api/runs lists; else null)."
    )

    @classmethod
    def of(cls, r: Run, group: RunGroupRefOut | None = None) -> RunOut:
        return cls(
            group_id=r.group_id,
            group=group,
            id=r.id,
            dataset_id=r.dataset_id,
            estimator=r.estimator,
            name=r.name,
            status=r.status,  # type: ignore[arg-type]
            progress=r.progress,
            sample=r.sample,
            n_samples=r.n_samples,
            error=r.error,
            signals=r.signals,
            table=r.table,
            config=r.config,
            estimator_config=r.estimator_config,
            produces_map=r.produces_map,
            created_at=r.created_at,
            started_at=r.started_at,
            finished_at=r.finished_at,
            metrics=r.metrics,
            rejected=r.rejected,
            n_versions=r.n_versions,
            base_map_id=r.base_map_id,
            attempt=r.attempt,
            lost_attempts=r.lost_attempts,
            heartbeat_at=r.heartbeat_at,
        )


class VersionSummaryOut(BaseModel):
    id: int = Field(description="The database id (unique over all runs).")
    number: int = Field(
        description="The version's place 1…n in its run by step: what the dashboard's URLs "
        "(?version=N, a=RUN:N), export headers and base-map names call it."
    )
    run_id: int
    step: int
    time_s: float
    label: str | None
    final: bool
    created_at: datetime

    @classmethod
    def of(cls, v: VersionSummary) -> VersionSummaryOut:
        return cls(
            id=v.id,
            number=v.number,
            run_id=v.run_id,
            step=v.step,
            time_s=v.time_s,
            label=v.label,
            final=v.final,
            created_at=v.created_at,
        )


class AxisOut(BaseModel):
    name: str
    unit: str = ""
    breakpoints: list[float]


class VersionOut(VersionSummaryOut):
    axes: list[AxisOut] | None
    values: Nested | None
    variances: Nested | None
    visits: Nested | None
    rejected: dict[str, int]
    cell_rejections: dict[str, Nested] = Field(
        default_factory=dict,
        description="Per cell, by reason (as in rejected): the interpolation weight of the "
        "samples rejected so far, in samples; empty for estimators without a map.",
    )

    @classmethod
    def of_version(cls, v: MapVersion) -> VersionOut:
        s = v.summary
        return cls(
            id=s.id,
            number=s.number,
            run_id=s.run_id,
            step=s.step,
            time_s=s.time_s,
            label=s.label,
            final=s.final,
            created_at=s.created_at,
            axes=None if v.axes is None else [AxisOut(**a) for a in v.axes],
            values=nested_or_none(v.values),
            variances=nested_or_none(v.variances),
            visits=nested_or_none(v.visits),
            rejected=v.rejected,
            cell_rejections={
                k: nested_or_none(x) or [] for k, x in (v.cell_rejections or {}).items()
            },
        )


class LabelIn(BaseModel):
    model_config = ConfigDict(extra="forbid")

    label: Annotated[str, Field(max_length=200, json_schema_extra=name_schema)] | None


class RunRenameIn(BaseModel):
    """Body of ``PATCH /api/runs/{id}``."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(
        min_length=1,
        max_length=200,
        json_schema_extra=name_schema,
        description="The run's new name (not blank).",
    )


class SeriesLine(BaseModel):
    unit: str
    role: SeriesRole | None = Field(
        None,
        description="input, measured, output (an estimate), truth, error or rejected (1 "
        "where a gate or the estimator rejected the sample, 0 where accepted; each bucket's "
        "maximum when decimated); null for a series stored before roles were recorded.",
    )
    values: list[float | None]


class SeriesOut(BaseModel):
    time: list[float | None]
    series: dict[str, SeriesLine]


class CellsOut(BaseModel):
    axes: list[AxisOut] | None
    visits: Nested | None
    rejected: dict[str, Nested]


class CompareItem(RunOut):
    final_version: VersionOut | None


class CompareOut(BaseModel):
    runs: list[CompareItem]


class LineageOut(BaseModel):
    run_id: int | None
    version_id: int | None
    version_number: int | None = Field(
        None,
        description="The version's number 1…n in its run; null for a file or once the version "
        "is deleted.",
    )
    dataset_id: int | None
    estimator: str | None
    config: dict[str, Any] | None
    parent_base_map_id: int | None
    metrics: dict[str, Any]


class BaseMapOut(BaseModel):
    id: int
    name: str
    source: str
    axes: list[AxisOut]
    values: Nested
    lineage: LineageOut
    created_at: datetime

    @classmethod
    def of(cls, b: BaseMap) -> BaseMapOut:
        return cls(
            id=b.id,
            name=b.name,
            source=b.source,
            axes=[AxisOut(**a) for a in b.axes],
            values=nested_or_none(b.values) or [],
            lineage=LineageOut(
                run_id=b.run_id,
                version_id=b.version_id,
                version_number=b.version_number,
                dataset_id=b.dataset_id,
                estimator=b.estimator,
                config=b.config,
                parent_base_map_id=b.parent_base_map_id,
                metrics=b.metrics,
            ),
            created_at=b.created_at,
        )


class PromoteIn(BaseModel):
    model_config = ConfigDict(extra="forbid")

    run_id: int = Field(ge=1, le=2**31 - 1)
    version_id: int = Field(ge=1, le=2**31 - 1)
    name: str | None = Field(
        None,
        min_length=1,
        max_length=200,
        description='Default: "<run name or run R> v<N>", N the version\'s number in its run.',
    )
    # An edited map (the run view's editor): the version's grid with these values instead.
    values: Nested | None = Field(
        None,
        description="The edited grid, nested like the version's values (one level per axis), "
        "finite numbers. Without it the version's own values are saved.",
    )
    edits: list[dict[str, Any]] | None = Field(
        None,
        max_length=2000,
        description="The editing operations that led to `values` (kept as lineage.config.edits), "
        f"at most {MAX_EDITS_BYTES // 1024} KiB as JSON.",
    )

    @field_validator("edits")
    @classmethod
    def _edits_fit(cls, edits: list[dict[str, Any]] | None) -> list[dict[str, Any]] | None:
        """The lineage is stored with the map and sent with every page of base maps: it is
        a record of the edits, not a place for documents."""
        if edits is not None:
            size = len(json.dumps(edits, separators=(",", ":")))
            if size > MAX_EDITS_BYTES:
                raise ValueError(
                    f"the edits take {size:,} bytes as JSON; at most {MAX_EDITS_BYTES:,}"
                )
        return edits

    source: Literal["run", "edit"] | None = Field(
        None, description='"edit" when values or edits are given, else "run".'
    )


class CatalogOut(BaseModel):
    items: list[dict[str, Any]]


class EstimatorSetupOut(BaseModel):
    """One estimator's start on a simulated dataset: what a run request's ``table``,
    ``signals`` and ``config`` get."""

    table: dict[str, Any] | None
    signals: dict[str, str]
    config: dict[str, Any]


class DatasetSetupOut(BaseModel):
    """The scenario's own setup of a simulated dataset (GET /api/datasets/{id}/setup)."""

    scenario: str | None
    seed: int | None
    mismatch: str | None
    suggested: list[str]
    estimators: dict[str, EstimatorSetupOut]


class GroupRunOut(BaseModel):
    """A run of a sweep or batch, in short."""

    id: int
    dataset_id: int
    status: str
    params: dict[str, Any] | None
    metric: float | None = Field(None, description="The sweep's ranking metric.")
    metrics: dict[str, float | None]
    error: str | None


class GroupOut(BaseModel):
    id: int
    kind: Literal["sweep", "batch"]
    name: str
    estimator: str
    metric: str | None
    order: Literal["min", "max"] | None
    created_at: datetime
    request: dict[str, Any]
    counts: dict[str, int] = Field(description="Runs by status.")
    runs: list[GroupRunOut] = Field(description="Sweeps: best first by the metric.")
    best_run_id: int | None = None


class AggregateOut(BaseModel):
    """A batch's merged map: inverse-variance per cell (visit-weighted without variances),
    with each vehicle's standardised deviation z from the other vehicles' merge."""

    axes: list[AxisOut]
    run_ids: list[int]
    values: Nested
    variances: Nested | None
    weights: list[Nested]
    z: list[Nested] | None
    deviating_cells: list[int] | None = Field(description="Cells with |z| > 3, per vehicle.")


class BatchOut(GroupOut):
    aggregate: AggregateOut | None = Field(
        None, description="Present once every run of the batch has succeeded."
    )
