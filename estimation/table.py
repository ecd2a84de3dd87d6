"""Look-up tables with named axes and their sparse interpolation regressor (docs/algorithms.md §1).

A table with ``d`` axes stores its values as an array of shape ``(n_1, …, n_d)``; filters
work on the flat C-order vector ``θ`` of length ``p = Π n_a``. For an input ``u`` the output is
multilinear interpolation ``y = ψ(u)ᵀ θ``, where ``ψ(u)`` has at most ``2^d`` non-zeros and is
represented as ``(indices[2^d], weights[2^d])``. Inputs outside the grid are clamped to the
nearest edge (LPV (12)–(15)), so the table is flat beyond its edges.

Example
-------
>>> t = Table([Axis("speed", "rpm", [1000, 2000]), Axis("fuel", "mg/cycle", [0, 10, 20])],
...           [[0.0, 1.0, 2.0], [10.0, 11.0, 12.0]])
>>> float(t.evaluate([[1500.0, 5.0]])[0])
5.5
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimation import kernels
from estimation.errors import ShapeError


@dataclass(frozen=True, slots=True)
class Axis:
    """One table axis: the input channel it reads, its unit and strictly increasing breakpoints."""

    name: str
    unit: str
    breakpoints: np.ndarray = field(repr=False)

    def __init__(self, name: str, unit: str, breakpoints: Sequence[float] | np.ndarray) -> None:
        if not isinstance(name, str) or not name:
            raise ShapeError(f"axis name must be a non-empty string, got {name!r}")
        g = np.array(breakpoints, dtype=np.float64)
        if g.ndim != 1:
            raise ShapeError(f"axis {name!r}: breakpoints must be 1-D, got shape {g.shape}")
        if g.size < 2:
            raise ShapeError(f"axis {name!r}: needs at least two breakpoints, got {g.size}")
        if not np.all(np.isfinite(g)):
            raise ShapeError(f"axis {name!r}: breakpoints must be finite, got {g.tolist()}")
        # Compared, not differenced: np.diff of breakpoints near ±1.8e308 overflows.
        bad = g[1:] <= g[:-1]
        if np.any(bad):
            i = int(np.argmax(bad))
            kind = "duplicate" if g[i] == g[i + 1] else "unsorted"
            raise ShapeError(
                f"axis {name!r}: breakpoints must be strictly increasing; {kind} at positions "
                f"{i} and {i + 1} ({g[i]:g}, {g[i + 1]:g})"
            )
        with np.errstate(over="ignore"):
            span = g[-1] - g[0]
        if not np.isfinite(span):
            raise ShapeError(
                f"axis {name!r}: breakpoints span {g[0]:g} … {g[-1]:g}, beyond the float64 range"
            )
        g.setflags(write=False)
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "unit", str(unit))
        object.__setattr__(self, "breakpoints", g)

    @property
    def size(self) -> int:
        return int(self.breakpoints.size)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "unit": self.unit, "breakpoints": self.breakpoints.tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Axis:
        return cls(data["name"], data.get("unit", ""), data["breakpoints"])

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Axis)
            and (self.name, self.unit) == (other.name, other.unit)
            and np.array_equal(self.breakpoints, other.breakpoints)
        )

    def __hash__(self) -> int:
        return hash((self.name, self.unit, self.breakpoints.tobytes()))


class Grid:
    """The breakpoint grid of a table, with the regressor ``U[n, d] → (idx, w)``."""

    __slots__ = ("_breakpoints", "_sizes", "_strides", "axes")

    def __init__(self, axes: Sequence[Axis]) -> None:
        axes = tuple(axes)
        if not axes:
            raise ShapeError("a table needs at least one axis")
        names = [a.name for a in axes]
        if len(set(names)) != len(names):
            raise ShapeError(f"axis names must be unique, got {names}")
        self.axes = axes
        self._sizes = np.array([a.size for a in axes], dtype=np.int64)
        strides = np.ones(len(axes), dtype=np.int64)
        for a in range(len(axes) - 2, -1, -1):
            strides[a] = strides[a + 1] * self._sizes[a + 1]
        self._strides = strides
        self._breakpoints = np.concatenate([a.breakpoints for a in axes])

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(int(n) for n in self._sizes)

    @property
    def ndim(self) -> int:
        return len(self.axes)

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    @property
    def n_corners(self) -> int:
        return 1 << self.ndim

    def regressor(
        self, U: np.ndarray | Sequence[Sequence[float]], *, specialised: bool = True
    ) -> tuple[np.ndarray, np.ndarray]:
        """Sparse regressor of a batch of inputs.

        Parameters
        ----------
        U : (n, d) array of inputs in axis order and axis units (a 1-D array is taken as
            ``n`` inputs of a 1-D table).
        specialised : use the kernel compiled for this dimension (1-D to 3-D), or the generic
            one; both give bit-identical results.

        Returns
        -------
        idx : (n, 2^d) int64 flat C-order indices of the active elements.
        w : (n, 2^d) float64 interpolation weights, ``Σ_c w[k, c] = 1``, each in ``[0, 1]``.
        """
        U = self._checked_inputs(U)
        n = U.shape[0]
        idx = np.empty((n, self.n_corners), dtype=np.int64)
        w = np.empty((n, self.n_corners), dtype=np.float64)
        corners = kernels.specialise.corner_token(self.n_corners, specialised=specialised)
        kernels.regressor.regressor_kernel(
            U, self._breakpoints, self._sizes, self._strides, idx, w, corners
        )
        return idx, w

    def _checked_inputs(self, U: np.ndarray | Sequence[Sequence[float]]) -> np.ndarray:
        """``U`` as a C-contiguous ``(n, d)`` float array; :class:`ShapeError` naming the axis
        and sample if its shape is wrong or a value is not finite."""
        U = np.asarray(U, dtype=np.float64)
        if U.ndim == 1 and self.ndim == 1:
            U = U[:, None]
        if U.ndim != 2 or U.shape[1] != self.ndim:
            raise ShapeError(
                f"inputs must have shape (n, {self.ndim}) for axes "
                f"{[a.name for a in self.axes]}, got {U.shape}"
            )
        if not np.all(np.isfinite(U)):
            row, col = np.argwhere(~np.isfinite(U))[0]
            raise ShapeError(
                f"input {self.axes[col].name!r} is not finite at sample {row}: {U[row, col]}"
            )
        return np.ascontiguousarray(U)

    def cell_index(self, position: Sequence[int]) -> int:
        """Flat C-order index of the grid node at ``position`` (one index per axis)."""
        if len(position) != self.ndim:
            raise ShapeError(f"cell {tuple(position)} needs {self.ndim} indices")
        for a, (i, n) in enumerate(zip(position, self.shape, strict=True)):
            if not 0 <= i < n:
                raise ShapeError(
                    f"cell {tuple(position)}: index {i} out of range 0..{n - 1} "
                    f"on axis {self.axes[a].name!r}"
                )
        return int(np.dot(position, self._strides))


class Table(Grid):
    """A look-up table: a :class:`Grid` plus finite values of shape ``grid.shape``."""

    __slots__ = ("values",)

    def __init__(
        self, axes: Sequence[Axis], values: np.ndarray | Sequence[Any] | float = 0.0
    ) -> None:
        super().__init__(axes)
        self.values = broadcast_cells(values, self.shape, what="values")

    @property
    def flat(self) -> np.ndarray:
        """The C-order parameter vector θ (a view)."""
        return self.values.reshape(-1)

    def with_values(self, values: np.ndarray | Sequence[Any] | float) -> Table:
        return Table(self.axes, values)

    def evaluate(self, U: np.ndarray | Sequence[Sequence[float]]) -> np.ndarray:
        """Interpolated table output ``y = ψ(u)ᵀθ`` for each row of ``U`` (clamped outside)."""
        idx, w = self.regressor(U)
        return np.einsum("nc,nc->n", self.flat[idx], w)

    __call__ = evaluate

    def on_grid(self, breakpoints: Sequence[Sequence[float] | np.ndarray]) -> np.ndarray:
        """The table's multilinear interpolation on the tensor grid ``b_1 × … × b_d`` (one
        array of targets per axis, in axis order; clamped beyond the box), of shape
        ``(len(b_1), …, len(b_d))``: what :meth:`evaluate` gives on every node of that grid.

        Multilinear interpolation is the tensor product of 1-D linear interpolants, so it is
        applied one axis at a time. Along axis ``a``, with ``g`` its breakpoints, a target
        ``u`` lies in interval ``i`` (``g_i ≤ u ≤ g_{i+1}``, clamped to the first or last) at
        ``t = (u − g_i) / (g_{i+1} − g_i)`` clipped to ``[0, 1]``, and
        ``v ← (1 − t) v[…, i, …] + t v[…, i + 1, …]``. On the table's own breakpoints ``t``
        is 0 or 1, so its nodes come back exactly. Pure numpy over the grid: no kernel is
        compiled, so a process that has not loaded numba can call it
        (docs/reliability.md#api-memory)."""
        if len(breakpoints) != self.ndim:
            raise ShapeError(f"a grid of {self.ndim} axes needs {self.ndim} breakpoint arrays")
        values = self.values
        for a, (axis, targets) in enumerate(zip(self.axes, breakpoints, strict=True)):
            g = axis.breakpoints
            u = np.asarray(targets, dtype=np.float64)
            i = np.clip(np.searchsorted(g, u, side="right") - 1, 0, g.size - 2)
            t = np.clip((u - g[i]) / (g[i + 1] - g[i]), 0.0, 1.0)
            shape = [1] * self.ndim
            shape[a] = u.size
            t = t.reshape(shape)
            values = (1.0 - t) * np.take(values, i, axis=a) + t * np.take(values, i + 1, axis=a)
        return values

    def to_dict(self) -> dict[str, Any]:
        return {"axes": [a.to_dict() for a in self.axes], "values": self.values.tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Table:
        try:
            axes = [Axis.from_dict(a) for a in data["axes"]]
            values = data["values"]
        except (KeyError, TypeError) as exc:
            raise ShapeError(f"table JSON needs 'axes' and 'values': {exc}") from exc
        return cls(axes, values)

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Table)
            and self.axes == other.axes
            and np.array_equal(self.values, other.values)
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        axes = ", ".join(f"{a.name}[{a.unit}]×{a.size}" for a in self.axes)
        return f"Table({axes})"


def broadcast_cells(
    value: np.ndarray | Sequence[Any] | float, shape: tuple[int, ...], *, what: str
) -> np.ndarray:
    """A finite float array of ``shape`` from a scalar, a table-shaped array or a flat vector."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ShapeError(f"{what}: not numeric ({exc})") from exc
    size = math.prod(shape)
    if arr.ndim == 0:
        arr = np.full(shape, float(arr))
    elif arr.shape == shape:
        arr = arr.copy()
    elif arr.ndim == 1 and arr.size == size:
        arr = arr.reshape(shape)
    else:
        raise ShapeError(f"{what}: expected a scalar or shape {shape}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        pos = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise ShapeError(f"{what}: non-finite value {arr[pos]} at cell {pos}")
    return arr
