"""Exports of maps and time series (CSV here; DCM and MCAP beside it) and map imports.

CSV map layout (what spreadsheets and calibration engineers expect)::

    u1 [rpm] \\ u2 [mg/stroke],0.0,20.0,40.0      ← corner: row axis \\ column axis
    500.0,1.0,1.5,2.5                            ← breakpoint of axis 1, then its row
    1500.0,2.0,2.5,3.5

A 1-D map is two columns, ``u1 [rpm],value [unit]``. Numbers are written with ``repr`` —
the shortest text that parses back to the identical float, negatives and ``-0.0``
included — and any *string* cell starting with ``= + - @``, tab or CR is prefixed with
``'`` so a spreadsheet shows it as text instead of running it as a formula (OWASP CSV
injection). The importers (:mod:`app.io.map_import`) undo that prefix.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Mapping

import numpy as np

from app.io.dcm import map_from_dcm, map_to_dcm, maps_to_dcm
from app.io.errors import InputError
from app.io.map_import import import_map, map_from_csv, map_from_json
from app.io.mcap_export import MapVersionRecord, run_to_mcap
from estimation.table import Axis, Table

FORMULA_PREFIXES = ("=", "+", "-", "@", "\t", "\r")

__all__ = [
    "MapVersionRecord",
    "axis_label",
    "format_number",
    "import_map",
    "map_from_csv",
    "map_from_dcm",
    "map_from_json",
    "map_to_csv",
    "map_to_dcm",
    "maps_to_dcm",
    "neutralise",
    "run_to_mcap",
    "series_to_csv",
]


def neutralise(cell: str) -> str:
    """``cell`` made inert for spreadsheets: a leading ``'`` if it starts like a formula."""
    return "'" + cell if cell.startswith(FORMULA_PREFIXES) else cell


def format_number(x: float) -> str:
    """The shortest decimal text of ``x`` that parses back to the same float (``repr``).

    ``float(format_number(x)) == x`` for every finite ``x`` (sign of zero included);
    non-finite values are written explicitly as ``nan``, ``inf``, ``-inf``.
    """
    return repr(float(x))


def axis_label(axis: Axis) -> str:
    """``name [unit]`` (``name`` alone without a unit)."""
    return f"{axis.name} [{axis.unit}]" if axis.unit else axis.name


def map_to_csv(table: Table, *, value_name: str = "value", value_unit: str = "") -> str:
    """A 1-D or 2-D map as CSV text (layout in the module docstring)."""
    if table.ndim == 1:
        (axis,) = table.axes
        value = f"{value_name} [{value_unit}]" if value_unit else value_name
        rows: Iterable[list[str]] = [
            [neutralise(axis_label(axis)), neutralise(value)],
            *(
                [format_number(b), format_number(v)]
                for b, v in zip(axis.breakpoints, table.values, strict=True)
            ),
        ]
    elif table.ndim == 2:
        rows_axis, cols_axis = table.axes
        corner = f"{axis_label(rows_axis)} \\ {axis_label(cols_axis)}"
        rows = [
            [neutralise(corner), *(format_number(b) for b in cols_axis.breakpoints)],
            *(
                [format_number(b), *(format_number(v) for v in row)]
                for b, row in zip(rows_axis.breakpoints, table.values, strict=True)
            ),
        ]
    else:
        raise InputError(
            f"CSV export holds 1-D and 2-D maps; this one has {table.ndim} axes", field="table"
        )
    return _write_rows(rows)


def series_to_csv(
    time_s: np.ndarray,
    channels: Mapping[str, tuple[str, np.ndarray]],
    *,
    time_name: str = "time",
) -> str:
    """Time series as CSV: header ``time [s]``, ``name [unit]`` …, then one row per sample.

    Readable back by :func:`app.io.ingest.ingest` (values identical).
    """
    time_s = np.asarray(time_s, dtype=np.float64)
    header = [neutralise(f"{time_name} [s]")]
    columns = [time_s]
    for name, (unit, values) in channels.items():
        values = np.asarray(values, dtype=np.float64)
        if values.shape != time_s.shape:
            raise InputError(
                f"series {name!r} has {values.size} values, time has {time_s.size}", field=name
            )
        header.append(neutralise(f"{name} [{unit}]" if unit else name))
        columns.append(values)
    body = np.column_stack(columns).tolist() if time_s.size else []
    template = ",".join(["%r"] * len(columns)) + "\n"  # %r of a float is format_number
    return _write_rows([header]) + "".join(template % tuple(row) for row in body)


def _write_rows(rows: Iterable[list[str]]) -> str:
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows(rows)
    return out.getvalue()
