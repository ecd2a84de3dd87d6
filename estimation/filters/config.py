"""Typed configurations of the map-updating filters.

Defaults are the SKF paper's values: the synthetic checks use ``σv² = σw² = 1``, ``θ0 = 0``,
``P0 = 0`` (SKF §5); the sensor model uses the NOx case study's ``a = 0.96``, ``τ = 0.75 s``,
``σf = 50`` (SKF (34)). Every ``sigma_*`` is a standard deviation in the unit of the table
output; ``p0`` is a variance (output unit squared). The JSON schema of each model is what
the dashboard renders as a form.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    field_validator,
    model_validator,
)

MAX_SIGMA = 1e75
"""Largest standard deviation accepted (σw, σv, σf, the gate): its square, 1e150, leaves
room for the products and sums of the covariance update without overflowing float64."""
MAX_VARIANCE = 1e150
"""Largest variance accepted (P0): ``P0²`` (the update's ``P w wᵀ P``) stays below 1e300."""
MAX_VALUE = 1e75
"""Largest start value of a cell accepted (θ0, a table's or base map's values): a residual's
square, 1e150, and its products with the variances stay finite."""

CellValues = Annotated[
    float | list[Any],
    Field(description="A scalar for every cell, or nested lists in axis order (table shape)."),
]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _numbers(value: Any) -> Iterator[float]:
    """The numbers in a scalar or nested lists (other items are the shape check's business)."""
    if isinstance(value, list):
        for item in value:
            yield from _numbers(item)
    elif isinstance(value, int | float) and not isinstance(value, bool):
        yield float(value)


def bounded(value: Any, limit: float = math.inf) -> Any:
    """``value`` (a scalar or nested lists) if every number in it is finite with magnitude
    at most ``limit``; else a ``ValueError`` quoting the first offender."""
    for v in _numbers(value):
        if not math.isfinite(v):
            raise ValueError(f"must be finite, got {v!r}")
        if abs(v) > limit:
            raise ValueError(
                f"{v:g} is too large: at most {limit:g}, so that the filter's float64 "
                "arithmetic (squares, products and sums of variances) cannot overflow"
            )
    return value


def _sigma_bound(value: Any) -> Any:
    return bounded(value, MAX_SIGMA)


def _variance_bound(value: Any) -> Any:
    return bounded(value, MAX_VARIANCE)


def _value_bound(value: Any) -> Any:
    """Finite values at most :data:`MAX_VALUE` in magnitude; a non-finite one is left to
    the grid's check, which names its cell."""
    bounded([v for v in _numbers(value) if math.isfinite(v)], MAX_VALUE)
    return value


#: A standard deviation (σv, σf): finite and at most :data:`MAX_SIGMA`.
Sigma = Annotated[float, AfterValidator(_sigma_bound)]
#: σw of every cell, or per cell: finite and at most :data:`MAX_SIGMA`.
SigmaCells = Annotated[CellValues, AfterValidator(_sigma_bound)]
#: P0 of every cell, or per cell: finite and at most :data:`MAX_VARIANCE`.
VarianceCells = Annotated[CellValues, AfterValidator(_variance_bound)]


class AxisConfig(_Strict):
    """One table axis: the input channel it reads and its breakpoints."""

    name: str = Field(min_length=1, description="Input channel the axis reads.")
    breakpoints: list[float] = Field(
        min_length=2, description="Strictly increasing breakpoints, in the channel's unit."
    )
    unit: str = Field("", description="Unit of the channel (e.g. rpm, mg/stroke).")

    @field_validator("breakpoints")
    @classmethod
    def _increasing(cls, g: list[float]) -> list[float]:
        for i in range(len(g) - 1):
            if not g[i] < g[i + 1]:
                kind = "duplicate" if g[i] == g[i + 1] else "unsorted"
                raise ValueError(
                    f"must be strictly increasing; {kind} at positions {i} and {i + 1} "
                    f"({g[i]:g}, {g[i + 1]:g})"
                )
        return g


class SensorConfig(_Strict):
    """First-order sensor lag and transport delay between the table and the measurement
    (docs/algorithms.md §2.6, SKF (23)–(33)): ``y_M(k) = a·y_M(k−1) + (1−a)·T(u_{k−τ})``."""

    lag: float = Field(0.96, ge=0.0, lt=1.0, description="Discrete lag pole a (per sample).")
    delay_s: float | None = Field(
        0.75, ge=0.0, description="Transport delay τ in seconds (needs a uniform time base)."
    )
    delay_samples: int | None = Field(
        None, ge=0, description="Transport delay τ in samples; overrides delay_s."
    )
    sigma_f: Sigma = Field(50.0, ge=0.0, description="Process noise σf of the sensor state.")

    @field_validator("delay_s")
    @classmethod
    def _finite_delay(cls, v: float | None) -> float | None:
        return None if v is None else bounded(v)


class TableFilterConfig(_Strict):
    """Settings shared by every map-updating filter."""

    axes: list[AxisConfig] = Field(min_length=1, description="Table axes, in order.")
    output: str = Field(min_length=1, description="Channel holding the measured table output.")
    output_unit: str = Field("", description="Unit of the output channel.")
    theta0: Annotated[CellValues, AfterValidator(_value_bound)] = Field(
        0.0, description=f"Initial table values θ0 (finite, |θ0| ≤ {MAX_VALUE:g})."
    )
    locked: list[list[int]] = Field(
        default_factory=list,
        description="Cells whose value and variance never change, as index lists per axis.",
    )
    gate_sigma: float | None = Field(
        None,
        gt=0.0,
        description="Innovation gate: reject a sample whose normalised innovation e²/s "
        "exceeds gate_sigma².",
    )

    @field_validator("gate_sigma")
    @classmethod
    def _finite_gate(cls, v: float | None) -> float | None:
        return None if v is None else _sigma_bound(v)

    @model_validator(mode="after")
    def _locked_cells_fit(self) -> TableFilterConfig:
        shape = [len(a.breakpoints) for a in self.axes]
        names = [a.name for a in self.axes]
        if len(set(names)) != len(names):
            raise ValueError(f"axes: names must be unique, got {names}")
        for cell in self.locked:
            if len(cell) != len(shape) or any(
                not 0 <= i < n for i, n in zip(cell, shape, strict=False)
            ):
                raise ValueError(f"locked: cell {cell} is not inside a table of shape {shape}")
        return self


class _Covariance(TableFilterConfig):
    sigma_w: SigmaCells = Field(1.0, description="Random-walk σw of each cell per sample.")
    sigma_v: Sigma = Field(1.0, gt=0.0, description="Measurement noise σv.")
    p0: VarianceCells = Field(0.0, description="Initial variance P0 of each cell.")
    limit: Literal["none", "p0"] = Field(
        "none",
        description="Covariance limiting (EKF §3.1): 'p0' caps each variance at P0 "
        "(PSD-preserving row/column scaling).",
    )


class KfConfig(_Covariance):
    """Full Kalman filter (SKF §4.4)."""

    sensor: SensorConfig | None = Field(None, description="Sensor lag and delay (optional).")


class SkfConfig(_Covariance):
    """Simplified Kalman filter (SKF §4.7)."""

    sensor: SensorConfig | None = Field(None, description="Sensor lag and delay (optional).")


class SskfConfig(TableFilterConfig):
    """Steady-state Kalman filter (SKF §4.5)."""

    sigma_w: SigmaCells = Field(1.0, description="Random-walk σw of each cell per sample.")
    sigma_v: Sigma = Field(1.0, gt=0.0, description="Measurement noise σv.")


class RlsConfig(TableFilterConfig):
    """Recursive least squares with forgetting on the active cells."""

    forgetting: float = Field(0.995, gt=0.0, le=1.0, description="Forgetting factor λ.")
    p0: VarianceCells = Field(1000.0, description="Initial (normalised) covariance of each cell.")
    limit: Literal["none", "p0"] = Field("none", description="Cap the covariance at P0.")
    sigma_v: Sigma = Field(
        1.0, gt=0.0, description="Measurement noise σv, used only by the innovation gate."
    )


class NlmsConfig(TableFilterConfig):
    """Normalised least mean squares on the active cells."""

    mu: float = Field(0.5, gt=0.0, lt=2.0, description="Step size μ (0 < μ < 2).")
    eps: float = Field(1e-6, gt=0.0, description="Regularisation ε of the normalisation.")
    sigma_v: Sigma = Field(
        1.0, gt=0.0, description="Measurement noise σv, used only by the innovation gate."
    )
