"""A characteristic's current values from a memory image, a DCM or a CDFX file.

:class:`CalibrationValues` holds physical values in axis order (X first, so a MAP's values
are ``values[i_x, i_y]``, as in mapwise tables). :func:`read_values` takes them from

* an Intel HEX or Motorola S-record image, decoded with the A2L's RECORD_LAYOUT, byte order
  and COMPU_METHOD (:mod:`app.calibration.image`);
* a DCM 2.0 file (``KENNLINIE``/``KENNFELD`` blocks named after the A2L characteristic,
  :mod:`app.io.dcm`);
* a CDFX file (ASAM CDF 2.0, :mod:`app.calibration.cdfx`).

Axis points read from DCM or CDFX must agree with the A2L: the number of points of every
axis, and the values of a ``FIX_AXIS``. Whatever the format, every value must lie within
the characteristic's limits and every STD_AXIS/COM_AXIS point within its axis' limits
(:func:`check_limits`), else the file is refused naming the cell. See
``docs/calibration.md#values``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np

from app.io.errors import InputError, unsupported

if TYPE_CHECKING:
    from app.calibration.a2l import A2lFile
    from app.calibration.model import Characteristic
    from app.calibration.quantize import Quantized

ValuesFormat = Literal["hex", "s19", "dcm", "cdfx"]
FORMATS: tuple[str, ...] = ("hex", "s19", "dcm", "cdfx")
# Tolerance for comparing FIX_AXIS points given in a file with the A2L's (relative).
_AXIS_RTOL = 1e-9
# Relative slack of the limits check: a value decoded through a conversion may miss a limit
# on the raw grid by float round-off (the slack of app.calibration.quantize).
_LIMIT_RTOL = 1e-12
# Axes whose points the file gives in physical units (RES_AXIS/CURVE_AXIS: point indices;
# FIX_AXIS: the A2L's own points, checked against it by check_against_a2l).
_CHECKED_AXES = ("STD_AXIS", "COM_AXIS")


@dataclass
class CalibrationValues:
    """Physical values of one characteristic and of its axes.

    ``values`` has shape ``tuple(len(a) for a in axes)`` for a CURVE/MAP, ``()`` for a VALUE
    and the block's shape for a VAL_BLK (no axes). ``axis_names`` are the axes' input
    quantities when known.
    """

    name: str
    axes: tuple[np.ndarray, ...]
    values: np.ndarray
    unit: str = ""
    axis_units: tuple[str, ...] = ()
    axis_names: tuple[str, ...] = ()
    description: str = ""
    axis_categories: tuple[str, ...] = field(default=())

    def to_json(self) -> dict[str, object]:
        """``{axes, values, unit, axis_units}`` with nested lists (the REST ``values``)."""
        return {
            "axes": [np.asarray(a).tolist() for a in self.axes],
            "values": np.asarray(self.values).tolist(),
            "unit": self.unit,
            "axis_units": list(self.axis_units),
        }


def detect_values_format(data: bytes) -> ValuesFormat:
    """``"hex"`` (Intel HEX: lines start with ``:``), ``"s19"`` (Motorola S-records: lines
    start with ``S0``–``S9``), ``"cdfx"`` (XML) or ``"dcm"`` (DAMOS text with
    ``KONSERVIERUNG_FORMAT`` or its blocks)."""
    head = data[:4096].lstrip(b"\xef\xbb\xbf \t\r\n")
    if head.startswith(b":") and _all_lines_start(head, (b":",)):
        return "hex"
    if head[:1] == b"S" and head[1:2].isdigit() and _all_lines_start(head, (b"S",)):
        return "s19"
    if head.startswith(b"<"):
        return "cdfx"
    text = head.decode("latin-1")
    if any(k in text for k in ("KONSERVIERUNG_FORMAT", "KENNFELD", "KENNLINIE", "FESTWERT")):
        return "dcm"
    raise unsupported(
        "the values file is not Intel HEX, Motorola S-record, DCM or CDFX", field="values"
    )


def _all_lines_start(head: bytes, prefixes: tuple[bytes, ...]) -> bool:
    lines = [line.strip() for line in head.splitlines()[:-1] if line.strip()]
    return all(line.startswith(prefixes) for line in lines)


def read_values(a2l: A2lFile, char: Characteristic, data: bytes) -> CalibrationValues:
    """The current values of ``char`` from a HEX, S19, DCM or CDFX file (format detected)."""
    # cdfx and image import this module for CalibrationValues, hence the late imports.
    from app.calibration import cdfx, image

    fmt = detect_values_format(data)
    if fmt in ("hex", "s19"):
        return check_limits(char, image.decode_image(a2l, char, data), source=fmt.upper())
    if fmt == "dcm" and char.type not in ("CURVE", "MAP"):
        raise InputError(
            f"characteristic {char.name}: DCM values are read for CURVEs and MAPs "
            f"(KENNLINIE/KENNFELD), not for a {char.type}",
            field="values",
        )
    found = cdfx.read_cdfx(data) if fmt == "cdfx" else read_dcm_values(data)
    if char.name not in found:
        raise InputError(
            f"no characteristic {char.name!r} in the {fmt.upper()} file "
            f"(it holds {sorted(found)[:20]})",
            field="values",
        )
    checked = check_against_a2l(a2l, char, found[char.name], source=fmt.upper())
    return check_limits(char, checked, source=fmt.upper())


def check_limits(
    char: Characteristic, values: CalibrationValues, *, source: str
) -> CalibrationValues:
    """``values`` if every value lies in ``[char.lower, char.upper]`` and every point of a
    STD_AXIS or COM_AXIS in its axis' ``[lower, upper]`` (ASAM MCD-2 MC LowerLimit /
    UpperLimit, with a relative slack of 1e-12 for conversion round-off), else an
    InputError (field ``values``) naming the characteristic, the cell or axis point, the
    value and the limit. A NaN is outside every limit. The limits are those a learned map
    is clamped to on write (:mod:`app.calibration.quantize`), so a base map read from an
    ECU is one the ECU may hold (docs/calibration.md#values)."""
    where = f"{source} {char.name}"
    array = np.asarray(values.values, dtype=np.float64)
    problem = _outside(array, char.lower, char.upper)
    if problem is not None:
        index, value, limit = problem
        cell = f"cell {index}" if array.ndim else "the value"
        count = int(np.count_nonzero(_outside_mask(array, char.lower, char.upper)))
        more = f" ({count} values outside)" if count > 1 else ""
        raise InputError(
            f"{where}: {cell} is {value!r}, {limit} [{char.lower:g}, {char.upper:g}]{more}",
            field="values",
        )
    for i, (axis, points) in enumerate(zip(char.axes, values.axes, strict=False)):
        if axis.attribute not in _CHECKED_AXES:
            continue
        found = _outside(np.asarray(points, dtype=np.float64), axis.lower, axis.upper)
        if found is not None:
            index, value, limit = found
            raise InputError(
                f"{where}: axis {'XYZ'[i]} ({axis.input_quantity}) point {index[0]} is "
                f"{value!r}, {limit} the axis [{axis.lower:g}, {axis.upper:g}]",
                field="values",
            )
    return values


def _outside_mask(array: np.ndarray, lower: float, upper: float) -> np.ndarray:
    slack = _LIMIT_RTOL * max(abs(lower), abs(upper), 1.0)
    return ~((array >= lower - slack) & (array <= upper + slack))  # NaN: outside


def _outside(
    array: np.ndarray, lower: float, upper: float
) -> tuple[tuple[int, ...], float, str] | None:
    """The first element outside ``[lower, upper]``: its index, value and which limit."""
    bad = _outside_mask(array, lower, upper)
    if not np.any(bad):
        return None
    index = tuple(int(i) for i in np.argwhere(bad)[0])
    value = float(array[index])
    limit = (
        "not a number, outside the limits"
        if np.isnan(value)
        else "below the lower limit of"
        if value < lower
        else "above the upper limit of"
    )
    return index, value, limit


def read_dcm_values(data: bytes | str) -> dict[str, CalibrationValues]:
    """Every KENNLINIE/KENNFELD of a DCM file, by name."""
    from app.io.dcm import decode_text, parse_dcm

    out: dict[str, CalibrationValues] = {}
    for block in parse_dcm(decode_text(data)):
        curve = not block.y
        axes = (np.array(block.x),) if curve else (np.array(block.x), np.array(block.y))
        values = np.array(block.rows[0]) if curve else np.array(block.rows).T
        letters = "X" if curve else "XY"
        out[block.name] = CalibrationValues(
            name=block.name,
            axes=axes,
            values=values,
            unit=block.units.get("W", ""),
            axis_units=tuple(block.units.get(k, "") for k in letters),
            axis_names=tuple(block.axis_names.get(k, "") for k in letters),
            description=block.description,
        )
    return out


def check_against_a2l(
    a2l: A2lFile, char: Characteristic, values: CalibrationValues, *, source: str
) -> CalibrationValues:
    """``values`` if their shape and axes agree with the A2L, else an InputError naming the
    characteristic and the axis. Missing units and axis names are filled from the A2L."""
    from app.calibration.image import axis_points_from_a2l, expected_points

    where = f"{source} {char.name}"
    want_ndim = len(char.axes)
    if len(values.axes) != want_ndim:
        raise InputError(
            f"{where}: {len(values.axes)} axes, the A2L {char.type} has {want_ndim}",
            field="values",
        )
    for index, (axis, points) in enumerate(zip(char.axes, values.axes, strict=True)):
        letter = "XYZ"[index]
        expected = axis_points_from_a2l(a2l, char, index)
        exact, n_max = expected_points(a2l, char, index)
        if exact is not None and len(points) != exact:
            raise InputError(
                f"{where}: axis {letter} ({axis.input_quantity}) has {len(points)} points, "
                f"the A2L {axis.attribute} has {exact}",
                field="values",
            )
        if not 1 <= len(points) <= n_max:
            raise InputError(
                f"{where}: axis {letter} ({axis.input_quantity}) has {len(points)} points, "
                f"the A2L allows at most {n_max}",
                field="values",
            )
        if (
            axis.attribute == "FIX_AXIS"
            and expected is not None
            and not np.allclose(points, expected, rtol=_AXIS_RTOL, atol=0.0)
        ):
            raise InputError(
                f"{where}: axis {letter} ({axis.input_quantity}) points "
                f"{np.asarray(points).tolist()} differ from the A2L FIX_AXIS "
                f"{np.asarray(expected).tolist()}",
                field="values",
            )
    shape = tuple(len(a) for a in values.axes)
    if want_ndim and np.shape(values.values) != shape:
        raise InputError(
            f"{where}: values have shape {np.shape(values.values)}, the axes {shape}",
            field="values",
        )
    return CalibrationValues(
        name=char.name,
        axes=tuple(np.asarray(a, dtype=np.float64) for a in values.axes),
        values=np.asarray(values.values, dtype=np.float64),
        unit=values.unit or char.unit,
        axis_units=tuple(
            (values.axis_units[i] if i < len(values.axis_units) else "") or axis.unit
            for i, axis in enumerate(char.axes)
        ),
        axis_names=tuple(axis.input_quantity for axis in char.axes),
        description=values.description or char.description,
        axis_categories=tuple(axis.attribute for axis in char.axes),
    )


def learned_values(
    char: Characteristic,
    axes: Sequence[Sequence[float] | np.ndarray],
    values: np.ndarray,
    *,
    strict: bool = False,
) -> tuple[CalibrationValues, Quantized]:
    """A learned map as ``char``'s values, quantised to what the ECU holds
    (:func:`app.calibration.quantize.quantize`), ready for :func:`write_dcm`,
    :func:`app.calibration.cdfx.write_cdfx` or :func:`app.calibration.image.patch_image`;
    with the :class:`~app.calibration.quantize.Quantized` report (error per cell)."""
    from app.calibration.quantize import quantize

    if len(axes) != len(char.axes):
        raise InputError(
            f"characteristic {char.name}: the map has {len(axes)} axes, the A2L {char.type} "
            f"has {len(char.axes)}",
            field="map",
        )
    quantized = quantize(char, values, strict=strict)
    vals = CalibrationValues(
        name=char.name,
        axes=tuple(np.asarray(a, dtype=np.float64) for a in axes),
        values=quantized.values,
        unit=char.unit,
        axis_units=tuple(axis.unit for axis in char.axes),
        axis_names=tuple(axis.input_quantity for axis in char.axes),
        description=char.description,
        axis_categories=tuple(axis.attribute for axis in char.axes),
    )
    return vals, quantized


def write_dcm(items: Sequence[tuple[Characteristic | None, CalibrationValues]]) -> str:
    """CURVEs and MAPs as one DCM 2.0 file keyed by their names (A2L names when linked);
    axis names are the A2L input quantities. A characteristic with a ``COM_AXIS`` is
    written as a ``GRUPPENKENNLINIE``/``GRUPPENKENNFELD``, one with only ``FIX_AXIS`` axes
    as a ``FESTKENNLINIE``/``FESTKENNFELD``."""
    from app.io.dcm import DcmBlock, blocks_to_dcm

    blocks = []
    for char, vals in items:
        if char is not None:
            names = tuple(a.input_quantity for a in char.axes)
            attributes = {a.attribute for a in char.axes}
        else:
            names = vals.axis_names or ("x", "y")[: len(vals.axes)]
            attributes = set(vals.axis_categories)
        prefix = (
            "GRUPPEN" if "COM_AXIS" in attributes else "FEST" if attributes == {"FIX_AXIS"} else ""
        )
        axes = [
            (names[i] or "xy"[i], unit, points)
            for i, (unit, points) in enumerate(zip(_units(vals), vals.axes, strict=True))
        ]
        description = vals.description or (char.description if char is not None else "")
        blocks.append(
            DcmBlock(vals.name, axes, np.asarray(vals.values), vals.unit, description, prefix)
        )
    return blocks_to_dcm(blocks)


def _units(vals: CalibrationValues) -> tuple[str, ...]:
    return tuple(vals.axis_units) + ("",) * (len(vals.axes) - len(vals.axis_units))
