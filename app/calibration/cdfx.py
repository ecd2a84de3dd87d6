"""Calibration values as ASAM CDF 2.0 (CDFX) XML.

The structure written (ASAM CDF V2.0.0, the ``MSRSW`` document type)::

    MSRSW
      SHORT-NAME, CATEGORY CDF20
      SW-SYSTEMS / SW-SYSTEM (SHORT-NAME)
        SW-INSTANCE-SPEC / SW-INSTANCE-TREE (SHORT-NAME, CATEGORY NO_VCD)
          SW-INSTANCE                          one per characteristic (and per COM_AXIS)
            SHORT-NAME                         the A2L name
            LONG-NAME                          the description, when there is one
            CATEGORY                           VALUE | CURVE | MAP | VAL_BLK | COM_AXIS
            SW-VALUE-CONT
              UNIT-DISPLAY-NAME
              SW-ARRAYSIZE / V …               VAL_BLK only: the block's shape
              SW-VALUES-PHYS                   V (VALUE, CURVE, VAL_BLK row-major);
                                               MAP: one VG per X point holding V per Y point
            SW-AXIS-CONTS / SW-AXIS-CONT       one per axis, X first
              CATEGORY                         STD_AXIS | FIX_AXIS | COM_AXIS | …
              UNIT-DISPLAY-NAME
              SW-INSTANCE-REF                  COM_AXIS: the AXIS_PTS instance
              SW-VALUES-PHYS / V …             the axis points

Numbers are written with ``repr`` so a file parses back bit-exactly (DCM → CDFX → DCM is
lossless). Reading uses the standard library's ``xml.etree`` and refuses what it cannot
read safely: an internal DTD subset or any ``<!ENTITY`` declaration (entity expansion), and
files over :data:`MAX_BYTES`. An external ``<!DOCTYPE MSRSW PUBLIC …>`` line, as INCA writes
it, is accepted (expat does not fetch it). See ``docs/calibration.md#values``.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from app.calibration.values import CalibrationValues
from app.io.errors import InputError, too_large

if TYPE_CHECKING:
    from app.calibration.model import Characteristic

MAX_BYTES = 64 * 1024 * 1024
_DOCTYPE = re.compile(rb"<!DOCTYPE[^>\[]*(\[)?", re.IGNORECASE)
_VALUE_CATEGORIES = ("VALUE", "CURVE", "MAP", "VAL_BLK", "COM_AXIS")


def write_cdfx(
    items: Sequence[tuple[Characteristic | None, CalibrationValues]], *, name: str = "mapwise"
) -> bytes:
    """The CDFX document of ``items`` (characteristic or ``None``, values)."""
    root = ET.Element("MSRSW")
    _text(root, "SHORT-NAME", name)
    _text(root, "CATEGORY", "CDF20")
    system = ET.SubElement(ET.SubElement(root, "SW-SYSTEMS"), "SW-SYSTEM")
    _text(system, "SHORT-NAME", name)
    tree = ET.SubElement(ET.SubElement(system, "SW-INSTANCE-SPEC"), "SW-INSTANCE-TREE")
    _text(tree, "SHORT-NAME", name)
    _text(tree, "CATEGORY", "NO_VCD")
    shared: dict[str, tuple[np.ndarray, str]] = {}
    for char, vals in items:
        _instance(tree, char, vals, shared)
    for axis_name, (points, unit) in shared.items():
        instance = ET.SubElement(tree, "SW-INSTANCE")
        _text(instance, "SHORT-NAME", axis_name)
        _text(instance, "CATEGORY", "COM_AXIS")
        cont = ET.SubElement(instance, "SW-VALUE-CONT")
        _text(cont, "UNIT-DISPLAY-NAME", unit)
        _numbers(ET.SubElement(cont, "SW-VALUES-PHYS"), points)
    ET.indent(root, space="  ")
    body = ET.tostring(root, encoding="unicode")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + body + "\n").encode("utf-8")


def _instance(
    tree: ET.Element,
    char: Characteristic | None,
    vals: CalibrationValues,
    shared: dict[str, tuple[np.ndarray, str]],
) -> None:
    values = np.asarray(vals.values, dtype=np.float64)
    category = char.type if char is not None else _category(vals)
    instance = ET.SubElement(tree, "SW-INSTANCE")
    _text(instance, "SHORT-NAME", vals.name)
    description = vals.description or (char.description if char is not None else "")
    if description:
        _text(instance, "LONG-NAME", description)
    _text(instance, "CATEGORY", category)
    cont = ET.SubElement(instance, "SW-VALUE-CONT")
    _text(cont, "UNIT-DISPLAY-NAME", vals.unit)
    if category == "VAL_BLK":
        _numbers(ET.SubElement(cont, "SW-ARRAYSIZE"), values.shape, integer=True)
    phys = ET.SubElement(cont, "SW-VALUES-PHYS")
    if values.ndim == 2 and category == "MAP":
        for row in values:
            _numbers(ET.SubElement(phys, "VG"), row)
    else:
        _numbers(phys, values.reshape(-1))
    if not vals.axes:
        return
    conts = ET.SubElement(instance, "SW-AXIS-CONTS")
    for index, points in enumerate(vals.axes):
        axis = char.axes[index] if char is not None else None
        attribute = axis.attribute if axis is not None else _axis_category(vals, index)
        unit = vals.axis_units[index] if index < len(vals.axis_units) else ""
        cont = ET.SubElement(conts, "SW-AXIS-CONT")
        _text(cont, "CATEGORY", attribute)
        _text(cont, "UNIT-DISPLAY-NAME", unit)
        if axis is not None and attribute == "COM_AXIS" and axis.axis_pts_ref:
            _text(cont, "SW-INSTANCE-REF", axis.axis_pts_ref)
            shared.setdefault(axis.axis_pts_ref, (np.asarray(points, dtype=np.float64), unit))
        _numbers(ET.SubElement(cont, "SW-VALUES-PHYS"), points)


def _category(vals: CalibrationValues) -> str:
    return {0: "VALUE" if np.ndim(vals.values) == 0 else "VAL_BLK", 1: "CURVE", 2: "MAP"}.get(
        len(vals.axes), "MAP"
    )


def _axis_category(vals: CalibrationValues, index: int) -> str:
    if index < len(vals.axis_categories) and vals.axis_categories[index]:
        return vals.axis_categories[index]
    return "STD_AXIS"


def _text(parent: ET.Element, tag: str, text: str) -> ET.Element:
    element = ET.SubElement(parent, tag)
    element.text = text
    return element


def _numbers(parent: ET.Element, numbers, *, integer: bool = False) -> None:
    for number in np.asarray(numbers).reshape(-1):
        _text(parent, "V", str(int(number)) if integer else repr(float(number)))


def read_cdfx(data: bytes, *, max_bytes: int = MAX_BYTES) -> dict[str, CalibrationValues]:
    """Every numeric instance (VALUE, CURVE, MAP, VAL_BLK, COM_AXIS) of a CDFX file, by
    SHORT-NAME. A COM_AXIS reference without points of its own takes the referenced
    instance's. Files over ``max_bytes`` are refused."""
    root = _parse(data, max_bytes)
    if _local(root.tag) != "MSRSW":
        raise InputError(f"CDFX root element is <{root.tag}>, not <MSRSW>", field="values")
    instances = [e for e in root.iter() if _local(e.tag) == "SW-INSTANCE"]
    if not instances:
        raise InputError("the CDFX file holds no SW-INSTANCE", field="values")
    found: dict[str, CalibrationValues] = {}
    pending: list[tuple[CalibrationValues, int, str]] = []
    for instance in instances:
        category = _child_text(instance, "CATEGORY")
        if category not in _VALUE_CATEGORIES:
            continue
        vals, refs = _read_instance(instance, category)
        found[vals.name] = vals
        pending += [(vals, index, ref) for index, ref in refs]
    for vals, index, ref in pending:
        if ref not in found:
            raise InputError(
                f"CDFX {vals.name}: axis {'XYZ'[index]} refers to {ref!r}, which the file "
                "does not hold",
                field="values",
            )
        axes = list(vals.axes)
        axes[index] = np.asarray(found[ref].values, dtype=np.float64).reshape(-1)
        vals.axes = tuple(axes)
    return found


def _parse(data: bytes, max_bytes: int) -> ET.Element:
    if len(data) > max_bytes:
        raise too_large(
            f"the CDFX file has {len(data)} bytes; at most {max_bytes} are read", field="values"
        )
    if re.search(rb"<!ENTITY", data, re.IGNORECASE):
        raise InputError(
            "the CDFX file declares XML entities (<!ENTITY>); they are refused for safety",
            field="values",
        )
    doctype = _DOCTYPE.search(data)
    if doctype is not None and doctype.group(1):
        raise InputError(
            "the CDFX file has an internal DTD subset (<!DOCTYPE … [ … ]>); it is refused "
            "for safety",
            field="values",
        )
    try:
        return ET.fromstring(data)
    except ET.ParseError as exc:
        raise InputError(f"the CDFX file is not well-formed XML: {exc}", field="values") from None


def _read_instance(
    instance: ET.Element, category: str
) -> tuple[CalibrationValues, list[tuple[int, str]]]:
    name = _child_text(instance, "SHORT-NAME")
    if not name:
        raise InputError("CDFX: a SW-INSTANCE has no SHORT-NAME", field="values")
    cont = _child(instance, "SW-VALUE-CONT")
    if cont is None:
        raise InputError(f"CDFX {name}: no SW-VALUE-CONT", field="values")
    phys = _child(cont, "SW-VALUES-PHYS")
    if phys is None:
        raise InputError(f"CDFX {name}: no SW-VALUES-PHYS", field="values")
    values = _values(phys, name, category)
    if category == "VAL_BLK":
        size = _child(cont, "SW-ARRAYSIZE")
        if size is not None:
            shape = tuple(int(v) for v in _floats(size, name))
            if int(np.prod(shape)) == values.size:
                values = values.reshape(shape)
    if category == "VALUE":
        if values.size != 1:
            raise InputError(f"CDFX {name}: a VALUE holds {values.size} values", field="values")
        values = values.reshape(())
    axes: list[np.ndarray] = []
    units: list[str] = []
    categories: list[str] = []
    refs: list[tuple[int, str]] = []
    conts = _child(instance, "SW-AXIS-CONTS")
    for index, axis in enumerate(conts if conts is not None else []):
        units.append(_child_text(axis, "UNIT-DISPLAY-NAME"))
        categories.append(_child_text(axis, "CATEGORY") or "STD_AXIS")
        points = _child(axis, "SW-VALUES-PHYS")
        ref = _child_text(axis, "SW-INSTANCE-REF")
        if points is not None and len(points):
            axes.append(np.array(_floats(points, name)))
        elif ref:
            axes.append(np.array([]))
            refs.append((index, ref))
        else:
            raise InputError(
                f"CDFX {name}: axis {'XYZ'[index]} has neither SW-VALUES-PHYS nor SW-INSTANCE-REF",
                field="values",
            )
    vals = CalibrationValues(
        name=name,
        axes=tuple(axes),
        values=values,
        unit=_child_text(cont, "UNIT-DISPLAY-NAME"),
        axis_units=tuple(units),
        description=_child_text(instance, "LONG-NAME"),
        axis_categories=tuple(categories),
    )
    return vals, refs


def _values(phys: ET.Element, name: str, category: str) -> np.ndarray:
    groups = [e for e in phys if _local(e.tag) == "VG"]
    if not groups:
        return np.array(_floats(phys, name))
    rows = [_floats(g, name) for g in groups]
    if len({len(r) for r in rows}) != 1:
        raise InputError(
            f"CDFX {name}: the VG groups of the {category} have different lengths "
            f"{[len(r) for r in rows]}",
            field="values",
        )
    return np.array(rows)


def _floats(parent: ET.Element, name: str) -> list[float]:
    out: list[float] = []
    for element in parent:
        tag = _local(element.tag)
        if tag == "VT":
            raise InputError(
                f"CDFX {name}: verbal values (VT) are not supported; export numeric values",
                field="values",
            )
        if tag != "V":
            continue
        text = (element.text or "").strip()
        try:
            value = float(text)
        except ValueError:
            raise InputError(f"CDFX {name}: non-numeric value {text!r}", field="values") from None
        if not np.isfinite(value):
            raise InputError(
                f"CDFX {name}: {text} is not allowed (values must be finite)", field="values"
            )
        out.append(value)
    return out


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _child(parent: ET.Element, tag: str) -> ET.Element | None:
    return next((e for e in parent if _local(e.tag) == tag), None)


def _child_text(parent: ET.Element, tag: str) -> str:
    element = _child(parent, tag)
    return (element.text or "").strip() if element is not None else ""
