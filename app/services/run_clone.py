"""The request that made a stored run, for ``POST /api/runs/{id}/clone``.

A clone is a new run through the same path as ``POST /api/runs`` (:meth:`RunService.create`):
the stored run is turned back into a :class:`RunRequest` (dataset, estimator, signals, table
grid, starting values or base map, A2L link, config), the caller's overrides applied, and the
request planned and validated exactly as a new one would be.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from app.domain import Run
from app.errors import InvalidRequestError, field_of
from app.io.names import name_schema
from app.services.catalog import kind_of
from app.services.overrides import merge
from app.services.run_plan import RunRequest
from estimation.registry import registry

MAX_NAME = 200
COPY_SUFFIX = " (copy)"


class CloneRequest(BaseModel):
    """Body of ``POST /api/runs/{id}/clone`` (optional): what the copy changes."""

    model_config = ConfigDict(extra="forbid")

    name: str | None = Field(
        None,
        max_length=MAX_NAME,
        json_schema_extra=name_schema,
        description='Default: the run\'s name + " (copy)".',
    )
    config: dict[str, Any] | None = Field(
        None,
        description="Merged into the run's config: a dict merges into the section of the same "
        "key, any other value replaces it, null removes the key.",
    )


def copy_name(name: str) -> str:
    """``"<name> (copy)"``, the name shortened so the whole fits ``MAX_NAME`` characters."""
    return name[: MAX_NAME - len(COPY_SUFFIX)] + COPY_SUFFIX


def request_of(run: Run, overrides: CloneRequest | None = None) -> RunRequest:
    """The request that reproduces ``run``, with ``overrides``; 422 naming the field when the
    overrides make it invalid (the planner checks the rest, as for a new run)."""
    overrides = overrides or CloneRequest()
    table_spec = dict(run.table or {})
    config = dict(run.config)
    if overrides.config is not None:
        config = merge(config, overrides.config)
    table: dict[str, Any] | None = None
    if table_spec.get("axes"):
        table = {
            "axes": [
                {"name": a["name"], "breakpoints": list(a["breakpoints"]), "unit": a.get("unit")}
                for a in table_spec["axes"]
            ]
        }
        spec = registry().get(run.estimator)
        # A table filter's starting map: its base map when that still exists, else the
        # values it started from, stored as a grid in theta0 (a scalar theta0 is the
        # config's own, default or given, and comes back with the config).
        if (
            spec is not None
            and kind_of(spec) == "table-filter"
            and run.base_map_id is None
            and "theta0" not in config
            and isinstance(run.estimator_config.get("theta0"), list)
        ):
            table["values"] = run.estimator_config["theta0"]
    fields: dict[str, Any] = {
        "dataset_id": run.dataset_id,
        "estimator": run.estimator,
        "signals": dict(run.signals),
        "table": table,
        "config": config,
        "base_map_id": run.base_map_id,
        "name": overrides.name if overrides.name is not None else copy_name(run.name),
        "calibration": table_spec.get("calibration"),
    }
    try:
        return RunRequest.model_validate(fields)
    except ValidationError as exc:
        first = exc.errors()[0]
        raise InvalidRequestError(
            f"the copy of run {run.id} is not a valid run: {first['msg']}",
            field=field_of(tuple(first["loc"])) or None,
        ) from exc
