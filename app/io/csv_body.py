"""The body of a CSV log by the Python rules: cells split column by column and converted to
floats, every refusal naming its file line and column.

:mod:`app.io.csv_arrow` reads the body with pyarrow and calls :func:`parse_body` only for a
block pyarrow refused or that holds a value mapwise refuses, so the values and messages of a
log are those of these rules alone (``tests/app/io/test_csv_equivalence.py``). A cell is a
number by :data:`app.io.csv_sniff.NUMBER`. In a sparse column (``allowed_empty``, the
upload path) an empty cell is no sample and a written ``nan``/``inf``/``-inf`` a masked
sample, both NaN, the latter's rows returned apart; elsewhere a non-finite value is refused
(docs/data-formats.md#multi-rate).
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence, Set

import numpy as np

from app.io.csv_sniff import NUMBER, LogFormatError, mixed_delimiter_message, splits_into

CHUNK_ROWS = 20_000
_NO_ROWS = np.empty(0, dtype=np.int64)


def cell_columns(
    body: list[str], lines: list[int], delimiter: str, width: int
) -> list[Sequence[str]]:
    """The body's cells column by column, every row checked to have ``width`` fields.

    Without quote characters the whole body is split at once (fast for long logs);
    otherwise each line goes through :mod:`csv`.
    """
    if not body:
        return [[] for _ in range(width)]
    joined = "\n".join(body)
    if '"' in joined:
        rows = list(csv.reader(body, delimiter=delimiter))
        counts = [len(row) for row in rows]
    else:
        rows = None
        counts = [ln.count(delimiter) + 1 for ln in body]
    for k, count in enumerate(counts):
        if count != width:
            other = None if rows is not None else splits_into(body[k], delimiter, width)
            message = (
                mixed_delimiter_message(lines[k], other, delimiter)
                if other is not None
                else f"line {lines[k]}: {count} fields, header has {width}"
            )
            raise LogFormatError(message, field="file", line=lines[k])
    if rows is not None:
        return [list(col) for col in zip(*rows, strict=True)]
    cells = joined.replace("\n", delimiter).split(delimiter)
    return [cells[j::width] for j in range(width)]


def parse_body(
    body: list[str],
    lines: list[int],
    delimiter: str,
    names: list[str],
    must: Mapping[str, bool],
    decimal: str,
    allowed_empty: Set[str] = frozenset(),
) -> tuple[dict[str, np.ndarray | None], dict[str, np.ndarray]]:
    """The Python rules for a block of the body (:mod:`app.io.csv_arrow` calls this only for
    a block pyarrow refused or that holds a refused value): floats of the columns in
    ``must`` (name → strict), converted :data:`CHUNK_ROWS` rows at a time so that the cells
    held as Python strings stay a small part of the block; a non-strict column that is not
    numeric throughout is ``None``. In a column of ``allowed_empty`` an empty cell is NaN and
    a written non-finite value is NaN too, its row (in the block) listed in the second dict
    (masked samples)."""
    parts: dict[str, list[np.ndarray] | None] = {name: [] for name in must}
    masked: dict[str, list[np.ndarray]] = {}
    for lo in range(0, max(len(body), 1), CHUNK_ROWS):
        chunk_lines = lines[lo : lo + CHUNK_ROWS]
        cells = cell_columns(body[lo : lo + CHUNK_ROWS], chunk_lines, delimiter, len(names))
        for j, name in enumerate(names):
            kept = parts.get(name)
            if kept is None:
                continue
            parsed = _parse_column(
                cells[j],
                chunk_lines,
                name,
                strict=must[name],
                decimal=decimal,
                empty_is_missing=name in allowed_empty,
            )
            if parsed is None:
                parts[name] = None
            else:
                kept.append(parsed[0])
                if parsed[1].size:
                    masked.setdefault(name, []).append(parsed[1] + lo)
    values = {name: None if kept is None else np.concatenate(kept) for name, kept in parts.items()}
    return values, {name: np.concatenate(rows) for name, rows in masked.items()}


def _parse_column(
    cells: Sequence[str],
    lines: list[int],
    name: str,
    *,
    strict: bool,
    decimal: str = ".",
    empty_is_missing: bool = False,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Floats of one column and the rows of its masked samples; ``None`` for a non-numeric
    column when not ``strict``. With ``empty_is_missing`` (a sparse column) an empty cell is
    NaN (no sample) and a written ``nan``/``inf``/``-inf`` is NaN with its row listed (a
    masked sample); otherwise a non-finite value is refused, naming its line.

    The whole column is converted at once; only when that fails is it walked cell by cell
    to name the first bad line.
    """
    texts = [c.replace(",", ".") for c in cells] if decimal == "," else list(cells)
    empty = _empty_cells(texts) if empty_is_missing else None
    if empty is not None:
        texts = ["nan" if e else t for t, e in zip(texts, empty, strict=True)]
    joined = "".join(texts)
    if not joined.isascii() or "_" in joined:  # only then can float() and NUMBER disagree
        k = next((k for k, t in enumerate(texts) if NUMBER.fullmatch(t) is None), None)
        if k is not None and not strict:
            return None
        if k is not None and _looks_numeric(texts[k]):
            raise LogFormatError(
                f"line {lines[k]}, column {name!r}: {cells[k].strip()!r} is not a plain number "
                "(ASCII digits 0-9 with an optional sign, decimal point and exponent; no digit "
                "separators)",
                field=name,
                line=lines[k],
            )
    try:
        out = np.array(texts, dtype=np.float64) if texts else np.empty(0)
    except ValueError:
        out = None
    if out is None:
        if not strict:
            return None
        for k, text in enumerate(texts):
            if NUMBER.fullmatch(text) is None:
                shown = cells[k].strip()
                what = "empty value" if not shown else f"non-numeric value {shown!r}"
                raise LogFormatError(
                    f"line {lines[k]}, column {name!r}: {what}", field=name, line=lines[k]
                )
        out = np.array([float(t) for t in texts])  # numpy and float() disagree: trust float()
    bad = ~np.isfinite(out)
    if empty is not None:
        bad &= ~empty
    if not np.any(bad):
        return out, _NO_ROWS
    if empty_is_missing:
        out[bad] = np.nan
        return out, np.flatnonzero(bad)
    k = int(np.argmax(bad))
    raise LogFormatError(
        f"line {lines[k]}, column {name!r}: {cells[k].strip()} is not allowed "
        "(values must be finite)",
        field=name,
        line=lines[k],
    )


def _empty_cells(texts: list[str]) -> np.ndarray | None:
    """Where the cells are empty (blank), or ``None`` when none is."""
    empty = np.fromiter((not t.strip() for t in texts), dtype=bool, count=len(texts))
    return empty if empty.any() else None


def _looks_numeric(text: str) -> bool:
    """Python would read ``text`` as a number (``1_000``, ``١٢``): worth its own message."""
    try:
        float(text)
    except ValueError:
        return False
    return True
