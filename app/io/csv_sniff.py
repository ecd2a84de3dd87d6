"""The layout of a CSV log, read in Python from its first lines: line splitting, comment and
blank lines, the delimiter (and a file that mixes two), the header's names and units, the
optional units row, the decimal mark, and the time column names looked for.

A units row is a second row whose non-empty cells are all non-numeric by :data:`NUMBER`, the
one number syntax of a cell (with a decimal comma, :data:`DECIMAL_COMMA`). The reader that
applies these rules is :mod:`app.io.csv_files`; :mod:`app.io.map_import` sniffs a CSV map's
delimiter and decimal mark here too.
"""

from __future__ import annotations

import csv
import re
from collections import Counter

from app.io.errors import InputError
from app.io.names import check_name
from estimation.errors import SignalError

TIME_COLUMNS = ("time", "time_s", "t", "timestamp", "timestamps")  # the last: asammdf's exports
DELIMITERS = ",;\t"
# The units a time column may be in, and their length in seconds (looked up as written,
# then in lower case; "" is seconds, what a header without a unit means).
TIME_UNITS_S = {
    "": 1.0, "s": 1.0, "sec": 1.0, "secs": 1.0, "second": 1.0, "seconds": 1.0,
    "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "ns": 1e-9,
    "min": 60.0, "h": 3600.0,
}  # fmt: skip
_HEADER_UNIT = re.compile(r"^\s*(?P<name>.+?)\s*\[(?P<unit>[^\]]*)\]\s*$")
DECIMAL_COMMA = re.compile(r"^\s*[+-]?\d+,\d+([eE][+-]?\d+)?\s*$")
_DECIMAL_POINT = re.compile(r"\d\.\d")
# The one number syntax of a cell: plain ASCII digits, sign, point, exponent (and the NaN/inf
# spellings, which the finite check then refuses with its own message). float() alone would
# also take ``1_000``, Arabic-Indic or fullwidth digits and non-ASCII spaces.
NUMBER = re.compile(
    r"\s*[+-]?(?:(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|nan|inf|infinity)\s*",
    re.IGNORECASE | re.ASCII,
)


class LogFormatError(InputError, SignalError):
    """The file is not a usable log; the message names the line and column."""


def split_lines(text: str) -> list[str]:
    """Lines ended by LF, CRLF or CR only: :meth:`str.splitlines` also breaks at U+0085,
    U+2028 and U+2029, which may sit inside a cell (and must then be judged there)."""
    return text.replace("\r\n", "\n").replace("\r", "\n").split("\n")


def content_lines(text: str, first: int = 1) -> list[tuple[int, str]]:
    """Non-blank, non-comment lines with their line numbers (``text`` starting at line
    ``first``)."""
    return [
        (n, ln)
        for n, ln in enumerate(split_lines(text), start=first)
        if ln.strip() and not ln.lstrip().startswith("#")
    ]


_LINE_BREAK = re.compile(r"\r\n|\r|\n")
_LINE_BREAK_BYTES = re.compile(rb"\r\n|\r|\n")


def head_lines(text: str | bytes, count: int) -> list[tuple[int, str, int]]:
    """The first ``count`` content lines (as :func:`content_lines`): line number, text and
    where the next line starts, without splitting the rest of ``text`` (a str, or bytes of
    pure ASCII)."""
    out: list[tuple[int, str, int]] = []
    pos, number = 0, 0
    breaks = _LINE_BREAK if isinstance(text, str) else _LINE_BREAK_BYTES
    while pos < len(text) and len(out) < count:
        match = breaks.search(text, pos)  # type: ignore[arg-type]
        end, after = (match.start(), match.end()) if match else (len(text), len(text))
        number += 1
        part = text[pos:end]
        line = part if isinstance(part, str) else part.decode("ascii")
        if line.strip() and not line.lstrip().startswith("#"):
            out.append((number, line, after))
        pos = after
    return out


def sniff_delimiter(sample_lines: list[str]) -> str:
    """The column delimiter among tab, ``;`` and ``,``.

    First choice: a delimiter that occurs equally often (and at least once) on every sample
    line, preferring tab, then ``;`` (whose files often use a decimal comma, so ``,`` may be
    just as regular), then ``,``; else :class:`csv.Sniffer` (quoted fields); else the one
    most frequent in the header.
    """
    for d in ("\t", ";", ","):
        counts = {line.count(d) for line in sample_lines}
        if len(counts) == 1 and 0 not in counts:
            return d
    try:
        return csv.Sniffer().sniff("\n".join(sample_lines), delimiters=DELIMITERS).delimiter
    except csv.Error:
        header = sample_lines[0]
        counts = {d: header.count(d) for d in DELIMITERS}
        best = max(counts, key=lambda d: counts[d])
        return best if counts[best] else ","


def check_delimiters(sample: list[tuple[int, str]], delimiter: str, header: list[str]) -> None:
    """Refuse a file whose lines are split by different delimiters, naming the line.

    Two signatures: a row that has the header's field count only when split at another
    delimiter; and a header cell holding another delimiter that recurs in exactly the same
    columns of every sampled row (``time,a;b`` over ``0,1;2``) — a decimal comma would put
    commas in the values, never only where the names have them.
    """
    header_line = sample[0][0]
    width = len(header)
    for number, text in sample[1:]:
        if '"' not in text and text.count(delimiter) + 1 != width:
            other = splits_into(text, delimiter, width)
            if other is not None:
                raise LogFormatError(
                    mixed_delimiter_message(number, other, delimiter), field="file", line=number
                )
    for other in DELIMITERS.replace(delimiter, ""):
        in_header = [cell.count(other) for cell in header]
        if not any(in_header) or any('"' in text for _, text in sample):
            continue
        rows = [text.split(delimiter) for _, text in sample[1:]]
        if rows and all(
            len(row) == width and [c.count(other) for c in row] == in_header for row in rows
        ):
            cell = header[next(j for j, n in enumerate(in_header) if n)]
            raise LogFormatError(
                f"line {header_line}: the delimiter is inconsistent: column {cell.strip()!r} "
                f"contains {other!r} though the columns are separated by {delimiter!r} (the "
                f"rows have {other!r} in the same places); use one delimiter throughout",
                field="header",
                line=header_line,
            )


def splits_into(text: str, delimiter: str, width: int) -> str | None:
    """The other delimiter that splits ``text`` into ``width`` fields, if one does."""
    for other in DELIMITERS.replace(delimiter, ""):
        if text.count(other) and text.count(other) + 1 == width:
            return other
    return None


def mixed_delimiter_message(line: int, other: str, delimiter: str) -> str:
    """The message for a row split by ``other`` in a file whose header uses ``delimiter``."""
    return (
        f"line {line}: the delimiter is inconsistent: this row is separated by {other!r}, "
        f"the header by {delimiter!r}; use one delimiter throughout"
    )


def sniff_decimal(rows: list[list[str]], delimiter: str) -> str:
    """The decimal mark of the sampled cells: ``,`` when some cell is a number with a decimal
    comma and none has a decimal point; always ``.`` when ``,`` is the delimiter."""
    if delimiter == ",":
        return "."
    cells = [c for row in rows for c in row]
    comma = any(DECIMAL_COMMA.match(c) for c in cells)
    point = any(_DECIMAL_POINT.search(c) for c in cells)
    return "," if comma and not point else "."


def split_header(header: list[str], line: int) -> tuple[list[str], list[str]]:
    """The column names and the units of ``name [unit]`` header cells (``""`` where none);
    an empty, invalid or repeated name is refused, naming the header's line."""
    names, units = [], []
    for cell in header:
        match = _HEADER_UNIT.match(cell)
        name, unit = (match["name"], match["unit"].strip()) if match else (cell.strip(), "")
        if not name:
            raise LogFormatError(
                f"line {line}: empty column name in the header", field="header", line=line
            )
        try:
            name = check_name(name, field="header", what="column name", line=line)
        except InputError as exc:
            raise LogFormatError(exc.message, field="header", line=line) from None
        names.append(name)
        units.append(unit)
    dupes = sorted(n for n, count in Counter(names).items() if count > 1)
    if dupes:
        raise LogFormatError(
            f"line {line}: duplicate column names {dupes}", field="header", line=line
        )
    return names, units


def is_units_row(cells: list[str]) -> bool:
    """A row with some non-empty cell, none of them a number: the optional units row."""
    filled = [c.strip() for c in cells if c.strip()]
    return bool(filled) and not any(_is_number(c) for c in filled)


def _is_number(text: str) -> bool:
    return NUMBER.fullmatch(text) is not None or DECIMAL_COMMA.match(text) is not None


def time_scale(column: str, unit: str) -> float:
    """Seconds per unit of the time ``column`` written in ``unit`` (:data:`TIME_UNITS_S`);
    a unit that is not a time is refused, naming the column, since reading its numbers as
    seconds would store a log of the wrong length."""
    written = unit.strip()
    scale = TIME_UNITS_S.get(written, TIME_UNITS_S.get(written.lower()))
    if scale is None:
        known = ", ".join(u for u in TIME_UNITS_S if u)
        raise LogFormatError(
            f"time column {column!r} is in {written!r}, not a unit of time ({known})",
            field=column,
        )
    return scale


def time_column_note(time_column: str | None, names: list[str]) -> str | None:
    """The upload's note when more than one column is named like a time base: which one the
    time is, and that the others are kept as channels (never silently)."""
    others = [n for n in names if n in TIME_COLUMNS and n != time_column]
    if time_column is None or not others:
        return None
    listed = ", ".join(repr(n) for n in others)
    return f"time from {time_column!r}; {listed} also named like a time base, kept as a channel"
