"""Sweeps and fleet batches: many runs as one group.

* A **sweep** runs one dataset through one estimator at many settings — a grid (the product of
  value lists) or a seeded random sample (values drawn from lists, or uniformly / log-uniformly
  from ranges) — and ranks the runs by a metric (``output_rmse``, ``map_rmse``, ``ise`` …).
* A **batch** runs many datasets (a fleet's logs) through one config; its aggregate map is the
  cell-wise inverse-variance merge of the vehicles' maps, with each vehicle's standardised
  deviation from the others (:func:`estimation.merge.merge_maps`).

Every run of a group is planned (validated) in one transaction before any is stored, so a bad
parameter value stores nothing and names ``parameters.<name>``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from app.db.engine import Database
from app.db.repositories import GroupRepo, RunRepo, VersionRepo
from app.domain import Page, Run, RunGroup, RunStatus
from app.errors import AppError, InvalidRequestError
from app.io.names import check_name, name_schema
from app.services.admission import GroupBudget, Limits, OverBudgetError
from app.services.catalog import EstimatorName
from app.services.overrides import merge
from app.services.run_plan import RunRequest, TableSpec
from app.services.runs import RunService
from estimation.errors import EstimationError
from estimation.merge import merge_maps

MAX_GROUP_RUNS = 2000


class Range(BaseModel):
    """Values drawn uniformly (or log-uniformly) from ``[min, max]``."""

    model_config = ConfigDict(extra="forbid")

    min: float = Field(allow_inf_nan=False)
    max: float = Field(allow_inf_nan=False)
    scale: Literal["linear", "log"] = "linear"
    integer: bool = False


Values = list[Any] | Range


class SweepRequest(BaseModel):
    """Body of ``POST /api/sweeps``: a run request plus the parameters to vary."""

    model_config = ConfigDict(extra="forbid")

    dataset_id: int = Field(ge=1, le=2**31 - 1)
    estimator: EstimatorName
    signals: dict[str, str] = Field(default_factory=dict)
    table: TableSpec | None = None
    config: dict[str, Any] = Field(default_factory=dict, description="Fixed settings.")
    parameters: dict[str, Values] = Field(
        min_length=1,
        description='Config key (dotted for sections, e.g. "sensor.lag") → a list of values '
        '(grid) or {"min", "max", "scale": "linear"|"log", "integer"} (random).',
    )
    samples: int | None = Field(
        None, ge=1, le=MAX_GROUP_RUNS, description="Random sample size; omitted: the full grid."
    )
    seed: int = Field(0, ge=0, le=2**31 - 1, description="Seed of the random sample.")
    metric: str = Field("output_rmse", min_length=1, max_length=100)
    order: Literal["min", "max"] = "min"
    name: str | None = Field(None, max_length=200, json_schema_extra=name_schema)


class BatchRequest(BaseModel):
    """Body of ``POST /api/batches``: one config over many datasets (a fleet's logs)."""

    model_config = ConfigDict(extra="forbid")

    dataset_ids: list[Annotated[int, Field(ge=1, le=2**31 - 1)]] = Field(
        min_length=1, max_length=MAX_GROUP_RUNS
    )
    estimator: EstimatorName
    signals: dict[str, str] = Field(default_factory=dict)
    table: TableSpec | None = None
    config: dict[str, Any] = Field(default_factory=dict)
    name: str | None = Field(None, max_length=200, json_schema_extra=name_schema)


# The scalar metrics a run records (:func:`estimation.metrics.score_run` and the run's
# results: known-truth, output, torque and bookkeeping figures) and the prefixes of its
# families (held-out prediction, NIS, residual whiteness); a sweep ranks by one of them.
RANK_METRICS = frozenset(
    {
        "output_rmse", "rmse", "map_rmse", "max_abs_error", "mean_relative_error",
        "coverage", "visited_cells", "ise", "mae", "sd", "accepted", "samples", "run_s",
    }
)  # fmt: skip
RANK_METRIC_FAMILIES = ("holdout:", "nis:", "residual:")


def check_metric(metric: str) -> str:
    """``metric`` if a run can record it, else a 422 on ``metric`` naming those it can."""
    if metric in RANK_METRICS or metric.startswith(RANK_METRIC_FAMILIES):
        return metric
    known = ", ".join(sorted(RANK_METRICS))
    families = ", ".join(f"{f}…" for f in RANK_METRIC_FAMILIES)
    raise InvalidRequestError(
        f"no run records a metric {metric!r}; rank by one of {known} or {families}",
        field="metric",
    )


def check_parameter_keys(parameters: dict[str, Values]) -> None:
    """Each key a dotted config path with no empty part, none inside another's section
    (``sensor`` and ``sensor.lag`` would each set ``sensor.lag``): else a 422 naming it."""
    paths = {key: tuple(key.split(".")) for key in parameters}
    for key, path in paths.items():
        if not all(part.strip() for part in path):
            raise InvalidRequestError(
                f"{key!r} is not a config key: a dotted key has no empty part",
                field=f"parameters.{key}",
            )
        for other, other_path in paths.items():
            if other != key and other_path[: len(path)] == path:
                raise InvalidRequestError(
                    f"{key!r} and {other!r} both set {other!r}: vary the section or its key",
                    field=f"parameters.{key}",
                )


def expand_parameters(
    parameters: dict[str, Values], *, samples: int | None, seed: int
) -> list[dict[str, Any]]:
    """The parameter sets of a sweep: the grid (``samples`` None) or a seeded sample."""
    check_parameter_keys(parameters)
    if samples is None:
        ranges = [k for k, v in parameters.items() if isinstance(v, Range)]
        if ranges:
            raise InvalidRequestError(
                f"{ranges[0]!r} is a range: give 'samples' for a random sweep, or a list",
                field=f"parameters.{ranges[0]}",
            )
        for key, values in parameters.items():
            if not values:
                raise InvalidRequestError("give at least one value", field=f"parameters.{key}")
        keys = list(parameters)
        grid = itertools.product(*(parameters[k] for k in keys))  # type: ignore[misc]
        count = math.prod(len(parameters[k]) for k in keys)  # type: ignore[arg-type]
        if count > MAX_GROUP_RUNS:
            raise InvalidRequestError(
                f"the grid has {count} points; at most {MAX_GROUP_RUNS} runs per sweep",
                field="parameters",
            )
        return [dict(zip(keys, point, strict=True)) for point in grid]
    rng = np.random.default_rng(seed)
    columns = {key: _draw(key, spec, rng, samples) for key, spec in parameters.items()}
    return [{key: column[i] for key, column in columns.items()} for i in range(samples)]


def _draw(key: str, spec: Values, rng: np.random.Generator, n: int) -> list[Any]:
    if isinstance(spec, list):
        if not spec:
            raise InvalidRequestError("give at least one value", field=f"parameters.{key}")
        return [spec[i] for i in rng.integers(0, len(spec), n)]
    if spec.min > spec.max:
        raise InvalidRequestError(
            f"min {spec.min:g} is above max {spec.max:g}", field=f"parameters.{key}"
        )
    if spec.scale == "log":
        if spec.min <= 0:
            raise InvalidRequestError("a log range needs min > 0", field=f"parameters.{key}.min")
        values = np.exp(rng.uniform(math.log(spec.min), math.log(spec.max), n))
    else:
        values = rng.uniform(spec.min, spec.max, n)
    if spec.integer:
        return [round(float(v)) for v in values]
    return [float(v) for v in values]


def _dotted(params: dict[str, Any]) -> dict[str, Any]:
    """``{"sensor.lag": 0.9}`` → ``{"sensor": {"lag": 0.9}}``."""
    out: dict[str, Any] = {}
    for key, value in params.items():
        node = out
        *head, last = key.split(".")
        for part in head:
            node = node.setdefault(part, {})
        node[last] = value
    return out


def _group_name(name: str | None) -> str:
    """The group's name as given (:func:`check_name`: 422 naming ``name`` for a control or
    format character), ``""`` for none."""
    if name is None or not name.strip():
        return ""
    return check_name(name, field="name", what="group name")


@dataclass(frozen=True, slots=True)
class GroupView:
    group: RunGroup
    runs: list[Run]


class SweepService:
    def __init__(self, db: Database, runs: RunService) -> None:
        self.db = db
        self.runs = runs

    def _budget(self, what: str, field: str) -> GroupBudget:
        return GroupBudget(Limits.from_settings(self.runs.settings), what=what, field=field)

    def create_sweep(self, request: SweepRequest) -> GroupView:
        self.runs.need_executor()
        name = _group_name(request.name)
        check_metric(request.metric)
        points = expand_parameters(request.parameters, samples=request.samples, seed=request.seed)
        base = request.model_dump(mode="json", include={"dataset_id", "estimator", "signals"})
        table = None if request.table is None else request.table.model_dump(mode="json")
        with self.db.write() as s:
            group = GroupRepo(s).add(
                kind="sweep",
                name=(name or f"{request.estimator} sweep of {', '.join(request.parameters)}")[
                    :200
                ],
                estimator=request.estimator,
                request=request.model_dump(mode="json"),
                metric=request.metric,
                order=request.order,
            )
            runs = []
            budget = self._budget("sweep", "samples" if request.samples else "parameters")
            for i, params in enumerate(points):
                label = ", ".join(f"{k}={_short(v)}" for k, v in params.items())
                run_request = RunRequest(
                    **base,
                    table=table,
                    config=merge(request.config, _dotted(params)),
                    name=f"{group.name} #{i + 1}: {label}"[:200],
                )
                runs.append(
                    self._store(s, run_request, group.id, params, parameters=True, budget=budget)
                )
            budget.check()  # the transaction stores nothing of a refused sweep
        for run in runs:
            self.runs.submit(run.id)
        return GroupView(group, runs)

    def create_batch(self, request: BatchRequest) -> GroupView:
        self.runs.need_executor()
        name = _group_name(request.name)
        table = None if request.table is None else request.table.model_dump(mode="json")
        with self.db.write() as s:
            group = GroupRepo(s).add(
                kind="batch",
                name=name or f"{request.estimator} over {len(request.dataset_ids)} logs",
                estimator=request.estimator,
                request=request.model_dump(mode="json"),
            )
            runs = []
            budget = self._budget("batch", "dataset_ids")
            for i, dataset_id in enumerate(request.dataset_ids):
                run_request = RunRequest(
                    dataset_id=dataset_id,
                    estimator=request.estimator,
                    signals=request.signals,
                    table=table,
                    config=request.config,
                    name=f"{group.name}: vehicle {i + 1} (dataset {dataset_id})"[:200],
                )
                runs.append(self._store(s, run_request, group.id, None, index=i, budget=budget))
            budget.check()
        for run in runs:
            self.runs.submit(run.id)
        return GroupView(group, runs)

    def _store(
        self,
        s: Any,
        request: RunRequest,
        group_id: int,
        params: dict[str, Any] | None,
        *,
        parameters: bool = False,
        index: int | None = None,
        budget: GroupBudget | None = None,
    ) -> Run:
        """Plan and store one run of a group; its errors name the parameter or dataset."""
        try:
            return self.runs.store_in(s, request, group_id=group_id, params=params, budget=budget)
        except (AppError, EstimationError) as exc:
            message = getattr(exc, "message", str(exc))
            # an over-budget member keeps its code (over_budget), any other a validation error
            error = type(exc) if isinstance(exc, InvalidRequestError) else InvalidRequestError
            if parameters and params:
                values = ", ".join(f"{k}={v!r}" for k, v in params.items())
                field = getattr(exc, "field", None)
                if not (isinstance(exc, OverBudgetError) and field and "config." not in field):
                    field = _parameter_field(field, message, params)
                raise error(f"with {values}: {message}", field=field) from exc
            if index is not None:
                raise error(
                    f"dataset {request.dataset_id}: {message}", field=f"dataset_ids[{index}]"
                ) from exc
            raise

    def get(self, group_id: int, kind: str) -> GroupView:
        with self.db.read() as s:
            group = GroupRepo(s).get(group_id, kind)
            return GroupView(group, RunRepo(s).in_group(group_id))

    def list(self, kind: str, *, limit: int, offset: int) -> Page[RunGroup]:
        with self.db.read() as s:
            return GroupRepo(s).list(kind, limit=limit, offset=offset)

    def aggregate(self, group_id: int) -> dict[str, Any] | None:
        """The batch's merged map once every run succeeded (None before, or without maps)."""
        with self.db.read() as s:
            GroupRepo(s).get(group_id, "batch")
            runs = RunRepo(s).in_group(group_id)
            if not runs or any(r.status != RunStatus.SUCCEEDED or not r.produces_map for r in runs):
                return None
            versions = [VersionRepo(s).latest(r.id) for r in runs]
        if any(v is None or v.values is None for v in versions):
            return None
        found = [v for v in versions if v is not None]
        values = np.stack([np.asarray(v.values) for v in found])
        variances = None
        if all(v.variances is not None for v in found):
            variances = np.stack([np.asarray(v.variances) for v in found])
        ones = np.ones_like(values[0])
        visits = np.stack([ones if v.visits is None else np.asarray(v.visits) for v in found])
        merged = merge_maps(values, variances, visits=visits)
        return {
            "axes": found[0].axes,
            "run_ids": [r.id for r in runs],
            "values": merged.values,
            "variances": merged.variances,
            "weights": merged.weights,
            "z": merged.z,
            "deviating_cells": (
                [int(np.count_nonzero(np.abs(z) > 3.0)) for z in merged.z]
                if merged.z is not None
                else None
            ),
        }


def rank(group: RunGroup, runs: list[Run]) -> list[Run]:
    """Runs by the sweep's metric (best first); runs without the metric last, by id."""
    metric = group.metric or ""
    sign = -1.0 if group.order == "max" else 1.0

    def key(run: Run) -> tuple[int, float, int]:
        value = run.metrics.get(metric)
        if value is None or not math.isfinite(value):
            return (1, 0.0, run.id)
        return (0, sign * value, run.id)

    return sorted(runs, key=key)


def _parameter_field(field: str | None, message: str, params: dict[str, Any]) -> str:
    """The swept parameter an error is about: by its field (``config.sigma_w``), else by
    its name in the message, else the only parameter; otherwise the error's own field."""
    if field and field.startswith("config."):
        key = field.removeprefix("config.")
        for name in params:
            if key == name or key.startswith(name + ".") or name.startswith(key + "."):
                return f"parameters.{name}"
    named = [name for name in params if name.split(".")[-1] in message]
    if len(named) == 1:
        return f"parameters.{named[0]}"
    if len(params) == 1:
        return f"parameters.{next(iter(params))}"
    return field or "parameters"


def _short(value: Any) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)
