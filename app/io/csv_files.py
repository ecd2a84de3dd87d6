"""Read drive logs from CSV into :class:`estimation.Signals`.

Accepted layout: one header row (delimiter sniffed among ``, ; tab``); units either in the
header as ``name [unit]`` or in an optional second row whose non-empty cells are all
non-numeric; lines starting with ``#`` are comments. Only the requested columns must be
numeric; every problem is reported with its file line and column name.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from estimation import Signals
from estimation.errors import SignalError

TIME_COLUMNS = ("time", "time_s", "t", "timestamp")
_HEADER_UNIT = re.compile(r"^\s*(?P<name>.+?)\s*\[(?P<unit>[^\]]*)\]\s*$")


class LogFormatError(SignalError):
    """The file is not a usable log; the message names the line and column."""


@dataclass(frozen=True, slots=True)
class CsvLog:
    """A loaded log and the column its time base came from (``None``: sample index)."""

    signals: Signals
    time_column: str | None


def read_csv(
    path: str | Path,
    *,
    columns: Sequence[str] | None = None,
    time_column: str | None = None,
) -> CsvLog:
    """Load ``columns`` (default: every numeric column) of a CSV log.

    The time base is ``time_column`` (seconds), else the first of :data:`TIME_COLUMNS`
    present, else the sample index (unit ``sample``, 1 Hz nominal).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise LogFormatError(f"{path}: no such file") from None
    except UnicodeDecodeError as exc:
        raise LogFormatError(f"{path}: not a UTF-8 text file ({exc.reason})") from None
    rows = _rows(text)
    if not rows:
        raise LogFormatError(f"{path}: empty file, expected a header row")
    header_line, header = rows[0]
    names, units = _split_header(header, header_line)
    body = rows[1:]
    if body and _is_units_row(body[0][1]):
        line, cells = body[0]
        if len(cells) != len(names):
            raise LogFormatError(
                f"line {line}: units row has {len(cells)} fields, header has {len(names)}"
            )
        units = [u.strip() or h for u, h in zip(cells, units, strict=True)]
        body = body[1:]
    for line, cells in body:
        if len(cells) != len(names):
            raise LogFormatError(f"line {line}: {len(cells)} fields, header has {len(names)}")
    if time_column is None:
        time_column = next((c for c in TIME_COLUMNS if c in names), None)
    elif time_column not in names:
        raise LogFormatError(f"time column {time_column!r} not in the file; columns: {names}")
    wanted = list(columns) if columns is not None else None
    if wanted is not None:
        missing = [c for c in wanted if c not in names]
        if missing:
            raise LogFormatError(
                f"missing column{'s' if len(missing) > 1 else ''} "
                f"{', '.join(repr(c) for c in missing)}; the file has {names}"
            )
    lines = [line for line, _ in body]
    parsed: dict[str, np.ndarray] = {}
    for j, name in enumerate(names):
        if name == time_column or (wanted is not None and name not in wanted):
            continue
        column = [cells[j] for _, cells in body]
        values = _parse_column(column, lines, name, strict=wanted is not None)
        if values is not None:
            parsed[name] = values
    if time_column is not None:
        j = names.index(time_column)
        time = _parse_column([c[j] for _, c in body], lines, time_column, strict=True)
        assert time is not None
    else:
        time = np.arange(len(body), dtype=np.float64)
    try:
        signals = Signals(time, parsed, dict(zip(names, units, strict=True)))
    except SignalError as exc:
        raise LogFormatError(_with_line(str(exc), lines)) from None
    return CsvLog(signals, time_column)


def _rows(text: str) -> list[tuple[int, list[str]]]:
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), start=1)]
    content = [(n, ln) for n, ln in lines if ln.strip() and not ln.lstrip().startswith("#")]
    if not content:
        return []
    sample = "\n".join(ln for _, ln in content[:20])
    try:
        dialect: type[csv.Dialect] | csv.Dialect = csv.Sniffer().sniff(sample, delimiters=",;\t")
    except csv.Error:
        dialect = csv.excel
    out = []
    for n, ln in content:
        cells = next(csv.reader([ln], dialect))
        out.append((n, cells))
    return out


def _split_header(header: list[str], line: int) -> tuple[list[str], list[str]]:
    names, units = [], []
    for cell in header:
        match = _HEADER_UNIT.match(cell)
        name, unit = (match["name"], match["unit"].strip()) if match else (cell.strip(), "")
        if not name:
            raise LogFormatError(f"line {line}: empty column name in the header")
        names.append(name)
        units.append(unit)
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise LogFormatError(f"line {line}: duplicate column names {dupes}")
    return names, units


def _is_units_row(cells: list[str]) -> bool:
    filled = [c.strip() for c in cells if c.strip()]
    return bool(filled) and not any(_is_number(c) for c in filled)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _parse_column(
    cells: list[str], lines: list[int], name: str, *, strict: bool
) -> np.ndarray | None:
    """Floats of one column; ``None`` for a non-numeric column when not ``strict``."""
    out = np.empty(len(cells))
    for k, cell in enumerate(cells):
        text = cell.strip()
        try:
            value = float(text)
        except ValueError:
            if not strict:
                return None
            what = "empty value" if not text else f"non-numeric value {text!r}"
            raise LogFormatError(f"line {lines[k]}, column {name!r}: {what}") from None
        if not math.isfinite(value):
            raise LogFormatError(
                f"line {lines[k]}, column {name!r}: {text} is not allowed (values must be finite)"
            )
        out[k] = value
    return out


def _with_line(message: str, lines: list[int]) -> str:
    """Rewrite ``at sample k`` in a Signals error as the file line."""
    match = re.search(r"at sample (\d+)", message)
    if match and int(match[1]) < len(lines):
        return message.replace(match[0], f"at line {lines[int(match[1])]}")
    return message


def write_csv(signals: Signals, path: str | Path, *, time_column: str = "time") -> None:
    """Write a log readable by :func:`read_csv`: header ``name [unit]``, time first, values
    with 17 significant digits (they round-trip exactly)."""
    names = signals.names
    if time_column in names:
        raise LogFormatError(f"a channel is already called {time_column!r}")
    header = [f"{time_column} [s]"] + [
        f"{n} [{signals.units[n]}]" if signals.units.get(n) else n for n in names
    ]
    columns = np.column_stack([signals.time, *(signals[n] for n in names)])
    with Path(path).open("w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(header)
        writer.writerows([[repr(float(v)) for v in row] for row in columns])
