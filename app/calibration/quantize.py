"""What an ECU can store of a learned map: clamped to the limits, rounded to the data type.

For each cell, with ``lower``/``upper`` the characteristic's physical limits, ``conv`` its
COMPU_METHOD (:mod:`app.calibration.conversions`) and ``dt`` the FNC_VALUES data type::

    clipped = min(max(requested, lower), upper)
    raw     = saturate_dt(round(conv⁻¹(clipped)))        # integer types round, floats cast
    stored  = conv(raw)
    error   = stored − clipped                            # the quantisation error (physical)

Rounding can step just outside a limit that is not on the raw grid; then the neighbouring
raw value inside the limits is taken. ``clamped`` marks the cells that were outside the
limits. See ``docs/calibration.md#values``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from app.calibration.conversions import to_physical, to_raw
from app.calibration.datatypes import datatype
from app.io.errors import InputError

if TYPE_CHECKING:
    from app.calibration.model import Characteristic

# Relative slack when testing a stored value against a limit (float round-off of conv).
_LIMIT_RTOL = 1e-12


@dataclass(frozen=True)
class Quantized:
    """``values``: the physical values the ECU will hold; ``raw``: the stored integers (or
    floats); ``error``: ``values − clipped request`` per cell; ``clamped``: cells that were
    outside ``[lower, upper]``."""

    values: np.ndarray
    raw: np.ndarray
    error: np.ndarray
    clamped: np.ndarray

    @property
    def max_abs_error(self) -> float:
        return float(np.max(np.abs(self.error))) if self.error.size else 0.0


def quantize(char: Characteristic, values: np.ndarray, *, strict: bool = False) -> Quantized:
    """Clamp ``values`` (physical) to ``char``'s limits and round them to what its data type
    and conversion hold. ``strict``: a value outside the limits is an InputError naming the
    characteristic and the first such cell instead of being clamped."""
    requested = np.asarray(values, dtype=np.float64)
    if not np.all(np.isfinite(requested)):
        cell = tuple(int(i) for i in np.argwhere(~np.isfinite(requested))[0])
        raise InputError(
            f"characteristic {char.name}: value at cell {cell} is not finite", field="values"
        )
    lower, upper = float(char.lower), float(char.upper)
    clamped = (requested < lower) | (requested > upper)
    if strict and np.any(clamped):
        cell = tuple(int(i) for i in np.argwhere(clamped)[0])
        raise InputError(
            f"characteristic {char.name}: {int(clamped.sum())} value(s) outside the limits "
            f"[{lower:g}, {upper:g}]; first at cell {cell}: {requested[cell]!r}",
            field="values",
        )
    clipped = np.clip(requested, lower, upper)
    dt = datatype(char.datatype, char.byte_order, what=f"characteristic {char.name}")
    raw = to_raw(char.compu_method, clipped, dt)
    if dt.is_integer:
        raw = _inside_limits(char, raw, clipped, dt.min, dt.max)
    stored = to_physical(char.compu_method, raw)
    return Quantized(values=stored, raw=raw, error=stored - clipped, clamped=clamped)


def _inside_limits(
    char: Characteristic, raw: np.ndarray, target: np.ndarray, raw_min: float, raw_max: float
) -> np.ndarray:
    """Per cell, of ``raw − 1``, ``raw`` and ``raw + 1`` the one whose physical value lies in
    the limits and nearest ``target`` (``raw`` itself when none does)."""
    candidates = np.clip(raw[..., None] + np.array([0.0, -1.0, 1.0]), raw_min, raw_max)
    phys = to_physical(char.compu_method, candidates)
    slack = _LIMIT_RTOL * max(abs(char.lower), abs(char.upper), 1.0)
    inside = (phys >= char.lower - slack) & (phys <= char.upper + slack)
    distance = np.where(inside, np.abs(phys - target[..., None]), np.inf)
    best = np.argmin(distance, axis=-1)
    chosen = np.take_along_axis(candidates, best[..., None], axis=-1)[..., 0]
    return np.where(np.any(inside, axis=-1), chosen, raw)
