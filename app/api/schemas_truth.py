"""The response of ``GET /api/runs/{run_id}/truth-map`` (:mod:`app.services.truth_map`)."""

from __future__ import annotations

from pydantic import BaseModel, Field

from app.api.schemas import AxisOut, Nested
from app.io.decimate import nested_or_none
from app.services.truth_map import TruthOnGrid


class TruthMapOut(BaseModel):
    axes: list[AxisOut]
    values: Nested = Field(description="The true map at the nodes of the run's grid.")
    name: str = Field(description="What the map holds (the run's output or map quantity).")
    unit: str = Field(description="Unit of the values ('' when the dataset names none).")
    exact: bool = Field(
        description="True on the truth's own breakpoints; false: interpolated from them."
    )

    @classmethod
    def of(cls, t: TruthOnGrid) -> TruthMapOut:
        return cls(
            axes=[AxisOut(**a) for a in t.axes],
            values=nested_or_none(t.values) or [],
            name=t.name,
            unit=t.unit,
            exact=t.exact,
        )
