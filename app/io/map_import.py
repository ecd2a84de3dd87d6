"""Import a starting map (e.g. the production calibration) from JSON, CSV or DCM.

- JSON: the ``mapwise adapt`` map document (:func:`app.io.map_json.map_document`) or any object
  with ``axes: [{"name", "unit", "breakpoints"}]`` and nested ``values``.
- CSV: the grid layout of :func:`app.io.export.map_to_csv` (corner ``row axis [unit] \\
  column axis [unit]``), or two columns for a 1-D map; delimiter ``, ; tab`` sniffed.
- DCM: a ``KENNLINIE`` / ``KENNFELD`` block (:mod:`app.io.dcm`).

Errors are :class:`~app.io.errors.InputError` naming the line, cell or JSON path.
"""

from __future__ import annotations

import csv
import json
import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from app.io.csv_sniff import sniff_decimal, sniff_delimiter
from app.io.errors import InputError, unsupported
from estimation.errors import ShapeError
from estimation.table import Axis, Table

_FORMULA_PREFIXES = ("=", "+", "-", "@", "\t", "\r")
_LABEL = re.compile(r"^\s*(?P<name>.+?)\s*(?:\[(?P<unit>[^\]]*)\])?\s*$")
_DCM = re.compile(r"^\s*(KONSERVIERUNG_FORMAT|(GRUPPEN|FEST)?KENN(FELD|LINIE))\b", re.MULTILINE)
_BINARY = re.compile(r"[\x00-\x08\x0b\x0e-\x1f\x7f]")


def import_map(data: bytes | str, *, name: str | None = None) -> Table:
    """A table from JSON, DCM or CSV, told apart by content (never by a filename)."""
    text = _decode(data)
    if text.lstrip().startswith("{"):
        return map_from_json(text)
    if _DCM.search(text):
        from app.io.dcm import map_from_dcm

        return map_from_dcm(text, name=name)[2]
    return map_from_csv(text)


def _decode(data: bytes | str) -> str:
    if isinstance(data, str):
        text = data
    else:
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError:
            text = data.decode("latin-1")
    if not text.strip():
        raise InputError("empty map file", field="file")
    if _BINARY.search(text):
        raise unsupported("binary data: a map file is JSON, CSV or DCM text")
    return text


def map_from_json(data: bytes | str | Mapping[str, Any]) -> Table:
    """A table from the ``mapwise adapt`` document or ``{"axes", "values"}``."""
    if isinstance(data, Mapping):
        document: Any = data
    else:
        text = _decode(data)
        try:
            document = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(
                f"line {exc.lineno}, column {exc.colno}: invalid JSON ({exc.msg})",
                field="file",
                line=exc.lineno,
            ) from None
        except RecursionError:
            raise InputError("the JSON document is nested too deeply", field="file") from None
    if not isinstance(document, Mapping):
        raise InputError("a map document is a JSON object with 'axes' and 'values'", field="file")
    axes_doc = document.get("axes")
    if not isinstance(axes_doc, list) or not axes_doc:
        raise InputError("'axes' must be a non-empty list", field="axes")
    axes = []
    for i, a in enumerate(axes_doc):
        if not isinstance(a, Mapping):
            raise InputError("an axis is an object {name, unit, breakpoints}", field=f"axes[{i}]")
        name, unit, breakpoints = a.get("name"), a.get("unit", ""), a.get("breakpoints")
        if not isinstance(name, str) or not name:
            raise InputError("axis name must be a non-empty string", field=f"axes[{i}].name")
        if not isinstance(unit, str):
            raise InputError("axis unit must be a string", field=f"axes[{i}].unit")
        if not isinstance(breakpoints, list) or not all(_is_number(b) for b in breakpoints):
            raise InputError(
                "breakpoints must be a list of numbers", field=f"axes[{i}].breakpoints"
            )
        try:
            axes.append(Axis(name, unit, breakpoints))
        except ShapeError as exc:
            raise InputError(str(exc), field=f"axes[{i}].breakpoints") from None
    if "values" not in document:
        raise InputError("the map document has no 'values'", field="values")
    values = document["values"]
    bad = _first_non_number(values, "values")
    if bad is not None:
        raise InputError(f"{bad[0]}: {bad[1]!r} is not a number", field=bad[0])
    try:
        array = np.array(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(
            "values must be a nested list of numbers shaped like the axes", field="values"
        ) from None
    try:
        return Table(axes, array)
    except ShapeError as exc:
        raise InputError(str(exc), field="values" if "values" in str(exc) else "axes") from None


def _first_non_number(value: Any, path: str) -> tuple[str, Any] | None:
    """Path and value of the first leaf of a nested list that is not a JSON number."""
    if isinstance(value, list):
        for i, item in enumerate(value):
            found = _first_non_number(item, f"{path}[{i}]")
            if found is not None:
                return found
        return None
    return None if _is_number(value) else (path, value)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def map_from_csv(data: bytes | str) -> Table:
    """A table from the CSV grid layout (2-D) or two columns (1-D)."""
    text = _decode(data)
    lines = [
        (n, ln)
        for n, ln in enumerate(text.splitlines(), start=1)
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if len(lines) < 3:
        raise InputError("a CSV map needs a header row and at least two rows", field="file")
    delimiter = sniff_delimiter([ln for _, ln in lines[:20]])
    rows = list(csv.reader([ln for _, ln in lines], delimiter=delimiter))
    numbers = [n for n, _ in lines]
    decimal = sniff_decimal(rows[1:20], delimiter)
    corner = _unneutralise(rows[0][0])
    width = len(rows[0])
    for k, row in enumerate(rows):
        if len(row) != width:
            raise InputError(
                f"line {numbers[k]}: {len(row)} fields, the header has {width}",
                field=f"line {numbers[k]}",
                line=numbers[k],
            )
    grid = np.empty((len(rows) - 1, width - 1))
    first = np.empty(len(rows) - 1)
    for k, row in enumerate(rows[1:], start=1):
        first[k - 1] = _cell(row[0], numbers[k], 1, decimal)
        for j, cell in enumerate(row[1:], start=2):
            grid[k - 1, j - 2] = _cell(cell, numbers[k], j, decimal)
    if "\\" in corner:
        left, _, right = corner.partition("\\")
        row_axis = _axis(left, first, "axes[0]", numbers[0])
        column_breakpoints = np.array(
            [_cell(c, numbers[0], j, decimal) for j, c in enumerate(rows[0][1:], start=2)]
        )
        col_axis = _axis(right, column_breakpoints, "axes[1]", numbers[0])
        return _table([row_axis, col_axis], grid)
    if width != 2:
        raise InputError(
            f"line {numbers[0]}: the first cell must name both axes as "
            "'row_axis [unit] \\ column_axis [unit]' (a 1-D map has two columns)",
            field=f"line {numbers[0]}",
            line=numbers[0],
        )
    return _table([_axis(corner, first, "axes[0]", numbers[0])], grid[:, 0])


def _unneutralise(cell: str) -> str:
    """Undo the export's formula guard (``'=x`` → ``=x``)."""
    if cell.startswith("'") and cell[1:].startswith(_FORMULA_PREFIXES):
        return cell[1:]
    return cell


def _cell(text: str, line: int, column: int, decimal: str) -> float:
    shown = text.strip()
    try:
        value = float(shown.replace(",", ".") if decimal == "," else shown)
    except ValueError:
        what = "empty cell" if not shown else f"non-numeric value {shown!r}"
        raise InputError(
            f"line {line}, column {column}: {what}", field=f"line {line}", line=line
        ) from None
    if not np.isfinite(value):
        raise InputError(
            f"line {line}, column {column}: {shown} is not allowed (values must be finite)",
            field=f"line {line}",
            line=line,
        )
    return value


def _axis(label: str, breakpoints: np.ndarray, field: str, line: int) -> Axis:
    match = _LABEL.match(_unneutralise(label.strip()))
    if not match:
        raise InputError(
            f"line {line}: empty axis name in {label!r}", field=f"{field}.name", line=line
        )
    try:
        return Axis(match["name"], (match["unit"] or "").strip(), breakpoints)
    except ShapeError as exc:
        raise InputError(str(exc), field=f"{field}.breakpoints", line=line) from None


def _table(axes: list[Axis], values: np.ndarray) -> Table:
    try:
        return Table(axes, values)
    except ShapeError as exc:
        raise InputError(str(exc), field="axes") from None
