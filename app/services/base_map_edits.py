"""An edited map saved as a base map: the run view's editor sends a run version's grid with
values of its own (locked, reset, smoothed, accepted or rejected cells) and the log of the
operations; both are checked here before :meth:`BaseMapService.promote` stores them, the
values in place of the version's and the log in the lineage (``config.edits``)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.domain import MapVersion
from app.errors import InvalidRequestError
from estimation.filters.config import MAX_VALUE


@dataclass(frozen=True, slots=True)
class EditedMap:
    """What the editor sent: the grid (``None``: the version's own values) and its edits."""

    values: Any
    edits: list[dict[str, Any]]

    def values_for(self, version: MapVersion) -> np.ndarray:
        """The values to store: the edited grid, checked against the version's axes, else
        the version's own (an edit log that changed nothing, e.g. "accept")."""
        assert version.values is not None  # promote() refuses a version without a map
        assert version.axes is not None
        if self.values is None:
            return version.values
        return checked_values(self.values, tuple(len(a["breakpoints"]) for a in version.axes))

    def config(self, run_config: dict[str, Any] | None) -> dict[str, Any]:
        """The run's configuration with the edit log beside it (lineage: how the map was made)."""
        return {**(run_config or {}), "edits": self.edits}


def edited_map(
    values: Any, edits: list[dict[str, Any]] | None, source: str | None
) -> EditedMap | None:
    """The edit of a promote request; ``None`` for a plain promotion (no values, no edits and
    no ``source: "edit"``). 422 naming ``source`` for values sent as ``source: "run"``."""
    if source == "run" and (values is not None or edits):
        raise InvalidRequestError(
            'source "run" saves the version as it is; send edited values with source "edit"',
            field="source",
        )
    if values is None and not edits and source != "edit":
        return None
    return EditedMap(values=values, edits=list(edits or []))


def checked_values(values: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Nested lists of finite numbers with exactly ``shape`` (one level per axis) as an
    array; 422 naming ``values`` (and the first offending cell) otherwise."""
    got = _shape(values)
    if got is None:
        raise InvalidRequestError(
            "values must be nested lists of equal length, one level per axis", field="values"
        )
    if got != shape:
        raise InvalidRequestError(
            f"values have shape {_dims(got)}, the version's grid is {_dims(shape)}", field="values"
        )
    flat = np.asarray(values, dtype=object).reshape(-1) if shape else [values]
    for k, v in enumerate(flat):
        where = ", ".join(map(str, np.unravel_index(k, shape))) if shape else ""
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InvalidRequestError(
                f"values[{where}] is {v!r}; every cell must be a finite number",
                field="values",
            )
        if abs(v) > MAX_VALUE:  # a run would start from it (θ0) and overflow
            raise InvalidRequestError(
                f"values[{where}] is {v!r}; a cell is at most {MAX_VALUE:g} in magnitude",
                field="values",
            )
    return np.asarray(values, dtype=np.float64)


def _shape(value: Any) -> tuple[int, ...] | None:
    """The shape of regular nested lists (``()`` for a leaf), ``None`` if ragged."""
    if not isinstance(value, list):
        return ()
    shapes = {_shape(v) for v in value}
    if len(shapes) > 1 or None in shapes:
        return None
    inner = shapes.pop() if shapes else ()
    return (len(value), *inner)


def _dims(shape: tuple[int, ...]) -> str:
    return " × ".join(map(str, shape)) if shape else "a single number"
