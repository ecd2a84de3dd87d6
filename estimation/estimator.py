"""The interface every estimator implements, and the registry of estimators by name.

An estimator is built from a typed config (a pydantic model whose JSON schema the dashboard
renders as a form), declares the channels it needs, and ``run``s over a :class:`Signals`
block in compiled chunks, yielding a :class:`Snapshot` after each chunk. Its state is
explicit and serialisable: ``run(..., state=snapshot.state)`` resumes to a result identical
to an uninterrupted run.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from pydantic import BaseModel, ValidationError

from estimation.errors import ConfigError
from estimation.signals import Signals
from estimation.table import Table


@dataclass(frozen=True, slots=True, eq=False)
class Snapshot:
    """What an estimator reports between chunks.

    ``sample`` counts the log samples consumed so far (of ``n_samples``); ``chunk_start`` is
    the first log sample of the chunk that just ran, and ``outputs`` hold per-sample series
    for that chunk (e.g. ``prediction`` and ``residual`` of the table output, in its unit),
    with ``status`` (0 accepted, 1 rejected by the accept mask, 2 by the innovation gate,
    3 not usable: before the sensor delay is filled).
    """

    estimator: str
    sample: int
    n_samples: int
    time_s: float
    state: Any
    chunk_start: int
    table: Table | None = None
    variance: np.ndarray | None = None
    outputs: dict[str, np.ndarray] = field(default_factory=dict)
    status: np.ndarray | None = None
    rejected: dict[str, int] = field(default_factory=dict)
    metrics: dict[str, float] = field(default_factory=dict)

    @property
    def done(self) -> bool:
        return self.sample >= self.n_samples


class Estimator(Protocol):
    """What the service, the CLI and the benchmarks rely on."""

    name: str
    config: BaseModel

    def required_signals(self) -> list[str]: ...

    def run(
        self,
        signals: Signals,
        *,
        every: int | None = None,
        state: Any = None,
        accept: np.ndarray | None = None,
    ) -> Iterator[Snapshot]: ...


@dataclass(frozen=True, slots=True)
class EstimatorSpec:
    """A registered estimator: its name, what it is, where it comes from, how to build it."""

    name: str
    title: str
    description: str
    paper: str
    config_model: type[BaseModel]
    factory: Callable[[BaseModel], Estimator]
    produces_map: bool = True

    def build(self, config: BaseModel | dict[str, Any]) -> Estimator:
        """Validate ``config`` against the estimator's model and build the estimator."""
        if not isinstance(config, self.config_model):
            try:
                config = self.config_model.model_validate(config)
            except ValidationError as exc:
                raise ConfigError(f"{self.name}: {describe_validation_error(exc)}") from exc
        return self.factory(config)

    def catalog_entry(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "title": self.title,
            "description": self.description,
            "paper": self.paper,
            "produces_map": self.produces_map,
            "config_schema": self.config_model.model_json_schema(),
        }


def describe_validation_error(exc: ValidationError) -> str:
    """One line per problem: ``field.path: message``."""
    parts = []
    for err in exc.errors():
        message = err["msg"].removeprefix("Value error, ")
        loc = ".".join(str(p) for p in err["loc"])
        parts.append(f"{loc}: {message}" if loc else message)
    return "; ".join(parts)


def registry() -> dict[str, EstimatorSpec]:
    """Every built-in estimator by name."""
    from estimation.filters.estimator import FILTER_SPECS
    from estimation.observers.ekf import EKF_SPECS
    from estimation.observers.lpv import LPV_SPECS
    from estimation.torque import TORQUE_SPECS

    return {spec.name: spec for spec in (*FILTER_SPECS, *LPV_SPECS, *EKF_SPECS, *TORQUE_SPECS)}


def get_spec(name: str) -> EstimatorSpec:
    specs = registry()
    try:
        return specs[name]
    except KeyError:
        raise ConfigError(f"unknown estimator {name!r}; choose one of {sorted(specs)}") from None
