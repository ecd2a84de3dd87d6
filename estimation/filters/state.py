"""Explicit, serialisable filter states.

A state is frozen; the run functions copy its arrays, advance the copy and return a new
state, so a saved state resumes to a result bit-identical to an uninterrupted run.
``to_dict`` gives JSON-able data (Python floats round-trip exactly through JSON); ``save`` /
``load`` use ``.npz``.
"""

from __future__ import annotations

import ast
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np

from estimation.errors import StateError

_DTYPES = {"int64": np.int64, "float64": np.float64}


@dataclass(frozen=True, slots=True, eq=False)
class FilterState:
    """Common fields: the filter's registry name, kernel steps done, rejection counts."""

    kind: str
    step: int
    rejected_mask: int
    rejected_gate: int
    theta: np.ndarray  # (p,) flat C-order table values

    ARRAYS: ClassVar[tuple[str, ...]] = ("theta",)

    def copy(self) -> Self:
        return dataclasses.replace(
            self, **{name: np.array(getattr(self, name)) for name in self.ARRAYS}
        )

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"state_class": type(self).__name__}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                out[f.name] = {
                    "dtype": str(value.dtype),
                    "shape": list(value.shape),
                    "data": value.ravel().tolist(),
                }
            else:
                out[f.name] = value
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Self:
        """Rebuild a state from :meth:`to_dict` output; on the base class, the concrete class
        named in the data is chosen (as :meth:`load` does)."""
        saved_class = data.get("state_class")
        target = STATE_CLASSES.get(str(saved_class)) if saved_class is not None else cls
        if target is None:
            raise StateError(f"unknown state class {saved_class!r}")
        if not issubclass(target, cls):
            raise StateError(f"saved {target.__name__} cannot be loaded as {cls.__name__}")
        if target is not cls:
            return target.from_dict(data)  # type: ignore[return-value]
        names = [f.name for f in dataclasses.fields(cls)]
        missing = [n for n in names if n not in data]
        if missing:
            raise StateError(f"{cls.__name__}: saved state lacks {missing}")
        values: dict[str, Any] = {}
        for name in names:
            raw = data[name]
            if name in cls.ARRAYS:
                try:
                    dtype = _DTYPES[raw["dtype"]]
                    values[name] = np.array(raw["data"], dtype=dtype).reshape(raw["shape"])
                except (KeyError, TypeError, ValueError) as exc:
                    raise StateError(f"{cls.__name__}: bad array {name!r}: {exc}") from exc
            else:
                values[name] = raw
        return cls(**values)

    def save(self, path: str | Path) -> None:
        scalars = {
            f.name: getattr(self, f.name)
            for f in dataclasses.fields(self)
            if f.name not in self.ARRAYS
        }
        arrays = {name: getattr(self, name) for name in self.ARRAYS}
        np.savez(path, __class__=type(self).__name__, __scalars__=repr(scalars), **arrays)

    @staticmethod
    def load(path: str | Path) -> FilterState:
        with np.load(path, allow_pickle=False) as f:
            cls = STATE_CLASSES.get(str(f["__class__"]))
            if cls is None:
                raise StateError(f"{path}: not a saved filter state")
            scalars = _literal(str(f["__scalars__"]))
            arrays = {name: np.array(f[name]) for name in cls.ARRAYS}
        return cls(**scalars, **arrays)


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


def _literal(text: str) -> dict[str, Any]:
    value = ast.literal_eval(text)
    if not isinstance(value, dict):
        raise StateError("saved state scalars are not a mapping")
    return value
