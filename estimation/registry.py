"""The registry of estimators: one :class:`EstimatorSpec` per name, the home of the contract.

A spec says what an estimator is (title, description, paper, :class:`EstimatorKind`), how
to build it (a pydantic config model and a factory), what its state is (``state_class``),
the unit of every per-sample series it yields (``output_units``) and what a run of it costs
(:class:`Cost`: memory and work as functions of the table size and the log length, which the
service's admission control checks before it stores a run). Everything that lists
estimators — the CLI choices, the catalog, the scenarios, the state loader — derives from
:func:`registry`; adding an estimator is one line in :data:`BUILTIN`
(``docs/adding-an-estimator.md``).
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
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


FLOAT_BYTES = 8
STATE_COPIES = 9
"""Live copies of the state, in floats, while a version is persisted: the state and the
kernel's working copy (2), ``to_dict``'s Python list (a float object and a list slot: 4),
the array rebuilt from it (1) and the ``.npz`` buffer and its bytes (2)."""
CELL_FLOATS = 40
"""Floats per cell a run keeps besides the state: visits, rejection counts per reason, the
reported table and variance, a version's arrays and a live frame's nested lists (Python
floats, 4 slots each, for values, variances and visits)."""
VERSION_CELL_ARRAYS = 5
"""Per-cell arrays of one stored map version: values, variances, visits and two rejection
counts (innovation, delay); the state blob comes on top."""


@dataclass(frozen=True, slots=True)
class Cost:
    """What one run of an estimator costs, from the table's cells ``p``, the log's samples
    ``n`` and the active elements per sample ``c`` (``2**d`` on a ``d``-axis table).

    Memory, in bytes, of the run's data in the worker (the process itself not counted)::

        memory = 8 · (STATE_COPIES · state(p, c) + CELL_FLOATS · p + per_sample(c) · n)

    where ``state(p, c)`` is the floats in the estimator state (the full KF's P: ``p²``) and
    ``per_sample(c)`` the floats kept per log sample (the per-sample outputs, status codes,
    the prepared inputs and the regressor: the estimator's and the worker's copy). ``work``
    is ``ops_per_sample(p, c) · n`` arithmetic operations (a lower bound on the run time at
    any machine's speed). ``max_cells`` caps the table whatever the memory budget (``None``:
    only the service's global cap).
    """

    state_floats: Callable[[int, int], float]
    sample_floats: Callable[[int], float]
    ops_per_sample: Callable[[int, int], float]
    max_cells: int | None = None
    size: Callable[[BaseModel], tuple[int, int]] = field(default=lambda c: table_size(c))
    holdout_passes: float = 1.0
    """Further runs of the estimator that the truth-free check of every run makes
    (docs/tuning.md#which-runs-report-what): 1, a refit on the first 70 % of the log and a
    prediction of the rest, made while the run's own data are still held; 0 for an estimator
    without one (the torque estimators)."""
    stream_sample_bytes: float = 0.0
    """Bytes a sample of the whole log that a streamed run holds beyond its outputs, status
    codes and final residual copy (docs/reliability.md#admission): the LPV check's fit output
    error and its statistics' temporaries, what an EKF run's RSS was measured to keep; 0 for
    the map filters and torque estimators, whose checks keep only sums."""

    def run_memory_bytes(self, cells: int, samples: int, *, corners: int = 1) -> int:
        """Predicted peak bytes of a service run: the run and its held-out refit beside it."""
        return int((1.0 + self.holdout_passes) * self.memory_bytes(cells, samples, corners=corners))

    def run_work(self, cells: int, samples: int, *, corners: int = 1) -> float:
        """Predicted operations of a service run, its held-out refit included."""
        return (1.0 + self.holdout_passes) * self.work(cells, samples, corners=corners)

    def memory_of(self, config: BaseModel, samples: int) -> int:
        """:meth:`memory_bytes` at the size of a validated ``config``."""
        cells, corners = self.size(config)
        return self.memory_bytes(cells, samples, corners=corners)

    def state_bytes(self, cells: int, *, corners: int = 1) -> int:
        """Bytes of one serialised state (what each stored version's state blob holds)."""
        return int(FLOAT_BYTES * self.state_floats(cells, corners))

    def memory_bytes(self, cells: int, samples: int, *, corners: int = 1) -> int:
        """Predicted peak bytes of a run's data (class docstring)."""
        floats = (
            STATE_COPIES * self.state_floats(cells, corners)
            + CELL_FLOATS * cells
            + self.sample_floats(corners) * samples
        )
        return int(FLOAT_BYTES * floats)

    def work(self, cells: int, samples: int, *, corners: int = 1) -> float:
        """Predicted arithmetic operations of a run."""
        return float(self.ops_per_sample(cells, corners)) * samples

    def version_bytes(self, cells: int, *, corners: int = 1) -> int:
        """Bytes of one stored map version without its per-sample segment."""
        return FLOAT_BYTES * VERSION_CELL_ARRAYS * cells + self.state_bytes(cells, corners=corners)


def table_size(config: BaseModel) -> tuple[int, int]:
    """``(cells, corners)`` of a config with ``axes`` (each with ``breakpoints``); ``(0, 1)``
    without."""
    axes = getattr(config, "axes", None) or []
    return grid_size([len(a.breakpoints) for a in axes])


def grid_size(lengths: list[int]) -> tuple[int, int]:
    """``(cells, corners)`` of a grid with axes of these lengths (``(0, 1)`` for none)."""
    if not lengths:
        return 0, 1
    return math.prod(lengths), 2 ** len(lengths)


GENERIC_COST = Cost(
    state_floats=lambda p, c: 2 * p + c * c + 64,
    sample_floats=lambda c: 24 + 4 * c,
    ops_per_sample=lambda p, c: 10 * c * c + 50,
)
"""A cautious default for an estimator that declares nothing: local updates over the active
elements, a few dozen floats per sample."""


@dataclass(frozen=True, slots=True)
class EstimatorSpec:
    """A registered estimator: its name, what it is, where it comes from, how to build it.

    ``output_units`` gives the unit of each per-sample series in ``Snapshot.outputs`` by
    name; ``""`` means "the unit of the config's output channel" (``prediction`` and
    ``residual`` of the map filters) or, for an estimator without one, no unit.
    ``holdout`` names the truth-free check of its runs as ``"module:function"`` (``None``:
    its kind's, :data:`HOLDOUT`; :meth:`holdout_check`).
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
    cost: Cost = GENERIC_COST
    holdout: str | None = None

    def holdout_check(self) -> Callable[..., Any]:
        """The truth-free check of a run (held-out prediction error, innovation statistics;
        docs/tuning.md): ``holdout`` as ``"module:function"``, else its kind's
        (:data:`HOLDOUT`). Called as ``f(name, config, signals, *, fraction, accept)``; it
        returns a report whose ``metrics()`` a run stores."""
        module, attr = (self.holdout or HOLDOUT[self.kind]).split(":")
        return getattr(importlib.import_module(module), attr)  # type: ignore[no-any-return]

    @property
    def streams(self) -> bool:
        """Its runs can read their log a window at a time: its kind's check has a windowed
        form (:data:`HOLDOUT_WINDOWS`; a spec's own ``holdout`` has none). They do when its
        estimator plans windows too (``windowed``,
        :meth:`~estimation.estimator.ChunkedEstimator.run_windows`)."""
        return self.holdout is None and self.kind in HOLDOUT_WINDOWS

    def holdout_check_windows(self) -> Callable[..., Any]:
        """:meth:`holdout_check` over a log never held whole (:data:`HOLDOUT_WINDOWS`), called
        as ``f(name, config, log, *, unit)`` with a
        :class:`~estimation.estimator.LogWindows` ``log``; only when it
        :attr:`streams`."""
        if not self.streams:
            raise ConfigError(f"{self.name} runs read their log whole")
        module, attr = HOLDOUT_WINDOWS[self.kind].split(":")
        return getattr(importlib.import_module(module), attr)  # type: ignore[no-any-return]

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
    cost: Cost = GENERIC_COST,
) -> Callable[..., EstimatorSpec]:
    """The spec maker of a family of estimators built as ``estimator(name, config)``.

    ``make(name, title, description, config_model, state_class, output_units,
    produces_map=…, cost=…, paper=…)`` gives one member's spec, with the family's kind, and
    its paper and cost unless the member declares its own (a baseline in a family built on
    one paper credits its own source, not the family's).
    """
    family_cost = cost
    family_paper = paper

    def make(
        name: str,
        title: str,
        description: str,
        config_model: type[BaseModel],
        state_class: type[EstimatorState],
        output_units: Mapping[str, str],
        *,
        produces_map: bool = produces_map,
        cost: Cost = family_cost,
        paper: str = family_paper,
    ) -> EstimatorSpec:
        def factory(config: BaseModel) -> Estimator:
            if not isinstance(config, config_base):
                raise ConfigError(f"{name} needs a {config_base.__name__}")
            return estimator(name, config)

        return EstimatorSpec(
            name, title, description, paper, kind, config_model, factory, state_class,
            MappingProxyType(dict(output_units)), produces_map, cost,
        )  # fmt: skip

    return make


HOLDOUT: Mapping[EstimatorKind, str] = MappingProxyType(
    {
        EstimatorKind.MAP_FILTER: "estimation.holdout:holdout_error",
        EstimatorKind.MAP_OBSERVER: "estimation.holdout_observers:lpv_holdout",
        EstimatorKind.JOINT_EKF: "estimation.holdout_ekf:ekf_holdout",
        EstimatorKind.TORQUE: "estimation.holdout:unmeasured_input",
    }
)
"""The truth-free check of each kind, as ``"module:function"`` (imported on first use); a
spec's own ``holdout`` overrides it (docs/tuning.md#which-runs-report-what)."""

HOLDOUT_WINDOWS: Mapping[EstimatorKind, str] = MappingProxyType(
    {
        EstimatorKind.MAP_FILTER: "estimation.holdout:holdout_error_windows",
        EstimatorKind.MAP_OBSERVER: "estimation.holdout_observers:lpv_holdout_windows",
        EstimatorKind.JOINT_EKF: "estimation.holdout_ekf:ekf_holdout_windows",
        EstimatorKind.TORQUE: "estimation.holdout:unmeasured_input_windows",
    }
)
"""The kinds whose runs stream their log (docs/data-formats.md#streamed-runs): their
estimators run in windows and their truth-free check, here as ``"module:function"``, reads
the log a window at a time too."""


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
