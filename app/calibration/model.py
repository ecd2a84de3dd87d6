"""What an A2L (ASAM MCD-2 MC) says about a calibration object, as plain frozen data.

The A2L import (:mod:`app.calibration.a2l`) builds these from pya2ldb's database; the
values layer decodes memory images with them. Everything is resolved at import time, so a
consumer needs no A2L lookups of its own:

- a :class:`Characteristic` carries its :class:`RecordLayout` and :class:`CompuMethod`
  objects (not just their names) and its effective byte order (the characteristic's own
  ``BYTE_ORDER``, else ``MOD_COMMON``'s, else ``MSB_LAST``);
- a :class:`RecordLayout` carries every positioned item with its ASAM datatype and the
  effective ``ALIGNMENT_*`` (the layout's own, else ``MOD_COMMON``'s, else the natural size
  of the type);
- an :class:`AxisDescr` carries its unit and conversion (a ``COM_AXIS``/``CURVE_AXIS``
  with ``NO_COMPU_METHOD`` takes the referenced object's) and, for ``FIX_AXIS``, the axis
  values expanded from ``FIX_AXIS_PAR``/``FIX_AXIS_PAR_DIST``/``FIX_AXIS_PAR_LIST``.

Array orientation follows mapwise tables: ``shape`` lists the number of points per axis in
axis order (X, then Y), so a MAP's values are ``values[i_x, i_y]``. See
``docs/calibration.md#a2l-import``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

#: Sizes in bytes of the ASAM datatypes (ASAM MCD-2 MC ``datatype`` enumeration).
DATATYPE_SIZES: dict[str, int] = {
    "UBYTE": 1,
    "SBYTE": 1,
    "UWORD": 2,
    "SWORD": 2,
    "ULONG": 4,
    "SLONG": 4,
    "A_UINT64": 8,
    "A_INT64": 8,
    "FLOAT16_IEEE": 2,
    "FLOAT32_IEEE": 4,
    "FLOAT64_IEEE": 8,
}

#: The ``ALIGNMENT_*`` keyword that governs each datatype.
ALIGNMENT_KEYS: dict[str, str] = {
    "UBYTE": "BYTE",
    "SBYTE": "BYTE",
    "UWORD": "WORD",
    "SWORD": "WORD",
    "ULONG": "LONG",
    "SLONG": "LONG",
    "A_UINT64": "INT64",
    "A_INT64": "INT64",
    "FLOAT16_IEEE": "FLOAT16_IEEE",
    "FLOAT32_IEEE": "FLOAT32_IEEE",
    "FLOAT64_IEEE": "FLOAT64_IEEE",
}

CHARACTERISTIC_TYPES = ("VALUE", "CURVE", "MAP", "VAL_BLK")


@dataclass(frozen=True)
class CompuMethod:
    """A ``COMPU_METHOD``: the conversion from the ECU's raw value to the physical one.

    ``kind`` and what it uses:

    - ``IDENTICAL``: phys = raw (also ``NO_COMPU_METHOD``).
    - ``LINEAR``: ``coeffs = (a, b)``, phys = a*raw + b.
    - ``RAT_FUNC``: ``coeffs = (a, b, c, d, e, f)`` with raw = (a*p² + b*p + c) / (d*p² +
      e*p + f), p the physical value (ASAM's direction: physical → internal).
    - ``TAB_INTP`` / ``TAB_NOINTP``: ``table = ((raw, phys), ...)`` from ``COMPU_TAB``,
      interpolated or not; ``default_value`` for raw values outside it.
    - ``TAB_VERB``: ``verbal = ((raw, text), ...)`` from ``COMPU_VTAB`` and/or
      ``verbal_ranges = ((raw_lo, raw_hi, text), ...)`` from ``COMPU_VTAB_RANGE``;
      ``default_text`` otherwise. The physical value of a verbal entry is its raw value.
    - ``FORM``: ``formula`` (``X1`` is the raw value) and ``formula_inv``.
    - ``UNDEFINED``: the A2L references this COMPU_METHOD without defining it (refuse to
      convert with it).
    """

    name: str
    kind: str
    unit: str = ""
    format: str = ""
    coeffs: tuple[float, ...] = ()
    table: tuple[tuple[float, float], ...] = ()
    verbal: tuple[tuple[float, str], ...] = ()
    verbal_ranges: tuple[tuple[float, float, str], ...] = ()
    default_value: float | None = None
    default_text: str | None = None
    formula: str = ""
    formula_inv: str = ""

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "unit": self.unit, "format": self.format}


#: The conversion of objects that have none (``NO_COMPU_METHOD``).
IDENTICAL = CompuMethod(name="NO_COMPU_METHOD", kind="IDENTICAL")


@dataclass(frozen=True)
class LayoutItem:
    """One positioned entry of a ``RECORD_LAYOUT``.

    ``kind`` is the A2L keyword with its axis letter, e.g. ``FNC_VALUES``, ``AXIS_PTS_X``,
    ``NO_AXIS_PTS_Y``, ``AXIS_RESCALE_X``, ``NO_RESCALE_X``, ``SRC_ADDR_X``,
    ``RIP_ADDR_W``, ``OFFSET_X``, ``SHIFT_OP_X``, ``DIST_OP_X``, ``IDENTIFICATION`` or
    ``RESERVED`` (a ``RESERVED`` BYTE/WORD/LONG/LONG64 is given as UBYTE/UWORD/ULONG/
    A_UINT64). ``index_mode`` is ``ROW_DIR``/``COLUMN_DIR``/``ALTERNATE_*`` for
    ``FNC_VALUES`` and ``INDEX_INCR``/``INDEX_DECR`` for ``AXIS_PTS_*``/``AXIS_RESCALE_*``;
    ``addressing`` is ``DIRECT``/``PBYTE``/``PWORD``/``PLONG`` where the keyword has one.
    """

    kind: str
    position: int
    datatype: str
    index_mode: str = ""
    addressing: str = ""

    @property
    def size(self) -> int:
        return DATATYPE_SIZES[self.datatype]


@dataclass(frozen=True)
class RecordLayout:
    """A ``RECORD_LAYOUT``: how a characteristic's or axis' record sits in memory.

    The record is ``items`` in ``position`` order, each aligned to
    :meth:`alignment_of` its datatype. ``fix_no_axis_pts`` holds ``FIX_NO_AXIS_PTS_X/Y/…``
    as ``(("X", n), ...)``; ``alignment`` the effective ``ALIGNMENT_*`` borders as
    ``(("BYTE", 1), ("WORD", 2), ...)``. ``defined`` is false when the A2L references the
    layout without defining it (the stripped ASAM demo in the pya2ldb wheel does): such a
    layout has no items, listing still works and decoding values refuses it
    (``docs/calibration.md#a2l-import``).
    """

    name: str
    items: tuple[LayoutItem, ...] = ()
    fix_no_axis_pts: tuple[tuple[str, int], ...] = ()
    alignment: tuple[tuple[str, int], ...] = ()
    static_record_layout: bool = False
    static_address_offsets: bool = False
    defined: bool = True

    def item(self, kind: str) -> LayoutItem | None:
        return next((i for i in self.items if i.kind == kind), None)

    @property
    def fnc_values(self) -> LayoutItem | None:
        return self.item("FNC_VALUES")

    def axis_pts(self, axis: str) -> LayoutItem | None:
        """``AXIS_PTS_<axis>`` (axis ``"X"``, ``"Y"``, …)."""
        return self.item(f"AXIS_PTS_{axis}")

    def no_axis_pts(self, axis: str) -> LayoutItem | None:
        """``NO_AXIS_PTS_<axis>``: the stored actual number of axis points."""
        return self.item(f"NO_AXIS_PTS_{axis}")

    def fixed_points(self, axis: str) -> int | None:
        """``FIX_NO_AXIS_PTS_<axis>``, when the layout fixes the number of points."""
        return dict(self.fix_no_axis_pts).get(axis)

    def alignment_of(self, datatype: str) -> int:
        """Alignment border in bytes for ``datatype`` (natural size when unspecified)."""
        return dict(self.alignment).get(ALIGNMENT_KEYS[datatype], DATATYPE_SIZES[datatype])


@dataclass(frozen=True)
class AxisDescr:
    """One ``AXIS_DESCR`` of a CURVE/MAP, in axis order (X first).

    ``attribute`` is ``STD_AXIS``, ``FIX_AXIS``, ``COM_AXIS``, ``RES_AXIS`` or
    ``CURVE_AXIS``. ``fix_axis_values`` are the physical axis values of a ``FIX_AXIS``
    (``FIX_AXIS_PAR offset shift n``: offset + i·2^shift; ``FIX_AXIS_PAR_DIST offset dist
    n``: offset + i·dist; ``FIX_AXIS_PAR_LIST``: as listed), ``None`` for other axes or when
    the A2L gives no parameters. ``axis_pts_ref`` names the ``AXIS_PTS`` of a
    ``COM_AXIS``/``RES_AXIS``, ``curve_axis_ref`` the CURVE of a ``CURVE_AXIS``.
    """

    attribute: str
    input_quantity: str
    unit: str
    compu_method: CompuMethod
    max_axis_points: int
    lower: float
    upper: float
    fix_axis_values: tuple[float, ...] | None = None
    axis_pts_ref: str | None = None
    curve_axis_ref: str | None = None
    deposit: str = "ABSOLUTE"

    @property
    def points(self) -> int:
        if self.fix_axis_values is not None:
            return len(self.fix_axis_values)
        return self.max_axis_points

    def to_json(self) -> dict[str, Any]:
        values = list(self.fix_axis_values) if self.fix_axis_values is not None else None
        return {
            "attribute": self.attribute,
            "input_quantity": self.input_quantity,
            "unit": self.unit,
            "points": self.points,
            "limits": [self.lower, self.upper],
            "values": values,
            "compu_method": self.compu_method.to_json(),
            "axis_pts_ref": self.axis_pts_ref,
            "curve_axis_ref": self.curve_axis_ref,
        }


@dataclass(frozen=True)
class AxisPts:
    """An ``AXIS_PTS``: axis points stored on their own, shared by ``COM_AXIS`` users."""

    name: str
    address: int
    input_quantity: str
    record_layout: RecordLayout
    compu_method: CompuMethod
    max_points: int
    lower: float
    upper: float
    byte_order: str
    description: str = ""
    datatype: str = ""
    deposit: str = "ABSOLUTE"
    ecu_address_extension: int = 0

    @property
    def unit(self) -> str:
        return self.compu_method.unit


@dataclass(frozen=True)
class Characteristic:
    """A ``CHARACTERISTIC`` of type VALUE, CURVE, MAP or VAL_BLK.

    ``datatype`` is the ``FNC_VALUES`` datatype of its record layout; ``shape`` is ``()``
    for a VALUE, the points per axis for CURVE/MAP, ``MATRIX_DIM`` (trailing 1s dropped)
    or ``(NUMBER,)`` for a VAL_BLK. ``lower``/``upper`` are the physical limits.
    """

    name: str
    description: str
    type: str
    address: int
    record_layout: RecordLayout
    compu_method: CompuMethod
    lower: float
    upper: float
    datatype: str
    byte_order: str
    axes: tuple[AxisDescr, ...] = ()
    number: int | None = None
    shape: tuple[int, ...] = ()
    phys_unit: str = ""
    bit_mask: int | None = None
    extended_limits: tuple[float, float] | None = None
    ecu_address_extension: int = 0
    display_identifier: str = ""

    @property
    def unit(self) -> str:
        """``PHYS_UNIT`` when given, else the conversion's unit."""
        return self.phys_unit or self.compu_method.unit

    def to_json(self) -> dict[str, Any]:
        """The REST summary (``docs/calibration.md#a2l-import``)."""
        return {
            "name": self.name,
            "description": self.description,
            "type": self.type,
            "unit": self.unit,
            "datatype": self.datatype,
            "limits": [self.lower, self.upper],
            "compu_method": self.compu_method.to_json(),
            "record_layout": self.record_layout.name,
            "address": self.address,
            "byte_order": self.byte_order,
            "shape": list(self.shape),
            "axes": [axis.to_json() for axis in self.axes],
        }
