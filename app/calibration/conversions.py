"""COMPU_METHOD conversions between ECU-internal (raw) and physical values.

The conversion types of ASAM MCD-2 MC (ASAP2) 1.6, section COMPU_METHOD; see
``docs/calibration.md#values``:

* ``IDENTICAL`` (and ``NO_COMPU_METHOD``): ``phys = raw``.
* ``LINEAR`` (``COEFFS_LINEAR a b``): ``phys = a·raw + b``.
* ``RAT_FUNC`` (``COEFFS a b c d e f``). The standard states the coefficients in the
  direction physical → internal::

      raw = (a·phys² + b·phys + c) / (d·phys² + e·phys + f)

  so :func:`to_raw` evaluates it directly and :func:`to_physical` inverts it. With
  ``a = d = 0`` (the usual case) the inverse is closed form,
  ``phys = (c − f·raw) / (e·raw − b)``; otherwise it solves
  ``(a − d·raw)·phys² + (b − e·raw)·phys + (c − f·raw) = 0`` and takes the root that maps
  back onto ``raw`` (the larger of two real roots).
* ``TAB_INTP`` (``COMPU_TAB`` of ``raw phys`` pairs): linear interpolation between pairs,
  held at the ends; the inverse interpolates the other way (needs monotone physical values).
* ``TAB_NOINTP``: the pair whose raw value is nearest (ties to the lower); the inverse takes
  the pair whose physical value is nearest.
* ``TAB_VERB`` (verbal table): values stay numeric; ``phys = raw``.

:func:`to_raw` rounds to the nearest integer for integer data types (half to even) and
saturates to the data type's range; it never wraps around.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from app.calibration.datatypes import DataType
from app.io.errors import InputError

if TYPE_CHECKING:
    from app.calibration.model import CompuMethod

_IDENTITY = {"IDENTICAL", "NO_COMPU_METHOD", "TAB_VERB"}
SUPPORTED = ("IDENTICAL", "LINEAR", "RAT_FUNC", "TAB_INTP", "TAB_NOINTP", "TAB_VERB")


def to_physical(cm: CompuMethod | None, raw: np.ndarray) -> np.ndarray:
    """Physical values of ECU-internal values ``raw`` (any shape, float64 out)."""
    raw = np.asarray(raw, dtype=np.float64)
    kind = _kind(cm)
    if kind in _IDENTITY:
        return raw.copy()
    assert cm is not None
    if kind == "LINEAR":
        a, b = _coeffs(cm, 2)
        return a * raw + b
    if kind == "RAT_FUNC":
        return _rat_func_inverse(cm, raw)
    keys, values = _table(cm)
    if kind == "TAB_INTP":
        return np.interp(raw, keys, values)
    return values[_nearest(keys, raw)]


def to_raw_exact(cm: CompuMethod | None, phys: np.ndarray) -> np.ndarray:
    """ECU-internal values of physical values, before rounding to a data type."""
    phys = np.asarray(phys, dtype=np.float64)
    kind = _kind(cm)
    if kind in _IDENTITY:
        return phys.copy()
    assert cm is not None
    if kind == "LINEAR":
        a, b = _coeffs(cm, 2)
        if a == 0:
            raise InputError(
                f"COMPU_METHOD {cm.name}: LINEAR with a = 0 cannot be inverted", field="a2l"
            )
        return (phys - b) / a
    if kind == "RAT_FUNC":
        a, b, c, d, e, f = _coeffs(cm, 6)
        with np.errstate(divide="ignore", invalid="ignore"):
            return (a * phys**2 + b * phys + c) / (d * phys**2 + e * phys + f)
    keys, values = _table(cm)
    if kind == "TAB_INTP":
        order = np.argsort(values, kind="stable")
        if np.any(np.diff(values[order]) == 0) or not (
            np.all(np.diff(values) > 0) or np.all(np.diff(values) < 0)
        ):
            raise InputError(
                f"COMPU_METHOD {cm.name}: TAB_INTP physical values are not strictly monotone, "
                "so the table cannot be inverted",
                field="a2l",
            )
        return np.interp(phys, values[order], keys[order])
    order = np.argsort(values, kind="stable")
    return keys[order][_nearest(values[order], phys)]


def to_raw(cm: CompuMethod | None, phys: np.ndarray, dt: DataType) -> np.ndarray:
    """ECU-internal values as stored: rounded for integer types, saturated to ``dt``'s range
    (float64 out holding exactly representable values)."""
    raw = to_raw_exact(cm, phys)
    raw = np.where(np.isnan(raw), 0.0, raw)
    if dt.is_integer:
        return np.clip(np.rint(raw), dt.min, dt.max)
    return np.clip(raw, dt.min, dt.max).astype(dt.dtype).astype(np.float64)


def _kind(cm: CompuMethod | None) -> str:
    if cm is None:
        return "IDENTICAL"
    if cm.kind == "UNDEFINED":
        raise InputError(
            f"COMPU_METHOD {cm.name} is referenced but not defined in the A2L", field="a2l"
        )
    if cm.kind not in SUPPORTED and cm.kind != "NO_COMPU_METHOD":
        raise InputError(
            f"COMPU_METHOD {cm.name}: conversion type {cm.kind} is not supported "
            f"({', '.join(SUPPORTED)})",
            field="a2l",
        )
    return cm.kind


def _coeffs(cm: CompuMethod, n: int) -> tuple[float, ...]:
    coeffs = tuple(float(c) for c in cm.coeffs)
    if len(coeffs) != n:
        raise InputError(
            f"COMPU_METHOD {cm.name}: {cm.kind} needs {n} coefficients, got {len(coeffs)}",
            field="a2l",
        )
    return coeffs


def _table(cm: CompuMethod) -> tuple[np.ndarray, np.ndarray]:
    if not cm.table:
        raise InputError(
            f"COMPU_METHOD {cm.name}: {cm.kind} has an empty conversion table", field="a2l"
        )
    pairs = sorted((float(k), float(v)) for k, v in cm.table)
    keys = np.array([k for k, _ in pairs])
    values = np.array([v for _, v in pairs])
    return keys, values


def _nearest(sorted_keys: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Index of the nearest key to each ``x`` (ties to the lower key)."""
    right = np.clip(np.searchsorted(sorted_keys, x), 1, len(sorted_keys) - 1)
    left = right - 1
    if len(sorted_keys) == 1:
        return np.zeros(np.shape(x), dtype=np.intp)
    take_right = np.abs(sorted_keys[right] - x) < np.abs(x - sorted_keys[left])
    return np.where(take_right, right, left)


def _rat_func_inverse(cm: CompuMethod, raw: np.ndarray) -> np.ndarray:
    a, b, c, d, e, f = _coeffs(cm, 6)
    with np.errstate(divide="ignore", invalid="ignore"):
        if a == 0 and d == 0:
            phys = (c - f * raw) / (e * raw - b)
        else:
            phys = _quadratic_root(a - d * raw, b - e * raw, c - f * raw)
    if not np.all(np.isfinite(phys)):
        bad = float(raw[~np.isfinite(phys)].ravel()[0])
        raise InputError(
            f"COMPU_METHOD {cm.name}: RAT_FUNC has no physical value for raw {bad:g}",
            field="a2l",
        )
    return phys


def _quadratic_root(qa: np.ndarray, qb: np.ndarray, qc: np.ndarray) -> np.ndarray:
    """A real root of ``qa·x² + qb·x + qc = 0`` per element (the larger one of two), using
    the cancellation-free form ``q = −(qb + sign(qb)·√disc)/2``, roots ``q/qa`` and ``qc/q``."""
    qa, qb, qc = np.broadcast_arrays(qa, qb, qc)
    disc = qb**2 - 4 * qa * qc
    q = -0.5 * (qb + np.copysign(np.sqrt(disc), qb))
    linear = qa == 0
    r1 = np.where(linear, -qc / qb, q / qa)
    r2 = np.where(linear, r1, qc / q)
    return np.where(np.isfinite(r1) & ((r1 >= r2) | ~np.isfinite(r2)), r1, r2)
