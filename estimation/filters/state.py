"""Explicit, serialisable filter states (copy, ``to_dict``/``from_dict``, ``save``/``load``
come from :class:`~estimation.state.EstimatorState`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from estimation.state import EstimatorState


@dataclass(frozen=True, slots=True, eq=False)
class FilterState(EstimatorState):
    """Common fields: the filter's registry name (``kind``), kernel steps done (``step``),
    rejection counts and the table values."""

    rejected_mask: int
    rejected_gate: int
    theta: np.ndarray  # (p,) flat C-order table values

    ARRAYS: ClassVar[tuple[str, ...]] = ("theta",)
    WHAT: ClassVar[str] = "filter state"


@dataclass(frozen=True, slots=True, eq=False)
class KfState(FilterState):
    """Full KF: ``P`` is (p, p), or (p+1, p+1) with the sensor state ``y_m`` last."""

    P: np.ndarray
    y_m: float | None

    ARRAYS: ClassVar[tuple[str, ...]] = ("theta", "P")


@dataclass(frozen=True, slots=True, eq=False)
class LocalState(FilterState):
    """SKF / local RLS: per-cell variances, lazy-aging marks and the active block.

    ``var[j]`` is the variance of cell ``j`` aged through step ``last[j]``; ``active`` holds
    the flat indices of the active elements (−1 before the first sample) and ``P_active``
    their covariance, with the sensor state ``y_m`` as the last row/column when present.
    """

    var: np.ndarray
    last: np.ndarray
    active: np.ndarray
    P_active: np.ndarray
    y_m: float | None

    ARRAYS: ClassVar[tuple[str, ...]] = ("theta", "var", "last", "active", "P_active")


@dataclass(frozen=True, slots=True, eq=False)
class ThetaState(FilterState):
    """SSKF / NLMS: the table values are the whole state."""


STATE_CLASSES: dict[str, type[FilterState]] = {
    c.__name__: c for c in (KfState, LocalState, ThetaState)
}
