"""ASAM MCD-2 MC data types as numpy dtypes.

A RECORD_LAYOUT names the storage type of every item (``FNC_VALUES 1 SWORD ROW_DIR DIRECT``)
and the characteristic or module names the byte order (``BYTE_ORDER MSB_LAST``). ASAM's
``MSB_FIRST`` is big-endian (Motorola), ``MSB_LAST`` little-endian (Intel); the deprecated
spellings ``BIG_ENDIAN``/``LITTLE_ENDIAN`` mean the same respectively. See
``docs/calibration.md#values``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.io.errors import InputError

_CODES = {
    "UBYTE": "u1",
    "SBYTE": "i1",
    "UWORD": "u2",
    "SWORD": "i2",
    "ULONG": "u4",
    "SLONG": "i4",
    "A_UINT64": "u8",
    "A_INT64": "i8",
    "FLOAT16_IEEE": "f2",
    "FLOAT32_IEEE": "f4",
    "FLOAT64_IEEE": "f8",
}
_ORDERS = {"MSB_FIRST": ">", "BIG_ENDIAN": ">", "MSB_LAST": "<", "LITTLE_ENDIAN": "<"}


@dataclass(frozen=True, slots=True)
class DataType:
    """One ASAM data type in one byte order."""

    name: str
    dtype: np.dtype

    @property
    def size(self) -> int:
        return self.dtype.itemsize

    @property
    def is_integer(self) -> bool:
        return self.dtype.kind in "iu"

    @property
    def min(self) -> float:
        """Smallest storable value (the most negative finite float for IEEE types)."""
        if self.is_integer:
            return float(np.iinfo(self.dtype).min)
        return float(np.finfo(self.dtype).min)

    @property
    def max(self) -> float:
        if self.is_integer:
            return float(np.iinfo(self.dtype).max)
        return float(np.finfo(self.dtype).max)

    def decode(self, raw: bytes, count: int) -> np.ndarray:
        """``count`` consecutive values from ``raw`` as float64."""
        return np.frombuffer(raw, dtype=self.dtype, count=count).astype(np.float64)

    def encode(self, values: np.ndarray) -> bytes:
        """Values already rounded and saturated to this type, as bytes."""
        return np.asarray(values).astype(self.dtype).tobytes()


def datatype(name: str, byte_order: str = "MSB_LAST", *, what: str = "") -> DataType:
    """The :class:`DataType` of an ASAM data type name and byte order.

    ``what`` names the characteristic for the error message of an unknown type.
    """
    code = _CODES.get(name)
    order = _ORDERS.get(byte_order)
    where = f"{what}: " if what else ""
    if code is None:
        raise InputError(
            f"{where}data type {name!r} is not supported (one of {', '.join(_CODES)})",
            field="a2l",
        )
    if order is None:
        raise InputError(
            f"{where}byte order {byte_order!r} is not MSB_FIRST or MSB_LAST", field="a2l"
        )
    return DataType(name, np.dtype(order + code))
