"""The registry of estimators: one :class:`EstimatorSpec` per name, the home of the contract.

A spec says what an estimator is (title, description, paper, :class:`EstimatorKind`), how
to build it (a pydantic config model and a factory), what its state is (``state_class``)
and the unit of every per-sample series it yields (``output_units``). Everything that lists
estimators — the CLI choices, the catalog, the scenarios, the state loader — derives from
:func:`registry`; adding an estimator is one line in :data:`BUILTIN`
(``docs/adding-an-estimator.md``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import StrEnum
from functools import cache
from types import MappingProxyType
from typing import Any

from pydantic import BaseModel, ValidationError

from estimation.errors import ConfigError, StateError
from estimation.estimator import Estimator, describe_validation_error
from estimation.state import EstimatorState, state_class


class EstimatorKind(StrEnum):
    """What an estimator estimates, and so how a run of it is scored and shown."""

    MAP_FILTER = "map_filter"  # a look-up table over log channels, from its measured output
    MAP_OBSERVER = "map_observer"  # a sensor-error map, from an observer of the plant
    JOINT_EKF = "joint_ekf"  # plant states and (optionally) a map, jointly
    TORQUE = "torque"  # an unmeasured input (engine torque), no map


ROLES = ("axis", "output", "input")
"""Signal roles: table axes (operating point), measured outputs fed back, other inputs."""


@dataclass(frozen=True, slots=True)
class EstimatorSpec:
    """A registered estimator: its name, what it is, where it comes from, how to build it.

    ``output_units`` gives the unit of each per-sample series in ``Snapshot.outputs`` by
    name; ``""`` means "the unit of the config's output channel" (``prediction`` and
    ``residual`` of the map filters) or, for an estimator without one, no unit.
    """

    name: str
    title: str
    description: str
    paper: str
    kind: EstimatorKind
    config_model: type[BaseModel]
    factory: Callable[[BaseModel], Estimator]
    state_class: type[EstimatorState]
    output_units: Mapping[str, str]
    produces_map: bool = True

    def config(self, config: BaseModel | dict[str, Any]) -> BaseModel:
        """``config`` validated against the estimator's model (a :class:`ConfigError` if not)."""
        if isinstance(config, self.config_model):
            return config
        try:
            return self.config_model.model_validate(config)
        except ValidationError as exc:
            raise ConfigError(f"{self.name}: {describe_validation_error(exc)}") from exc

    def build(self, config: BaseModel | dict[str, Any]) -> Estimator:
        """Validate ``config`` against the estimator's model and build the estimator."""
        return self.factory(self.config(config))

    def signal_roles(self, config: BaseModel | dict[str, Any]) -> dict[str, list[str]]:
        """The channels the estimator reads under ``config``, by role (:data:`ROLES`)."""
        return self.build(config).signal_roles()

    def catalog_entry(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "title": self.title,
            "description": self.description,
            "paper": self.paper,
            "kind": str(self.kind),
            "produces_map": self.produces_map,
            "config_schema": self.config_model.model_json_schema(),
        }


def family(
    estimator: Callable[[str, Any], Estimator],
    config_base: type[BaseModel],
    *,
    kind: EstimatorKind,
    paper: str,
    produces_map: bool = True,
) -> Callable[..., EstimatorSpec]:
    """The spec maker of a family of estimators built as ``estimator(name, config)``.

    ``make(name, title, description, config_model, state_class, output_units,
    produces_map=…)`` gives one member's spec, with the family's kind and paper.
    """

    def make(
        name: str,
        title: str,
        description: str,
        config_model: type[BaseModel],
        state_class: type[EstimatorState],
        output_units: Mapping[str, str],
        *,
        produces_map: bool = produces_map,
    ) -> EstimatorSpec:
        def factory(config: BaseModel) -> Estimator:
            if not isinstance(config, config_base):
                raise ConfigError(f"{name} needs a {config_base.__name__}")
            return estimator(name, config)

        return EstimatorSpec(
            name, title, description, paper, kind, config_model, factory, state_class,
            MappingProxyType(dict(output_units)), produces_map,
        )  # fmt: skip

    return make


BUILTIN: tuple[str, ...] = (
    "estimation.filters.estimator:KF",
    "estimation.filters.estimator:SKF",
    "estimation.filters.estimator:SSKF",
    "estimation.filters.estimator:RLS",
    "estimation.filters.estimator:NLMS",
    "estimation.observers.lpv:LPV",
    "estimation.observers.ekf:EKF_DEF",
    "estimation.observers.ekf:EKF_AUG",
    "estimation.observers.ekf:EKF_MAP",
    "estimation.torque.estimators:UIO",
    "estimation.torque.estimators:SMO",
    "estimation.torque.estimators:DIRTY",
    "estimation.torque.estimators:ADAPTIVE_CONST",
    "estimation.torque.estimators:ADAPTIVE_TV",
)
"""Every built-in estimator, in catalog order, as ``"module:SPEC"`` (imported on first use,
since the modules import this one)."""


@cache
def registry() -> Mapping[str, EstimatorSpec]:
    """Every built-in estimator by name (read-only, in catalog order)."""
    specs: dict[str, EstimatorSpec] = {}
    for ref in BUILTIN:
        module, attr = ref.split(":")
        spec = getattr(importlib.import_module(module), attr)
        if not isinstance(spec, EstimatorSpec):
            raise TypeError(f"{ref} is not an EstimatorSpec")
        if spec.name in specs:
            raise ValueError(f"estimator {spec.name!r} is registered twice")
        specs[spec.name] = spec
    return MappingProxyType(specs)


def get_spec(name: str) -> EstimatorSpec:
    """The spec of estimator ``name``; a :class:`ConfigError` naming the choices if none."""
    specs = registry()
    try:
        return specs[name]
    except KeyError:
        raise ConfigError(f"unknown estimator {name!r}; choose one of {sorted(specs)}") from None


def names(kind: EstimatorKind | None = None) -> tuple[str, ...]:
    """Registered estimator names (of one ``kind``, or all), in catalog order."""
    return tuple(n for n, s in registry().items() if kind is None or s.kind == kind)


@cache
def state_classes() -> Mapping[str, type[EstimatorState]]:
    """Every state class by name: those the estimators declare, and their bases."""
    out: dict[str, type[EstimatorState]] = {}
    for spec in registry().values():
        for cls in spec.state_class.__mro__:
            if isinstance(cls, type) and issubclass(cls, EstimatorState):
                out.setdefault(cls.__name__, cls)
    return MappingProxyType(out)


def load_state(data: dict[str, Any]) -> EstimatorState:
    """The state saved as ``data`` (``to_dict`` output), of the class its ``state_class``
    tag names; a :class:`StateError` if the tag is missing or unknown."""
    tag = data.get("state_class")
    if tag is None:
        raise StateError("saved state has no state_class")
    return state_class(str(tag)).from_dict(data)
