"""Characteristic values in an Intel HEX or Motorola S-record memory image.

A characteristic's record starts at its ``address`` and holds the items of its
RECORD_LAYOUT in ``position`` order (ASAM MCD-2 MC, RECORD_LAYOUT), each aligned to the
``ALIGNMENT_*`` border of its data type:

* ``NO_AXIS_PTS_X/Y``: the actual number of points of an axis stored in the record;
* ``AXIS_PTS_X/Y``: the axis points (``INDEX_INCR``: ascending index with ascending
  address, ``INDEX_DECR``: the reverse);
* ``FNC_VALUES``: the values. For 2-D data ``COLUMN_DIR`` stores X fastest (column-major
  of ``values[i_x, i_y]``), ``ROW_DIR`` stores Y fastest, as pya2ldb's ``fnc_np_order``;
* anything else (``RESERVED``, ``IDENTIFICATION``, ``SRC_ADDR_*`` …) is one element that is
  skipped.

Without ``STATIC_RECORD_LAYOUT`` the record is compact: an axis with a stored point count
takes that many elements. With it, every axis reserves its maximum. Numbers have the
characteristic's byte order (``MSB_FIRST`` big-, ``MSB_LAST`` little-endian) and convert
with its COMPU_METHOD (:mod:`app.calibration.conversions`).

Axis points come from the record (``STD_AXIS``), from the ``AXIS_PTS`` object at its own
address (``COM_AXIS``) or from the A2L (``FIX_AXIS``). ``RES_AXIS`` and ``CURVE_AXIS``
(rescaled axes) are given over their point indices ``0 … n−1``.

:func:`patch_image` rewrites only the data records that hold the characteristic's bytes,
in place (:func:`app.calibration.memory_image.write_patches`): every other line of the file
stays as it was, and the changed lines keep their length and record type (only their data
and checksum change). The image's bytes by address are
:class:`app.calibration.memory_image.Memory`. See ``docs/calibration.md#values``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from app.calibration.conversions import to_physical, to_raw
from app.calibration.datatypes import DataType, datatype
from app.calibration.memory_image import Memory, write_patches
from app.calibration.quantize import quantize
from app.calibration.values import CalibrationValues
from app.io.errors import InputError

if TYPE_CHECKING:
    from app.calibration.a2l import A2lFile
    from app.calibration.model import AxisDescr, AxisPts, Characteristic, RecordLayout

LETTERS = "XYZ"
_SKIPPED_KINDS = ("RESERVED", "IDENTIFICATION", "SRC_ADDR_", "RIP_ADDR_", "SHIFT_OP_", "OFFSET_")
_INDEX_AXES = ("RES_AXIS", "CURVE_AXIS")


@dataclass(frozen=True)
class Span:
    """One located item of a record: ``count`` elements of ``dt`` from ``address``."""

    kind: str
    address: int
    count: int
    dt: DataType
    index_mode: str = ""

    @property
    def size(self) -> int:
        return self.count * self.dt.size


def decode_image(a2l: A2lFile, char: Characteristic, image: bytes) -> CalibrationValues:
    """The physical values and axis points of ``char`` in the HEX/S19 ``image``."""
    memory = Memory(image, char.name)
    record = _record(a2l, char, memory)
    raw = _read(memory, record.fnc, char.name)
    if char.bit_mask is not None and record.fnc.dt.is_integer:
        raw = _masked(raw, char.bit_mask)
    values = to_physical(char.compu_method, _shape(raw, record, char))
    return CalibrationValues(
        name=char.name,
        axes=tuple(record.axes),
        values=values,
        unit=char.unit,
        axis_units=tuple(axis.unit for axis in char.axes),
        axis_names=tuple(axis.input_quantity for axis in char.axes),
        description=char.description,
        axis_categories=tuple(axis.attribute for axis in char.axes),
    )


def patch_image(
    a2l: A2lFile, char: Characteristic, values: CalibrationValues, image: bytes
) -> bytes:
    """A copy of ``image`` (same format) with ``values`` written into ``char``'s record.

    Values are quantised first (:func:`app.calibration.quantize.quantize`: clamped to the
    limits, rounded to the data type). Axis points stored in the record (``STD_AXIS``) are
    rewritten too; the number of points cannot change, and axes stored elsewhere
    (``COM_AXIS``) or fixed by the A2L must equal the image's."""
    memory = Memory(image, char.name)
    record = _record(a2l, char, memory)
    expected = tuple(len(points) for points in record.axes) or record.shape
    got = np.shape(values.values)
    if got != expected:
        raise InputError(
            f"characteristic {char.name}: values have shape {got}, the image holds {expected}",
            field="values",
        )
    patches: list[tuple[int, bytes]] = []
    for index, axis in enumerate(char.axes):
        patches += _axis_patch(char, axis, index, record, values)
    order = "F" if record.fnc.index_mode == "COLUMN_DIR" else "C"
    raw = quantize(char, values.values).raw.reshape(-1, order=order)
    if char.bit_mask is not None and record.fnc.dt.is_integer:
        raw = _unmasked(raw, _read(memory, record.fnc, char.name), char.bit_mask)
    patches.append((record.fnc.address, record.fnc.dt.encode(raw)))
    return write_patches(image, memory.format, patches)


@dataclass
class _Record:
    fnc: Span
    axes: list[np.ndarray]
    axis_spans: dict[str, Span]
    shape: tuple[int, ...]


def _record(a2l: A2lFile, char: Characteristic, memory: Memory) -> _Record:
    """Locate every item of ``char``'s record and decode its axes."""
    what = f"characteristic {char.name}"
    layout = _defined_layout(char.record_layout, what)
    if char.type not in ("VALUE", "CURVE", "MAP", "VAL_BLK"):
        raise InputError(f"{what}: type {char.type} is not supported", field="map")
    counts: dict[str, int] = {}
    maxima: dict[str, int] = {}
    external: dict[int, np.ndarray] = {}
    for index, axis in enumerate(char.axes):
        letter = LETTERS[index]
        maxima[letter] = axis.max_axis_points
        points = _external_axis(a2l, char, axis, index, memory)
        if points is not None:
            external[index] = points
            counts[letter] = len(points)
        elif layout.fixed_points(letter) is not None:
            counts[letter] = int(layout.fixed_points(letter) or 0)
        elif layout.no_axis_pts(letter) is None:
            counts[letter] = axis.max_axis_points

    def fnc_count(static: bool) -> int:
        if char.axes:
            source = maxima if static else counts
            return math.prod(source[LETTERS[i]] for i in range(len(char.axes)))
        return math.prod(_block_shape(char))

    spans = _walk(layout, char.address, char.byte_order, memory, counts, maxima, fnc_count, what)
    if "FNC_VALUES" not in spans:
        raise InputError(f"{what}: RECORD_LAYOUT {layout.name} has no FNC_VALUES", field="a2l")
    axes: list[np.ndarray] = []
    for index, axis in enumerate(char.axes):
        if index in external:
            axes.append(external[index])
            continue
        span = spans.get(f"AXIS_PTS_{LETTERS[index]}")
        if span is None:
            raise InputError(
                f"{what}: axis {LETTERS[index]} ({axis.input_quantity}) is a STD_AXIS but "
                f"RECORD_LAYOUT {layout.name} has no AXIS_PTS_{LETTERS[index]}",
                field="a2l",
            )
        axes.append(to_physical(axis.compu_method, _read(memory, span, what)))
    shape = tuple(len(a) for a in axes) if axes else _block_shape(char)
    return _Record(spans["FNC_VALUES"], axes, spans, shape)


def _defined_layout(layout: RecordLayout, what: str) -> RecordLayout:
    if not layout.defined or not layout.items:
        raise InputError(
            f"{what}: RECORD_LAYOUT '{layout.name}' is not defined in the A2L", field="a2l"
        )
    return layout


def _block_shape(char: Characteristic) -> tuple[int, ...]:
    if char.type == "VALUE":
        return ()
    return tuple(char.shape) or ((char.number,) if char.number else (1,))


def _walk(
    layout: RecordLayout,
    address: int,
    byte_order: str,
    memory: Memory,
    counts: dict[str, int],
    maxima: dict[str, int],
    fnc_count: Callable[[bool], int],
    what: str,
) -> dict[str, Span]:
    """Every item of ``layout`` located from ``address``; stored point counts
    (``NO_AXIS_PTS_*``) are read from ``memory`` on the way and put into ``counts``."""
    static = layout.static_record_layout
    spans: dict[str, Span] = {}
    cursor = address
    for item in sorted(layout.items, key=lambda i: i.position):
        dt = datatype(item.datatype, byte_order, what=what)
        border = layout.alignment_of(item.datatype)
        cursor += -cursor % border
        kind = item.kind
        if kind.startswith("NO_AXIS_PTS_"):
            letter = kind[-1]
            span = Span(kind, cursor, 1, dt)
            stored = int(_read(memory, span, what)[0])
            limit = maxima.get(letter, stored)
            if not 1 <= stored <= limit:
                raise InputError(
                    f"{what}: the image stores {stored} points for axis {letter} "
                    f"(at 0x{cursor:X}); the A2L allows 1–{limit}",
                    field="values",
                )
            counts.setdefault(letter, stored)
            reserved = 1
        elif kind.startswith("AXIS_PTS_"):
            letter = kind[-1]
            if letter not in counts:
                raise InputError(
                    f"{what}: RECORD_LAYOUT {layout.name} has {kind} but the characteristic "
                    f"has no axis {letter}",
                    field="a2l",
                )
            span = Span(kind, cursor, counts[letter], dt, item.index_mode)
            reserved = maxima.get(letter, counts[letter]) if static else counts[letter]
        elif kind == "FNC_VALUES":
            span = Span(kind, cursor, fnc_count(False), dt, item.index_mode)
            reserved = fnc_count(True) if static else span.count
        elif kind.startswith(_SKIPPED_KINDS) or kind.startswith("DIST_OP_"):
            span = Span(kind, cursor, 1, dt)
            reserved = 1
        else:
            raise InputError(
                f"{what}: RECORD_LAYOUT {layout.name} item {kind} is not supported", field="a2l"
            )
        spans[kind] = span
        cursor += reserved * dt.size
    return spans


def _read(memory: Memory, span: Span, what: str) -> np.ndarray:
    """The span's numbers in index order (``INDEX_DECR`` reversed)."""
    raw = memory.read(span.address, span.size, f"{what} ({span.kind})")
    values = span.dt.decode(raw, span.count)
    return values[::-1].copy() if span.index_mode == "INDEX_DECR" else values


def _masked(raw: np.ndarray, mask: int) -> np.ndarray:
    """``(raw & mask) >> shift``, ``shift`` the mask's trailing zero bits (ASAM BIT_MASK)."""
    shift = (mask & -mask).bit_length() - 1
    return ((raw.astype(np.int64) & mask) >> shift).astype(np.float64)


def _unmasked(raw: np.ndarray, stored: np.ndarray, mask: int) -> np.ndarray:
    """``raw`` placed into the mask's bits of the ``stored`` numbers, other bits kept."""
    shift = (mask & -mask).bit_length() - 1
    kept = stored.astype(np.int64) & ~mask
    return (kept | ((raw.astype(np.int64) << shift) & mask)).astype(np.float64)


def _shape(raw: np.ndarray, record: _Record, char: Characteristic) -> np.ndarray:
    if not record.shape:
        return raw.reshape(())
    order = "F" if record.fnc.index_mode == "COLUMN_DIR" else "C"
    if math.prod(record.shape) != raw.size:
        raise InputError(
            f"characteristic {char.name}: {raw.size} values for shape {record.shape}",
            field="a2l",
        )
    return raw.reshape(record.shape, order=order)


def _external_axis(
    a2l: A2lFile, char: Characteristic, axis: AxisDescr, index: int, memory: Memory
) -> np.ndarray | None:
    """Axis points that are not in the characteristic's record (None for a STD_AXIS)."""
    letter = LETTERS[index]
    where = f"characteristic {char.name}: axis {letter} ({axis.input_quantity})"
    if axis.attribute == "STD_AXIS":
        return None
    if axis.attribute == "FIX_AXIS":
        points = axis_points_from_a2l(a2l, char, index)
        if points is None:
            raise InputError(
                f"{where} is a FIX_AXIS without FIX_AXIS_PAR/_PAR_DIST/_PAR_LIST in the A2L",
                field="a2l",
            )
        return points
    if axis.attribute == "COM_AXIS":
        return _com_axis(a2l, axis, memory, where)
    if axis.attribute in _INDEX_AXES:
        return np.arange(axis.max_axis_points, dtype=np.float64)
    raise InputError(f"{where}: axis type {axis.attribute} is not supported", field="a2l")


def _com_axis(a2l: A2lFile, axis: AxisDescr, memory: Memory, where: str) -> np.ndarray:
    ref = axis.axis_pts_ref
    pts = a2l.axis_pts.get(ref or "")
    if pts is None:
        raise InputError(f"{where}: AXIS_PTS {ref!r} is not in the A2L", field="a2l")
    span = _com_axis_span(pts, memory, where)
    return to_physical(pts.compu_method, _read(memory, span, where))


def _com_axis_span(pts: AxisPts, memory: Memory, where: str) -> Span:
    layout = _defined_layout(pts.record_layout, f"{where}: AXIS_PTS {pts.name}")
    counts: dict[str, int] = {}
    if layout.no_axis_pts("X") is None:
        counts["X"] = layout.fixed_points("X") or pts.max_points
    spans = _walk(
        layout,
        pts.address,
        pts.byte_order,
        memory,
        counts,
        {"X": pts.max_points},
        lambda static: 0,
        f"{where}: AXIS_PTS {pts.name}",
    )
    span = spans.get("AXIS_PTS_X")
    if span is None:
        raise InputError(
            f"{where}: AXIS_PTS {pts.name}: RECORD_LAYOUT {layout.name} has no AXIS_PTS_X",
            field="a2l",
        )
    return span


def expected_points(a2l: A2lFile, char: Characteristic, index: int) -> tuple[int | None, int]:
    """``(exact, maximum)`` number of points of axis ``index`` by the A2L: ``exact`` when the
    A2L fixes it (FIX_AXIS parameters, ``FIX_NO_AXIS_PTS``, a layout without a stored count,
    or an index axis), else ``None``."""
    axis = char.axes[index]
    letter = LETTERS[index]
    fixed = axis_points_from_a2l(a2l, char, index)
    if fixed is not None:
        return len(fixed), len(fixed)
    if axis.attribute in _INDEX_AXES:
        return axis.max_axis_points, axis.max_axis_points
    layout, maximum = char.record_layout, axis.max_axis_points
    if axis.attribute == "COM_AXIS":
        pts = a2l.axis_pts.get(axis.axis_pts_ref or "")
        if pts is None:
            return None, maximum
        layout, maximum, letter = pts.record_layout, pts.max_points, "X"
    if not layout.defined or not layout.items:
        return None, maximum
    if layout.fixed_points(letter) is not None:
        return layout.fixed_points(letter), maximum
    if layout.no_axis_pts(letter) is None and layout.axis_pts(letter) is not None:
        return maximum, maximum
    return None, maximum


def axis_points_from_a2l(a2l: A2lFile, char: Characteristic, index: int) -> np.ndarray | None:
    """The points the A2L itself fixes for axis ``index`` (a FIX_AXIS), else None."""
    axis = char.axes[index]
    if axis.attribute == "FIX_AXIS" and axis.fix_axis_values is not None:
        return np.array(axis.fix_axis_values, dtype=np.float64)
    return None


def _axis_patch(
    char: Characteristic,
    axis: AxisDescr,
    index: int,
    record: _Record,
    values: CalibrationValues,
) -> list[tuple[int, bytes]]:
    letter = LETTERS[index]
    where = f"characteristic {char.name}: axis {letter} ({axis.input_quantity})"
    new = np.asarray(values.axes[index], dtype=np.float64) if index < len(values.axes) else None
    current = record.axes[index]
    if new is None or new.shape != current.shape:
        got = None if new is None else len(new)
        raise InputError(
            f"{where} has {got} points, the image holds {len(current)}", field="values"
        )
    span = record.axis_spans.get(f"AXIS_PTS_{letter}")
    if axis.attribute != "STD_AXIS" or span is None:
        if not np.allclose(new, current, rtol=1e-9, atol=1e-12):
            raise InputError(
                f"{where} is a {axis.attribute}; its points {current.tolist()} cannot be "
                f"changed by writing this map (got {new.tolist()})",
                field="values",
            )
        return []
    raw = to_raw(axis.compu_method, new, span.dt)
    if span.index_mode == "INDEX_DECR":
        raw = raw[::-1]
    return [(span.address, span.dt.encode(raw))]
