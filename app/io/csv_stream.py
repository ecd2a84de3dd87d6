"""A dense CSV upload parsed block by block straight into a Parquet file, never held whole.

The header, units row, delimiter and decimal mark are read from the file's first lines by
the rules of every CSV (:func:`app.io.csv_files.read_header`); the body is then read
:data:`BLOCK_BYTES` at a time, cut at a line end, parsed by ``pyarrow.csv``
(:func:`app.io.csv_arrow.arrow_block`) and appended to the file through a
:class:`RowSink` (the store's :class:`~app.store.parquet_signals.SignalsWriter`). The
process holds one block of text, its columns and the distinct time steps with their counts
(for the median rate), whatever the file's size.

Only a *dense* log streams: UTF-8 text whose every cell is a finite number, a time column
(or a given row rate) strictly increasing, no empty cell. That is what a logger's CSV
export is. Anything else — an empty cell (a sparse multi-rate export), a written ``nan``, a
cell or row pyarrow refuses, a Latin-1 file, a name refused by the naming rule — raises
:class:`NotDense` with the reason, and the caller reads the file whole by the upload rules
(:func:`app.io.ingest.ingest`), which keep the samples, or name the line and column that
is wrong. Both paths give the same channels, units, notes and values
(``tests/app/io/test_csv_stream.py``). `docs/data-formats.md#streamed-uploads`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import BinaryIO, Protocol

import numpy as np

from app.io.csv_arrow import arrow_block
from app.io.csv_files import CsvHeader, read_header
from app.io.csv_sniff import head_lines, time_column_note
from app.io.csv_upload import BINARY, reject_unknown_delimiter
from app.io.ingest import BINARY_BYTES
from app.io.names import bad_character

STREAM_MIN_BYTES = 16 << 20  # a smaller file is read whole: it costs little either way
BLOCK_BYTES = 2 << 20  # text parsed at a time: two of pyarrow's blocks (ARROW_BLOCK_BYTES)
HEAD_BYTES = 1 << 20  # the header, units row and sniffed rows must lie within it
_BOM = b"\xef\xbb\xbf"
# The ASCII that ingest's BINARY_BYTES lets through: deleting these from a block leaves its
# control characters, ten times as fast as searching it with the regex.
_TEXT = bytes(b for b in range(0x80) if not BINARY_BYTES.match(bytes([b])))


class RowSink(Protocol):
    """Where the rows go (:class:`app.store.parquet_signals.SignalsWriter`)."""

    def write(self, time: np.ndarray, values: Sequence[np.ndarray]) -> None: ...

    def close(self) -> str:
        """Finish; the SHA-256 of what was written."""
        ...

    def abort(self) -> None: ...


class _Pipelined:
    """A :class:`RowSink` whose writes run on a thread of their own, one block behind the
    parse: block ``i`` is compressed and written while block ``i + 1`` is read and parsed
    (pyarrow releases the GIL in both), so the two use both cores. At most one block waits
    to be written; a write that failed raises at the next call, in order."""

    def __init__(self, sink: RowSink) -> None:
        self.sink = sink
        self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="mapwise-csv-write")
        self.pending: Future[None] | None = None

    def write(self, time: np.ndarray, values: Sequence[np.ndarray]) -> None:
        self._wait()
        self.pending = self.pool.submit(self.sink.write, time, values)

    def close(self) -> str:
        try:
            self._wait()
            return self.sink.close()
        finally:
            self.pool.shutdown()

    def abort(self) -> None:
        try:
            with contextlib.suppress(Exception):  # the reason is already being raised
                self._wait()
            self.sink.abort()
        finally:
            self.pool.shutdown()

    def _wait(self) -> None:
        pending, self.pending = self.pending, None
        if pending is not None:
            pending.result()


class NotDense(Exception):  # noqa: N818 - a reason to read the file whole, not an error
    """Why a CSV cannot stream; the upload is then read whole."""


@dataclass(frozen=True, slots=True)
class StreamedCsv:
    """What a streamed upload wrote: rows, the channels (name, unit) in the file's order,
    the time column used, its rate and duration as a whole-file read gives them, the notes
    and the file's SHA-256."""

    rows: int
    channels: list[tuple[str, str]]
    time_column: str | None
    rate_hz: float
    duration_s: float
    notes: tuple[str, ...]
    sha256: str


def stream_csv(
    source: BinaryIO,
    open_sink: Callable[[list[tuple[str, str]]], RowSink],
    *,
    units: Mapping[str, str] | None,
    time_column: str | None,
    channels: Sequence[str] | None,
    rate_hz: float | None,
    max_header_bytes: int,
    max_channels: int,
    min_samples: int,
) -> StreamedCsv:
    """Parse the dense CSV ``source`` (read from its start) into the sink that
    ``open_sink(channels)`` opens for the kept channels (name, unit).

    Arguments as :func:`app.io.ingest.ingest` for an upload (a time column is required
    unless ``rate_hz`` is given). Raises :class:`NotDense` for a file this path does not
    take, and :class:`~app.io.csv_sniff.LogFormatError` for a header every path refuses.
    """
    head = source.read(HEAD_BYTES)
    skip = len(_BOM) if head.startswith(_BOM) else 0
    cut = head.rfind(b"\n") + 1
    try:
        text = head[skip:cut].decode("utf-8")
    except UnicodeDecodeError:
        raise NotDense("not UTF-8 text") from None
    if BINARY.search(text):
        raise NotDense("a control character in the first lines")
    if len(head_lines(text, 22)) < 22:
        raise NotDense(f"fewer than 22 lines in the first {HEAD_BYTES} bytes")
    reject_unknown_delimiter(text)
    header = read_header(
        text,
        columns=None,
        time_column=time_column,
        strict=True,
        units=units,
        decimal=None,
        max_header_chars=max_header_bytes,
        max_columns=max_channels + 1,
        empty_is_missing=False,
    )
    kept = _kept(header.names, header.time_column, channels, rate_hz, max_channels)
    notes = ["decimal comma"] if header.decimal == "," else []
    if (note := time_column_note(header.time_column, header.names)) is not None:
        notes.append(note)
    if header.time_column is None:
        notes.append(f"no time column: rows taken at the given rate of {rate_hz:g} Hz")
    source.seek(skip + len(text[: header.body_start].encode("utf-8")))
    writer = _Pipelined(open_sink([(n, header.units[n]) for n in kept]))
    try:
        steps = _stream_body(source, header, kept, rate_hz, writer)
    except BaseException:
        writer.abort()
        raise
    if steps.rows < max(min_samples, 2):
        writer.abort()
        raise NotDense(f"{steps.rows} rows")
    sha256 = writer.close()
    return StreamedCsv(
        rows=steps.rows,
        channels=[(n, header.units[n]) for n in kept],
        time_column=header.time_column,
        rate_hz=float(1.0 / steps.median()),
        duration_s=steps.last - steps.first,
        notes=tuple(notes),
        sha256=sha256,
    )


@dataclass(slots=True)
class _Steps:
    """The time base as it streams in: its first and last time, its rows, and its steps
    ``t[k] − t[k−1]`` (the same floats as ``np.diff`` of the whole column) counted by value,
    for the median rate; a step ≤ 0 is refused as it comes. A logger's steps take few
    distinct values, so the count stays small whatever the rows (8 bytes a row before:
    76 MiB of a 10 M-row upload); jittered steps cost at most 16 bytes a row."""

    values: np.ndarray = field(default_factory=lambda: np.empty(0))  # distinct, sorted
    counts: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    pending: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    pending_size: int = 0
    rows: int = 0
    first: float = 0.0
    last: float = 0.0

    def add(self, time: np.ndarray) -> None:
        steps = np.diff(time, prepend=self.last) if self.rows else np.diff(time)
        if np.any(steps <= 0):
            raise NotDense(f"time not strictly increasing after row {self.rows}")
        if not self.rows:
            self.first = float(time[0])
        values, counts = np.unique(steps, return_counts=True)
        self.pending.append((values, counts))
        self.pending_size += values.size
        if self.pending_size > max(self.values.size, 1 << 16):  # amortised: linear in all
            self._merge()
        self.rows += time.size
        self.last = float(time[-1])

    def median(self) -> float:
        """``np.median(np.diff(time))`` of the whole column, bit for bit: the middle step
        (the mean of the two middle steps for an even count) by the cumulative counts."""
        self._merge()
        below = np.cumsum(self.counts)
        n = int(below[-1])

        def kth(k: int) -> float:  # the k-th smallest step, from 0
            return float(self.values[np.searchsorted(below, k, side="right")])

        if n % 2:
            return kth(n // 2)
        return float(np.mean([kth(n // 2 - 1), kth(n // 2)]))

    def _merge(self) -> None:
        if not self.pending:
            return
        values = np.concatenate([self.values, *(v for v, _ in self.pending)])
        counts = np.concatenate([self.counts, *(c for _, c in self.pending)])
        self.values, where = np.unique(values, return_inverse=True)
        self.counts = np.bincount(where, weights=counts).astype(np.int64)
        self.pending, self.pending_size = [], 0


def _kept(
    names: list[str],
    time_column: str | None,
    wanted: Sequence[str] | None,
    rate_hz: float | None,
    max_channels: int,
) -> list[str]:
    """The channels to store, in the order a whole read gives them."""
    if (time_column is None) == (rate_hz is None):
        raise NotDense("a time column and a rate, or neither")
    bad = [n for n in names if bad_character(n) is not None]
    if bad:
        raise NotDense(f"a column name the naming rule refuses: {bad[0]!r}")
    data = [n for n in names if n != time_column]
    if wanted is None:
        kept = data
    else:
        kept = list(dict.fromkeys(wanted))
        if any(n not in data for n in kept):
            raise NotDense("a channel asked for that the file does not have")
    if not kept:
        raise NotDense("no channel besides the time")
    if len(kept) > max_channels:
        raise NotDense(f"{len(kept)} channels, over the limit")
    return kept


def _stream_body(
    source: BinaryIO,
    header: CsvHeader,
    kept: list[str],
    rate_hz: float | None,
    writer: RowSink,
) -> _Steps:
    """Parse and write the body block by block; the time base's steps."""
    steps = _Steps()
    carry = b""
    while True:
        data = source.read(BLOCK_BYTES)
        buffer = carry + data
        cut = len(buffer) if not data else buffer.rfind(b"\n") + 1
        if data and cut == 0:
            if len(buffer) > 4 * BLOCK_BYTES:
                raise NotDense(f"a line longer than {4 * BLOCK_BYTES} bytes")
            carry = buffer
            continue
        block, carry = buffer[:cut], buffer[cut:]
        if not block:
            return steps
        rows = steps.rows
        if not block.isascii():
            raise NotDense(f"non-ASCII text after row {rows}")
        if block.translate(None, _TEXT):  # a control character, even in a comment line
            raise NotDense(f"a control character after row {rows}")
        got = arrow_block(
            block, header.delimiter, header.names, header.must, header.decimal, frozenset()
        )
        if got is None:
            raise NotDense(f"a cell or row after row {rows} that only the whole read can judge")
        values, _, count = got
        if count:
            column = header.time_column
            if column is None:
                time = np.arange(rows, rows + count, dtype=np.float64) / rate_hz
            else:
                time = _joined(values[column])
                if header.time_scale != 1.0:
                    time = time * header.time_scale
            steps.add(time)
            writer.write(time, [_joined(values[n]) for n in kept])
        if not data:
            return steps


def _joined(chunks: list[np.ndarray] | None) -> np.ndarray:
    assert chunks is not None  # every column is strict: text in one fails the block
    return chunks[0] if len(chunks) == 1 else np.concatenate(chunks)
