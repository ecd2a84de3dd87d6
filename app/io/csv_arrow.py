"""The body of a CSV log, column by column, with :mod:`pyarrow.csv` — the fast path of
:mod:`app.io.csv_files`.

The text after the header (and units row) is cut at line ends into blocks of about
:data:`BLOCK_CHARS` characters; each block is parsed by ``pyarrow.csv.read_csv`` (C++,
multi-threaded over :data:`ARROW_BLOCK_BYTES` sub-blocks) straight into float64 columns and
appended to the result, so the memory beyond the parsed columns is about one block. Comment
and blank lines are dropped from a block before pyarrow sees it (pyarrow has no comment
syntax).

pyarrow's number syntax is a subset of mapwise's (:data:`app.io.csv_sniff.NUMBER`: ASCII
digits, sign, point, exponent; no ``1_000``, no other digits) and both round correctly, so a
value pyarrow accepts is the value Python reads. Whenever pyarrow refuses a block (a cell it
cannot read, a row with the wrong field count) or the block holds something that mapwise
refuses although pyarrow read it (an empty cell where none is allowed, ``nan``, ``inf`` in
a column that is not sparse), that one block is read again by the Python rules
(:func:`app.io.csv_body.parse_body`), which either give its values (a cell only Python
accepts, such as a decimal point in a decimal-comma file) or the error naming the file line
and column. Line numbers are worked out only then: the fast path never splits the text into
Python lines.

In a sparse column (``allowed_empty``: the upload path) a written ``nan``/``inf``/``-inf``
is a masked sample: NaN in the column, its row listed in :attr:`Body.masked`, read on the
fast path as by the Python rules (docs/data-formats.md#multi-rate).
"""

from __future__ import annotations

import bisect
import re
from collections.abc import Callable, Mapping, Set
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from app.io.arrow_arrays import float64_values, valid_rows
from app.io.csv_body import parse_body
from app.io.csv_sniff import content_lines

BLOCK_CHARS = 4 << 20  # text per block handed to pyarrow: the memory beyond the columns
ARROW_BLOCK_BYTES = 1 << 20  # pyarrow's own block: the unit its threads parse in parallel
# A whole comment or blank line (after a lone CR has been made a LF): the lines
# `content_lines` leaves out. `\s` of a str pattern is str.isspace(), as in str.strip().
_SKIP_LINE = re.compile(r"^[^\S\n]*(?:#[^\n]*)?(?:\n|\Z)", re.MULTILINE)
_LF = {str: "\n", bytes: b"\n"}
_PAREN = {str: "(", bytes: b"("}


@dataclass(frozen=True, slots=True)
class Body:
    """The body's columns (``None``: a non-strict column that is not numeric throughout),
    its row count, the file line of a row (``line_of(k)``, 1-based, for messages) and, per
    sparse column that has any, the rows of its masked samples (a written non-finite
    value: NaN in ``values`` like an empty cell, but a sample)."""

    values: dict[str, np.ndarray | None]
    rows: int
    line_of: Callable[[int], int]
    masked: dict[str, np.ndarray] = field(default_factory=dict)


def read_body(
    text: str | bytes,
    start: int,
    *,
    delimiter: str,
    names: list[str],
    must: Mapping[str, bool],
    decimal: str,
    allowed_empty: Set[str] = frozenset(),
) -> Body:
    """Floats of the columns in ``must`` (name → strict) of the data rows in
    ``text[start:]`` (a str, or bytes of pure ASCII), by the rules of
    :func:`app.io.csv_body.parse_body`."""
    active = dict(must)  # the columns still read: a non-strict one leaves when found textual
    columns: dict[str, _Column | None] = {name: _Column() for name in must}
    blocks: list[tuple[int, int, int]] = []  # text start, text end, first row
    masked_rows: dict[str, list[np.ndarray]] = {}  # per block, rows counted from the start
    rows = 0
    pos = start
    while pos < len(text):
        end = text.find(_LF[type(text)], pos + BLOCK_CHARS)  # type: ignore[arg-type]
        end = len(text) if end < 0 else end + 1
        block = text[pos:end]
        got = arrow_block(block, delimiter, names, active, decimal, allowed_empty)
        if got is None:  # the error path: Python rules, exact values or messages
            numbered = content_lines(_str(block), _line_number(text, pos))
            body = [ln for _, ln in numbered]
            lines = [n for n, _ in numbered]
            parsed, masked = parse_body(
                body, lines, delimiter, names, active, decimal, allowed_empty
            )
            values = {name: None if v is None else [v] for name, v in parsed.items()}
            got = values, masked, len(lines)
        values, masked, count = got
        for name, where in masked.items():
            masked_rows.setdefault(name, []).append(where + rows)
        # rows still to come, from this block's rows per character: one allocation per column
        expected = int(count / max(len(block), 1) * (len(text) - end) * 1.02) + 64
        for name, chunks in values.items():
            column = columns[name]
            if chunks is None:  # a non-strict column with text: dropped from here on
                columns[name] = None
                del active[name]
            elif column is not None:
                column.extend(chunks, expected)
        blocks.append((pos, end, rows))
        rows += count
        pos = end
    out = {name: None if c is None else c.finish() for name, c in columns.items()}
    masked_out = {n: np.concatenate(masked_rows[n]) for n in must if n in masked_rows}
    return Body(out, rows, _line_finder(text, blocks), masked_out)


class _Column:
    """A float64 column filled block by block: the values are copied once, from pyarrow's
    buffers (freed with their block) into one array grown to the expected row count."""

    def __init__(self) -> None:
        self.array = np.empty(0)
        self.size = 0

    def extend(self, chunks: list[np.ndarray], expected_more: int) -> None:
        added = sum(len(c) for c in chunks)
        if self.size + added > self.array.size:
            self.array.resize(self.size + added + expected_more, refcheck=False)
        for chunk in chunks:
            self.array[self.size : self.size + len(chunk)] = chunk
            self.size += len(chunk)

    def finish(self) -> np.ndarray:
        self.array.resize(self.size, refcheck=False)  # shrinking: in place
        return self.array


def arrow_block(
    block: str | bytes,
    delimiter: str,
    names: list[str],
    active: Mapping[str, bool],
    decimal: str,
    allowed_empty: Set[str],
) -> tuple[dict[str, list[np.ndarray] | None], dict[str, np.ndarray], int] | None:
    """The block's columns (as chunks), the rows of the masked samples of its sparse
    columns and its row count, read by pyarrow; or ``None`` when the Python rules must read
    it (an error somewhere in it, or no column to read)."""
    if not active:
        return None
    if isinstance(block, bytes):  # pure ASCII, handed to pyarrow as is
        if b"#" in block or (b"\r" in block and block.count(b"\r") != block.count(b"\r\n")):
            return arrow_block(
                block.decode("ascii"), delimiter, names, active, decimal, allowed_empty
            )
        data = block
    else:
        if "\r" in block and block.count("\r") != block.count("\r\n"):
            block = block.replace("\r\n", "\n").replace("\r", "\n")  # a lone CR ends a line
        if "#" in block or not block.isascii():
            block = _SKIP_LINE.sub("", block)
        data = block.encode("utf-8", "surrogatepass")
    wanted = list(active)
    columns = [f"f{j}" for j in range(len(names))]  # the header is ours, names may be odd
    field = {name: f"f{j}" for j, name in enumerate(names) if name in active}
    try:
        table = pacsv.read_csv(
            pa.py_buffer(data),
            read_options=pacsv.ReadOptions(column_names=columns, block_size=ARROW_BLOCK_BYTES),
            parse_options=pacsv.ParseOptions(delimiter=delimiter),
            convert_options=pacsv.ConvertOptions(
                column_types={field[name]: pa.float64() for name in wanted},
                include_columns=[field[name] for name in wanted],
                null_values=[""],  # an empty cell (only); `NA`, `null`… are text
                strings_can_be_null=False,
                decimal_point=decimal,
            ),
        )
    except pa.ArrowException:  # a bad cell or row (ArrowInvalid), or anything else: Python
        return None
    values: dict[str, list[np.ndarray] | None] = {}
    masked: dict[str, np.ndarray] = {}
    for name in wanted:
        column = table.column(field[name])
        sparse = name in allowed_empty
        if column.null_count and not sparse:
            return None
        chunks: list[np.ndarray] = []
        where: list[np.ndarray] = []
        first = 0
        for chunk in column.chunks:
            got = _floats(chunk, sparse=sparse)
            if got is None:
                return None  # nan or inf written out: refused, the Python rules name the line
            chunks.append(got[0])
            if got[1].size:
                where.append(got[1] + first)
            first += len(chunk)
        values[name] = chunks  # type: ignore[assignment]
        if where:
            masked[name] = np.concatenate(where)
    if masked and _PAREN[type(block)] in block:  # type: ignore[operator]
        return None  # pyarrow reads `nan(1)` as NaN, mapwise refuses it: the Python rules
    return values, masked, table.num_rows


_NO_ROWS = np.empty(0, dtype=np.int64)


def _floats(chunk: pa.Array, *, sparse: bool) -> tuple[np.ndarray, np.ndarray] | None:
    """A float64 chunk as numpy (a view of pyarrow's buffer; NaN where a cell was empty)
    and the rows of its written-out nan/inf, which are NaN too (masked samples) in a
    ``sparse`` column and make the chunk ``None`` (refused) in any other. Read from the
    buffers (:mod:`app.io.arrow_arrays`): ``Array.to_numpy`` would import pandas."""
    values = float64_values(chunk)
    # min and max propagate nan and reach ±inf: no mask allocated on the common path
    finite = not values.size or bool(np.isfinite(values.min()) and np.isfinite(values.max()))
    if chunk.null_count:
        valid = valid_rows(chunk)
        written = _NO_ROWS if finite else np.flatnonzero(~np.isfinite(values) & valid)
        if written.size and not sparse:
            return None
        usable = valid if finite else valid & np.isfinite(values)
        return np.where(usable, values, np.nan), written
    if finite:
        return values, _NO_ROWS
    if not sparse:
        return None
    bad = ~np.isfinite(values)
    return np.where(bad, np.nan, values), np.flatnonzero(bad)


def _str(block: str | bytes) -> str:
    return block if isinstance(block, str) else block.decode("ascii")


def _line_number(text: str | bytes, pos: int) -> int:
    """The 1-based line that starts at ``text[pos]`` (after LF, CRLF or CR)."""
    lf, cr, crlf = ("\n", "\r", "\r\n") if isinstance(text, str) else (b"\n", b"\r", b"\r\n")
    return text.count(lf, 0, pos) + text.count(cr, 0, pos) - text.count(crlf, 0, pos) + 1  # type: ignore[arg-type]


def _line_finder(text: str | bytes, blocks: list[tuple[int, int, int]]) -> Callable[[int], int]:
    """``line_of(k)``: the file line of data row ``k``, found by reading the one block that
    holds it (only a message needs it)."""
    firsts = [first for _, _, first in blocks]

    def line_of(k: int) -> int:
        b = bisect.bisect_right(firsts, k) - 1
        start, end, first = blocks[b]
        numbered = content_lines(_str(text[start:end]), _line_number(text, start))
        return numbered[k - first][0]

    return line_of
