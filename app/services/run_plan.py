"""From a run request to a validated estimator config and the run's service options.

The request (``POST /api/runs``) names a dataset, an estimator, the dataset columns playing
the estimator's signal roles, a table grid and a config. Service-level keys (``pace``,
``version_every``, ``gates``, ``locked``) are taken out of the config first; the rest is
validated against the estimator's own config model, so a table filter gets exactly the
config ``mapwise adapt`` builds for the same flags (axes with the log's units, ``output``,
``output_unit``), and the two give the same map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from app.domain import BaseMap, Dataset
from app.errors import InvalidRequestError, field_of
from app.io.columns import same_unit
from app.io.names import check_name, name_schema
from app.runs.options import run_options, run_raster, streams_input
from app.services.admission import Limits, Prediction, admit_run, check_cells
from app.services.catalog import TABLE_ROLE, EstimatorName, kind_of, needs_table, roles
from estimation.errors import ConfigError, EstimationError
from estimation.registry import EstimatorSpec, registry
from estimation.table import Axis, Grid, broadcast_cells

SERVICE_KEYS = ("pace", "version_every", "gates", "locked", "raster")
MIN_RUN_SAMPLES = 2  # as an upload needs: one sample has no step, no time base


class AxisSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str = Field(min_length=1, description="Dataset column the axis reads.")
    breakpoints: list[float] = Field(min_length=2, description="Strictly increasing.")
    unit: str | None = Field(None, description="Default: the column's unit in the dataset.")


class TableSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")

    axes: list[AxisSpec] = Field(min_length=1)
    values: Any = Field(
        None, description="Starting values: a scalar or nested lists in axis order (θ0)."
    )


class CalibrationLink(BaseModel):
    """The A2L map a run's table adapts (docs/calibration.md#rest-and-cli): its exports can
    then be DCM/CDFX keyed by the A2L name and the ECU's patched memory image."""

    model_config = ConfigDict(extra="forbid")

    ecu_id: int = Field(ge=1, le=2**31 - 1)
    map: str = Field(min_length=1, max_length=1024, description="A MAP or CURVE of the A2L.")


class RunRequest(BaseModel):
    """Body of ``POST /api/runs``."""

    model_config = ConfigDict(extra="forbid")

    dataset_id: int = Field(ge=1, le=2**31 - 1)
    estimator: EstimatorName
    signals: dict[str, str] = Field(
        default_factory=dict, description="Estimator signal role → dataset column."
    )
    table: TableSpec | None = None
    config: dict[str, Any] = Field(default_factory=dict)
    base_map_id: int | None = Field(None, ge=1, le=2**31 - 1)
    name: str | None = Field(None, max_length=200, json_schema_extra=name_schema)
    calibration: CalibrationLink | None = Field(
        None, description="The ECU map the table adapts (GET /api/ecus/{id}/maps/{name}/template)."
    )


@dataclass(frozen=True, slots=True)
class RunPlan:
    estimator: str
    estimator_config: dict[str, Any]
    signals: dict[str, str]
    table_spec: dict[str, Any] | None
    config: dict[str, Any]
    produces_map: bool
    n_samples: int
    name: str
    prediction: Prediction | None = None


def _run_name(name: str | None) -> str:
    """The run's name as given (:func:`check_name`, as a dataset's: 422 naming ``name`` for a
    control or format character), ``""`` for none."""
    if name is None or not name.strip():
        return ""
    return check_name(name, field="name", what="run name")


def _spec(name: str) -> EstimatorSpec:
    specs = registry()
    if name not in specs:
        raise InvalidRequestError(
            f"unknown estimator {name!r}; choose one of {sorted(specs)}", field="estimator"
        )
    return specs[name]


def _check_column(dataset: Dataset, column: str, field: str) -> None:
    if not dataset.has_channel(column):
        names = [c.name for c in dataset.channels]
        raise InvalidRequestError(
            f"column {column!r} is not in dataset {dataset.id}; its channels: {names}",
            field=field,
        )


def _axes(
    table: TableSpec | None, base_map: BaseMap | None, dataset: Dataset
) -> list[dict[str, Any]] | None:
    if table is not None:
        axes = []
        for i, a in enumerate(table.axes):
            _check_column(dataset, a.name, f"table.axes[{i}].name")
            unit = a.unit if a.unit is not None else dataset.unit_of(a.name)
            try:
                Axis(a.name, unit, a.breakpoints)
            except EstimationError as exc:
                raise InvalidRequestError(str(exc), field=f"table.axes[{i}].breakpoints") from exc
            axes.append({"name": a.name, "breakpoints": list(a.breakpoints), "unit": unit})
        names = [a["name"] for a in axes]
        if len(set(names)) != len(names):
            raise InvalidRequestError(f"axis names must be unique, got {names}", field="table.axes")
        if base_map is not None:
            mine = [a["breakpoints"] for a in axes]
            theirs = [a["breakpoints"] for a in base_map.axes]
            if mine != theirs:
                raise InvalidRequestError(
                    f"the table grid does not match base map {base_map.id}'s grid",
                    field="base_map_id",
                )
        return axes
    if base_map is not None:
        for i, a in enumerate(base_map.axes):
            _check_column(dataset, a["name"], f"table.axes[{i}].name")
        return [
            {"name": a["name"], "breakpoints": list(a["breakpoints"]), "unit": a.get("unit", "")}
            for a in base_map.axes
        ]
    return None


def locked_cells(raw: Any, shape: tuple[int, ...]) -> list[list[int]]:
    """Locked cells as index lists from flat indices, a boolean mask or index lists.

    A boolean mask must have exactly the table's shape, and an index list one in-range
    index per axis: anything else is refused rather than read another way.
    """
    field = "config.locked"
    if raw is None or raw == []:
        return []
    if not isinstance(raw, list):
        raise InvalidRequestError("locked must be a list", field=field)
    size = math.prod(shape)
    if all(isinstance(i, int) and not isinstance(i, bool) for i in raw):
        bad = [i for i in raw if not 0 <= i < size]
        if bad:
            raise InvalidRequestError(
                f"flat cell indices {bad} are outside 0..{size - 1}", field=field
            )
        return [list(map(int, np.unravel_index(i, shape))) for i in raw]
    if _has_bool(raw):
        mask_shape = _nested_shape(raw)
        if mask_shape != shape:
            raise InvalidRequestError(
                f"a boolean lock mask must have the table's shape {list(shape)}, got "
                f"{'a ragged mask' if mask_shape is None else list(mask_shape)}",
                field=field,
            )
        arr = np.array(raw, dtype=object)
        if not all(isinstance(v, bool) for v in arr.ravel()):
            raise InvalidRequestError("a lock mask holds only true and false", field=field)
        return [list(map(int, ix)) for ix in np.argwhere(arr.astype(bool))]
    if all(isinstance(c, list) and all(isinstance(i, int) for i in c) for c in raw):
        for k, cell in enumerate(raw):
            if len(cell) != len(shape) or not all(
                0 <= i < n for i, n in zip(cell, shape, strict=True)
            ):
                raise InvalidRequestError(
                    f"cell {cell} is not inside a table of shape {list(shape)}",
                    field=f"{field}[{k}]",
                )
        return [list(c) for c in raw]
    raise InvalidRequestError(
        f"locked must be flat cell indices, index lists, or a boolean mask of shape {shape}",
        field=field,
    )


def _has_bool(value: Any) -> bool:
    if isinstance(value, list):
        return any(_has_bool(v) for v in value)
    return isinstance(value, bool)


def _nested_shape(value: Any) -> tuple[int, ...] | None:
    """The shape of regular nested lists (``()`` for a scalar), ``None`` if ragged."""
    if not isinstance(value, list):
        return ()
    shapes = {_nested_shape(v) for v in value}
    if len(shapes) > 1 or None in shapes:
        return None
    inner = shapes.pop() if shapes else ()
    return (len(value), *inner)


def plan_run(
    request: RunRequest,
    dataset: Dataset,
    base_map: BaseMap | None,
    *,
    version_fraction: float,
    limits: Limits | None = None,
) -> RunPlan:
    """Validate a run request against its dataset; raise 422 errors naming the field.

    With ``limits``, the run is also admitted (:mod:`app.services.admission`): its table's
    cells are capped before anything of the table's size is built, and its predicted
    memory, stored versions and duration checked before the estimator is.
    """
    spec = _spec(request.estimator)
    kind = kind_of(spec)
    config = dict(request.config)
    estimator_config = {k: v for k, v in config.items() if k not in SERVICE_KEYS}
    role_map = {r.role: r for r in roles(spec)}
    for role, column in request.signals.items():
        if role not in role_map:
            raise InvalidRequestError(
                f"{spec.name} has no signal role {role!r}; its roles: {sorted(role_map)}",
                field=f"signals.{role}",
            )
        _check_column(dataset, column, f"signals.{role}")
    axes = _axes(request.table, base_map, dataset) if needs_table(spec) else None
    if request.table is not None and not needs_table(spec):
        raise InvalidRequestError(f"{spec.name} has no table", field="table")
    rows, rate_hz = _rows(dataset, _channels_named(request, axes, config), config)
    options = run_options(config, rows, rate_hz, version_fraction)
    if axes is not None and limits is not None:
        cells = math.prod(len(a["breakpoints"]) for a in axes)
        check_cells(cells, limits, field="table.axes", spec=spec)
    if kind == "table-filter":
        if axes is None:
            raise InvalidRequestError(f"{spec.name} needs a table grid", field="table")
        output = request.signals.get(TABLE_ROLE)
        if output is None:
            raise InvalidRequestError(
                f"{spec.name} needs the measured output column as signals.y", field="signals.y"
            )
        estimator_config |= {
            "axes": axes,
            "output": output,
            "output_unit": dataset.unit_of(output),
        }
        start = _start_values(request.table, base_map, axes)
        if start is not None and "theta0" not in estimator_config:
            estimator_config["theta0"] = start
        if "locked" in config:
            shape = tuple(len(a["breakpoints"]) for a in axes)
            estimator_config["locked"] = locked_cells(config["locked"], shape)
    else:
        if "locked" in config:
            raise InvalidRequestError(
                f"locked cells apply to the table filters, not {spec.name}", field="config.locked"
            )
        if base_map is not None or (request.table is not None and request.table.values is not None):
            raise InvalidRequestError(
                f"{spec.name} does not start from a given map", field="base_map_id"
            )
        if axes is not None:
            estimator_config["axes"] = axes
        for role, column in request.signals.items():
            _set_dotted(estimator_config, role, column)
        if kind == "torque" and options.gates:
            raise InvalidRequestError(
                f"{spec.name} integrates every sample; sample gates do not apply",
                field="config.gates",
            )
    if options.gates:
        from app.runs.gates import parse_gates

        parse_gates(options.gates, [c.name for c in dataset.channels], field="config.gates")
    model = _validate_config(spec, estimator_config)
    _check_delay(model, dataset, rows)

    def admitted(streamed: bool) -> Prediction | None:
        if limits is None:
            return None
        cells, corners = spec.cost.size(model)
        return admit_run(
            spec,
            cells=cells,
            corners=corners,
            samples=rows,
            channels=len(dataset.channels),
            version_every=options.version_every,
            log_duration_s=dataset.duration_s,
            pace=options.pace,
            limits=limits,
            table_field="table.axes" if axes is not None else "config",
            streamed=streamed,
            gates=len(options.gates),
            raster=dataset.recorded,
            samples_field="config.raster" if run_raster(config) is not None else "dataset_id",
        )

    # Refused before the estimator is built (a huge table allocates); predicted as its spec
    # streams, and again whole if the built estimator turns out not to plan windows.
    spec_streams = streams_input(spec, dataset)
    prediction = admitted(spec_streams)
    try:
        estimator = spec.build(model)
    except EstimationError as exc:
        raise InvalidRequestError(" ".join(str(exc).split()), field="config") from exc
    if spec_streams and not streams_input(spec, dataset, estimator):
        prediction = admitted(False)
    _check_required(estimator.required_signals(), dataset, request, spec)
    _check_units(spec, dataset, request)
    return RunPlan(
        estimator=spec.name,
        estimator_config=model.model_dump(mode="json"),
        signals=dict(request.signals),
        table_spec=None if axes is None else {"axes": axes},
        config=config,
        produces_map=spec.produces_map,
        n_samples=rows,
        name=_run_name(request.name) or f"{spec.name} on {dataset.name}",
        prediction=prediction,
    )


def _channels_named(
    request: RunRequest, axes: list[dict[str, Any]] | None, config: dict[str, Any]
) -> list[str]:
    """The channels a run's request names (its table's axes, its signals, its gates'): on a
    dataset stored as recorded they set the run's raster (:meth:`Dataset.rows_for`; the
    worker reads them with the estimator's own, :func:`app.runs.results.channels_read`)."""
    names = [a["name"] for a in axes or []] + list(request.signals.values())
    gates = config.get("gates")
    if isinstance(gates, list):
        names += [g["channel"] for g in gates if isinstance(g, dict) and "channel" in g]
    return [n for n in names if isinstance(n, str)]


def _rows(dataset: Dataset, names: list[str], config: dict[str, Any]) -> tuple[int, float]:
    """The rows and rate of the run's read (:meth:`Dataset.rows_for`), on the raster its
    ``config.raster`` asks for (:func:`run_raster`; only on a dataset stored as recorded,
    whose channel a channel raster must be) or the slowest among its channels."""
    raster = run_raster(config)
    if raster is None:
        return dataset.rows_for(names)
    if not dataset.recorded:
        raise InvalidRequestError(
            f"dataset {dataset.id} is stored on one time base (uploaded with a raster, or "
            "its channels share their timestamps): a run's raster applies only to a dataset "
            "stored as recorded; give the raster at upload",
            field="config.raster",
        )
    if raster.channel is None:
        rows, rate_hz = dataset.rows_for(names, raster.step)
    else:
        timing = dataset.timing_of(raster.channel)
        if timing is None:
            raise InvalidRequestError(
                f"raster channel {raster.channel!r} is not in dataset {dataset.id}",
                field="config.raster",
            )
        rows, rate_hz = dataset.rows_for([*names, raster.channel], timing[2])
    if rows < MIN_RUN_SAMPLES:  # the rule of an upload's samples, for a run's raster
        raise InvalidRequestError(
            f"the raster gives {rows} sample{'s' if rows != 1 else ''} over the log; a run "
            f"needs at least {MIN_RUN_SAMPLES}: choose a finer raster",
            field="config.raster",
        )
    return rows, rate_hz


def _check_delay(model: BaseModel, dataset: Dataset, rows: int) -> None:
    """A sensor delay must be shorter than the log (else no sample has a measurement)."""
    sensor = getattr(model, "sensor", None)
    if sensor is None:
        return
    if sensor.delay_samples is not None:
        if sensor.delay_samples >= rows:
            raise InvalidRequestError(
                f"a delay of {sensor.delay_samples:,} samples is not shorter than the log "
                f"({rows:,} samples)",
                field="config.sensor.delay_samples",
            )
    elif sensor.delay_s and sensor.delay_s >= dataset.duration_s:
        raise InvalidRequestError(
            f"a delay of {sensor.delay_s:g} s is not shorter than the log "
            f"({dataset.duration_s:g} s)",
            field="config.sensor.delay_s",
        )


def _start_values(
    table: TableSpec | None, base_map: BaseMap | None, axes: list[dict[str, Any]]
) -> Any:
    shape = tuple(len(a["breakpoints"]) for a in axes)
    if table is not None and table.values is not None:
        try:
            return broadcast_cells(table.values, shape, what="table.values").tolist()
        except EstimationError as exc:
            raise InvalidRequestError(str(exc), field="table.values") from exc
    if base_map is not None:
        return np.asarray(base_map.values, dtype=np.float64).reshape(shape).tolist()
    return None


def _set_dotted(config: dict[str, Any], key: str, value: str) -> None:
    node = config
    parts = key.split(".")
    for part in parts[:-1]:
        node = node.setdefault(part, {})
    node[parts[-1]] = value


_FIELD_OF_KEY = {"axes": "table.axes", "output": "signals.y", "output_unit": "signals.y"}


def _validate_config(spec: EstimatorSpec, config: dict[str, Any]) -> BaseModel:
    try:
        return spec.config_model.model_validate(config)
    except ValidationError as exc:
        first = exc.errors()[0]
        loc = tuple(first["loc"])
        head = str(loc[0]) if loc else ""
        if head in _FIELD_OF_KEY:
            rest = field_of(loc[1:]) or ""
            field = _FIELD_OF_KEY[head] + (rest if rest.startswith("[") or not rest else f".{rest}")
        else:
            field = f"config.{field_of(loc)}" if loc else "config"
        messages = "; ".join(
            f"{field_of(e['loc']) or 'config'}: {e['msg'].removeprefix('Value error, ')}"
            for e in exc.errors()
        )
        raise InvalidRequestError(f"{spec.name}: {messages}", field=field) from exc
    except ConfigError as exc:
        raise InvalidRequestError(str(exc), field="config") from exc


def _check_required(
    required: list[str], dataset: Dataset, request: RunRequest, spec: EstimatorSpec
) -> None:
    missing = [c for c in required if not dataset.has_channel(c)]
    if not missing:
        return
    by_column = {column: role for role, column in request.signals.items()}
    defaults = {r.default: r.role for r in roles(spec) if r.default}
    column = missing[0]
    role = by_column.get(column) or defaults.get(column)
    raise InvalidRequestError(
        f"{spec.name} needs channel{'s' if len(missing) > 1 else ''} "
        f"{', '.join(repr(c) for c in missing)}, not in dataset {dataset.id}; map "
        f"{'signals.' + role if role else 'the roles'} to one of "
        f"{[c.name for c in dataset.channels]}",
        field=f"signals.{role}" if role else "signals",
    )


def _check_units(spec: EstimatorSpec, dataset: Dataset, request: RunRequest) -> None:
    """A column feeding a role must carry the role's unit where both are known: a pressure
    logged in kPa for a role in Pa would otherwise be read 1000× too small."""
    for role in roles(spec):
        column = request.signals.get(role.role, role.default)
        if not role.unit or column is None or not dataset.has_channel(column):
            continue
        unit = dataset.unit_of(column)
        if unit and not same_unit(unit, role.unit):
            raise InvalidRequestError(
                f"column {column!r} is in {unit!r} but {spec.name}'s {role.role} is in "
                f"{role.unit!r}; convert the column or map another one",
                field=f"signals.{role.role}",
            )


def grid_shape(table_spec: dict[str, Any] | None) -> tuple[int, ...] | None:
    if table_spec is None:
        return None
    return Grid([Axis.from_dict(a) for a in table_spec["axes"]]).shape
