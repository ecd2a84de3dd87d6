"""The response of ``GET /api/runs/{run_id}/truth-map`` (:mod:`app.services.truth_map`)."""

from __future__ import annotations

from pydantic import BaseModel, Field

from app.api.schemas import AxisOut, Nested
from app.io.decimate import nested_or_none
from app.services.truth_map import TruthOnGrid


class TruthMapOut(BaseModel):
    axes: list[AxisOut]
    values: Nested | None = Field(
        description="The true map at the nodes of the run's grid; null when the grid is not "
        "over the true map's inputs (``reason`` says why)."
    )
    name: str = Field(description="What the map holds (the run's output or map quantity).")
    unit: str = Field(description="Unit of the values ('' when the dataset names none).")
    exact: bool = Field(
        description="True on the truth's own breakpoints; false: interpolated from them."
    )
    reason: str | None = Field(None, description="Why there is no true map on this grid.")

    @classmethod
    def of(cls, t: TruthOnGrid) -> TruthMapOut:
        return cls(
            axes=[AxisOut(**a) for a in t.axes],
            values=None if t.values is None else nested_or_none(t.values) or [],
            name=t.name,
            unit=t.unit,
            exact=t.exact,
            reason=t.reason,
        )
