"""The estimator and scenario catalogs as the API shows them.

An estimator's *signal roles* are the channels a run maps dataset columns to: ``y`` (the
measured table output) for the table filters; for the observers, every config field that
names a channel (a string field with a channel-name default, e.g. ``speed_channel`` or
``p_im``; nested sections as ``channels.p_im``). The config schema shown to the UI leaves
out what the run request supplies separately (axes, channels, output), and gives every
property a ``source``: the paper value its default is, or "mapwise default"
(:mod:`estimation.default_sources`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Annotated, Any, Literal

from pydantic import BaseModel, Field

from estimation.default_sources import annotate
from estimation.registry import EstimatorKind, EstimatorSpec, registry
from estimation.scenarios import scenarios

Kind = Literal["table-filter", "maf-observer", "torque"]
TABLE_ROLE = "y"
_UNIT = re.compile(r"\[([^\]]+)\]")
# Config keys the run request's table and signals fill in for a table filter.
TABLE_FILTER_KEYS = ("axes", "output", "output_unit")


def _estimator_enum(schema: dict[str, Any]) -> None:
    # Called when the JSON schema is generated (not at import): the registry imports every
    # estimator module.
    schema["enum"] = list(registry())


def _scenario_enum(schema: dict[str, Any]) -> None:
    schema["enum"] = sorted(scenarios())


# A request's estimator or scenario: any string validates here (the service refuses an
# unknown name with a 422 listing the known ones), and the schema lists the names as an
# enum, so that OpenAPI clients and fuzzers offer only names that exist.
EstimatorName = Annotated[str, Field(min_length=1, json_schema_extra=_estimator_enum)]
ScenarioName = Annotated[str, Field(min_length=1, json_schema_extra=_scenario_enum)]


@dataclass(frozen=True, slots=True)
class Role:
    """A signal role: the config key it fills (dotted for nested sections)."""

    role: str
    description: str
    unit: str
    required: bool
    default: str | None


def kind_of(spec: EstimatorSpec) -> Kind:
    if spec.kind == EstimatorKind.MAP_FILTER:
        return "table-filter"
    if spec.kind == EstimatorKind.TORQUE:
        return "torque"
    return "maf-observer"


def needs_table(spec: EstimatorSpec) -> bool:
    return "axes" in spec.config_model.model_fields


def roles(spec: EstimatorSpec) -> list[Role]:
    if kind_of(spec) == "table-filter":
        return [Role(TABLE_ROLE, "The measured table output.", "", True, None)]
    return _channel_roles(spec.config_model, "")


def _channel_roles(model: type[BaseModel], prefix: str) -> list[Role]:
    out: list[Role] = []
    for name, info in model.model_fields.items():
        annotation = info.annotation
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            out += _channel_roles(annotation, f"{prefix}{name}.")
            continue
        default = info.default
        if not isinstance(default, str) or annotation not in (str, str | None):
            continue
        description = info.description or ""
        unit = _UNIT.search(description)
        out.append(
            Role(
                role=f"{prefix}{name}",
                description=description,
                unit=unit[1] if unit else "",
                required=annotation is str,
                default=default,
            )
        )
    return out


def role_keys(spec: EstimatorSpec) -> set[str]:
    """Config keys (top level) that the run's ``signals`` fill in."""
    if kind_of(spec) == "table-filter":
        return set(TABLE_FILTER_KEYS)
    return {r.role.split(".")[0] for r in roles(spec)} | ({"axes"} if needs_table(spec) else set())


def config_schema(spec: EstimatorSpec) -> tuple[dict[str, Any], dict[str, Any]]:
    """The config JSON schema (each property with its default's ``source``) and defaults,
    without the keys a run request fills in."""
    schema = annotate(spec.config_model.model_json_schema(), spec.config_model)
    hidden = role_keys(spec)
    props = {k: v for k, v in schema.get("properties", {}).items() if k not in hidden}
    schema = {**schema, "properties": props}
    if "required" in schema:
        schema["required"] = [k for k in schema["required"] if k not in hidden]
    defaults: dict[str, Any] = {}
    for name, info in spec.config_model.model_fields.items():
        if name in hidden or info.is_required():
            continue
        value = info.get_default(call_default_factory=True)
        defaults[name] = value.model_dump(mode="json") if isinstance(value, BaseModel) else value
    return schema, _jsonable(defaults)


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json")
    return value


def estimator_entry(spec: EstimatorSpec) -> dict[str, Any]:
    schema, defaults = config_schema(spec)
    return {
        "name": spec.name,
        "title": spec.title,
        "description": spec.description,
        "paper": spec.paper,
        "produces_map": spec.produces_map,
        "kind": kind_of(spec),
        "signals": [
            {
                "role": r.role,
                "description": r.description,
                "unit": r.unit,
                "required": r.required,
                "default": r.default,
            }
            for r in roles(spec)
        ],
        "needs_table": needs_table(spec),
        "config_schema": schema,
        "defaults": defaults,
    }


def estimators() -> list[dict[str, Any]]:
    return [estimator_entry(spec) for spec in registry().values()]


def scenario_entries() -> list[dict[str, Any]]:
    out = []
    for s in scenarios().values():
        entry = s.catalog_entry()
        out.append(
            {
                "name": s.name,
                "title": s.name,
                "description": s.description,
                "estimators": entry["suggested_estimators"],
                "duration_s": s.duration_s,
                "rate_hz": s.rate_hz,
                "channels": entry["channels"],
            }
        )
    return out
