"""Uploaded log → validated dataset: a time base in seconds plus named float64 channels.

The format is taken from the file's first bytes, never from the client's filename or
content type: MCAP magic ``\\x89MCAP0\\r\\n``, MDF magic ``MDF     `` (versions 3 and 4 via
asammdf), otherwise text → CSV. Every problem raises :class:`~app.io.errors.InputError`
with a ``code`` (``validation_error`` / ``unsupported_format`` / ``payload_too_large``),
the ``field`` it concerns (column, channel, ``"file"``) and a message naming the line/sample.

Each reader gives the channels as recorded (:class:`~app.io.resample.Track`: own time base,
masked samples as NaN; MDF4/MDF3 decide hold or interpolate from the channel metadata, CSV
and MCAP from the values). :func:`ingest` keeps the channels asked for (all by default) and
puts them on one raster (:func:`app.io.resample.resample`, `docs/data-formats.md#multi-rate`):
a rate, the raster of a named channel, or by default the slowest kept channel's. A masked
sample (non-finite, invalid) is counted per channel, never a reason to refuse the file.

Validation common to all formats: at least one channel besides time, at least
``min_samples`` rows, strictly increasing finite time, finite values after resampling
(enforced by :class:`estimation.Signals`), and the size limits of :class:`IngestLimits`.
"""

from __future__ import annotations

import io
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, BinaryIO

import numpy as np

from app.io.errors import InputError, too_large, unsupported
from app.io.names import bad_character, check_name
from app.io.resample import (
    Raster,
    Track,
    held_by_values,
    parse_raster,
    resample,
    select,
    shared_time_base,
)
from estimation import Signals
from estimation.errors import SignalError

if TYPE_CHECKING:
    from app.io.csv_files import SparseCsv

MCAP_MAGIC = b"\x89MCAP0\r\n"
MDF_MAGIC = b"MDF     "
# Bytes that never occur in a text log: NUL and the C0 controls other than tab, LF, FF, CR.
BINARY_BYTES = re.compile(rb"[\x00-\x08\x0b\x0e-\x1f\x7f]")


@dataclass(frozen=True, slots=True)
class IngestLimits:
    """Bounds on what an upload may make the server do."""

    max_bytes: int = 512 * 2**20
    max_header_bytes: int = 64 * 2**10
    max_channels: int = 2000
    min_samples: int = 2
    max_decompressed_bytes: int = 512 * 2**20
    # A rate raster makes rows out of nothing: its table is bounded before it is allocated.
    max_rows: int = 20_000_000
    max_values: int = 64 * 2**20  # rows × channels: 512 MiB of float64


@dataclass(frozen=True, slots=True)
class ParsedLog:
    """A validated log: ``signals`` (time in s, float64 channels with units), provenance,
    notes, and the masked (non-finite or invalid) samples per kept channel that has any.

    ``recorded``: the kept channels as recorded, when they are on different timestamps and
    no raster was asked for; ``signals`` is then their whole-log read on the default raster
    (the slowest kept channel's), and the dataset is stored as recorded so that each run
    reads its own channels on the slowest raster among them."""

    signals: Signals
    source: str
    time_column: str | None
    notes: tuple[str, ...] = ()
    masked: Mapping[str, int] = field(default_factory=dict)
    recorded: tuple[Track, ...] = ()

    @property
    def rows(self) -> int:
        return len(self.signals)

    @property
    def rate_hz(self) -> float:
        """``1 / median(Δt)`` in Hz (0.0 with fewer than two samples)."""
        if self.rows < 2:
            return 0.0
        return float(1.0 / np.median(np.diff(self.signals.time)))

    @property
    def duration_s(self) -> float:
        return float(self.signals.time[-1] - self.signals.time[0]) if self.rows else 0.0

    @property
    def channels(self) -> list[dict[str, str]]:
        return [{"name": n, "unit": self.signals.units[n]} for n in self.signals.names]


def detect_format(head: bytes) -> str:
    """``"mcap"``, ``"mdf4"`` or ``"csv"`` from the first bytes of a file.

    Raises ``unsupported_format`` for anything else (binary data without a known magic).
    """
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    if head.startswith(MDF_MAGIC):
        return "mdf4"
    if not head:
        raise InputError("empty file", field="file")
    if BINARY_BYTES.search(head[:4096]):
        raise unsupported(
            "binary data that is neither MCAP nor MDF4 (and not CSV text); "
            "upload a CSV, MCAP or MDF4 file"
        )
    return "csv"


def ingest(
    source: bytes | bytearray | memoryview | BinaryIO | os.PathLike[str],
    *,
    units: Mapping[str, str] | None = None,
    time_column: str | None = None,
    limits: IngestLimits | None = None,
    channels: Sequence[str] | None = None,
    raster: str | None = None,
    rate_hz: float | None = None,
    time_required: bool = False,
) -> ParsedLog:
    """Parse and validate an uploaded log.

    ``source``: the file's bytes, a binary file object (read from its current position), or
    a server-side path. ``units``: unit overrides by channel name (a units sidecar).
    ``time_column``: the time column/field; default the first of ``time, time_s, t,
    timestamp, timestamps`` present. ``channels``: the channels to keep (default all).
    ``raster``: ``"100Hz"``, ``"10ms"``, ``"channel:NAME"`` (:func:`parse_raster`); default
    the slowest kept channel's raster. ``rate_hz``: the sample rate of a CSV without a time
    column; ``time_required``: refuse such a CSV without it (uploads do, see
    :func:`app.io.csv_upload.read_csv_upload`).
    """
    limits = limits or IngestLimits()
    wanted = list(channels) if channels is not None else None
    grid = parse_raster(raster)  # a bad raster fails before the file is read
    data = _read_bounded(source, limits.max_bytes)
    kind = detect_format(data[:4096])
    if rate_hz is not None and kind != "csv":
        raise InputError(
            f"rate_hz is only for a CSV without a time column; a {kind.upper()} file has "
            "its own timestamps",
            field="rate_hz",
        )
    notes: list[str]
    if kind == "mcap":
        from app.io.mcap_files import read_mcap

        signals, used_time, notes = read_mcap(
            data, time_column=time_column, max_decompressed_bytes=limits.max_decompressed_bytes
        )
        tracks = _tracks_of(signals, classify=grid != Raster())
    elif kind == "mdf4":
        from app.io.mdf_files import read_mdf

        tracks, used_time, notes = read_mdf(
            data, max_decompressed_bytes=limits.max_decompressed_bytes, channels=wanted
        )
    else:
        from app.io.csv_upload import read_csv_upload

        log, notes = read_csv_upload(
            data,
            units=units,
            time_column=time_column,
            max_header_bytes=limits.max_header_bytes,
            max_channels=limits.max_channels,
            rate_hz=rate_hz,
            time_required=time_required,
        )
        used_time = log.time_column
        tracks = _sparse_tracks(log, grid, notes)
    kept = select(tracks, wanted)
    _check_recorded(kept, limits)
    table = resample(kept, grid, max_rows=limits.max_rows, max_values=limits.max_values)
    try:
        signals = Signals(table.time, table.channels, table.units, copy=False)
    except SignalError as exc:
        raise InputError(str(exc), field="file") from None
    if kind != "csv":  # CSV units are applied while parsing (the units row rule)
        signals = _apply_units(signals, units)
    _check_shape(signals, limits)
    said = [*notes, *table.notes]
    recorded: tuple[Track, ...] = ()
    if grid == Raster():
        usable = [t for t in kept if t.name in table.channels]
        if not shared_time_base(usable):
            recorded = tuple(usable)
            said.append(
                "stored as recorded, each channel on its own timestamps: a run reads the "
                "channels it needs on the slowest raster among them (the whole log: the "
                "raster above)"
            )
    return ParsedLog(signals, kind, used_time, tuple(said), dict(table.masked), recorded)


def _tracks_of(signals: Signals, *, classify: bool) -> list[Track]:
    """Channels on one shared time base; hold decided from the values only when they are
    to be resampled (:func:`held_by_values`)."""
    return [
        Track(
            n, signals.units[n], signals.time, signals[n], classify and held_by_values(signals[n])
        )
        for n in signals.names
    ]


def _sparse_tracks(log: SparseCsv, grid: Raster, notes: list[str]) -> list[Track]:
    """CSV columns as tracks: a column with empty cells has samples only on its filled rows
    (noted); a written ``nan``/``inf`` is a masked sample (NaN), counted by
    :func:`app.io.resample.resample` like MDF's; hold or interpolate from the values when
    anything is to be resampled."""
    classify = grid != Raster() or any(log.empty.values()) or bool(log.masked_rows)
    tracks = []
    for name, values in log.columns.items():
        if log.empty[name]:
            filled = log.sampled(name)
            notes.append(
                f"column {name!r}: a value on {int(filled.sum())} of {values.size} rows "
                "(empty cells: no sample)"
            )
            t, v = log.time[filled], values[filled]
        else:
            t, v = log.time, values
        tracks.append(Track(name, log.units[name], t, v, classify and held_by_values(v)))
    return tracks


def _read_bounded(
    source: bytes | bytearray | memoryview | BinaryIO | os.PathLike[str], max_bytes: int
) -> bytes:
    if isinstance(source, bytes | bytearray | memoryview):
        data = bytes(source)
    elif isinstance(source, os.PathLike):
        size = os.path.getsize(source)
        if size > max_bytes:
            raise _too_large(size, max_bytes)
        with open(source, "rb") as f:
            data = _read_at_most(f, max_bytes + 1)
    else:
        data = _read_at_most(source, max_bytes + 1)
    if len(data) > max_bytes:
        raise _too_large(len(data), max_bytes)
    return data


def _read_at_most(file: BinaryIO, limit: int) -> bytes:
    """The rest of ``file``, at most ``limit`` bytes, allocating no more than that: ``read(n)``
    reserves ``n`` bytes up front, which a process under a memory limit (the dataset child)
    cannot give when ``n`` is the upload limit rather than the file's size."""
    try:
        here = file.tell()
        size = file.seek(0, io.SEEK_END) - here
        file.seek(here)
    except (AttributeError, OSError, ValueError):  # not seekable: a block at a time
        chunks, total = [], 0
        while total < limit:
            chunk = file.read(min(1 << 20, limit - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
        return b"".join(chunks)
    return file.read(min(size + 1, limit))


def _too_large(size: int, max_bytes: int) -> InputError:
    more = "more than " if size == max_bytes + 1 else ""
    return too_large(f"file is {more}{size} bytes, the limit is {max_bytes} bytes")


def _apply_units(signals: Signals, units: Mapping[str, str] | None) -> Signals:
    if not units:
        return signals
    for name in units:
        if name not in signals:
            raise InputError(
                f"units given for unknown channel {name!r}; the file has {signals.names}",
                field=f"units.{name}",
            )
    merged = {**signals.units, **{k: str(v) for k, v in units.items()}}
    return Signals(signals.time, signals.channels, merged, copy=False)


def _check_recorded(tracks: Sequence[Track], limits: IngestLimits) -> None:
    """What no raster can mend: no channel, too many, or too few samples in every channel."""
    if not tracks:
        raise InputError("no data channels besides the time base", field="file")
    if len(tracks) > limits.max_channels:
        raise InputError(
            f"{len(tracks)} channels, the limit is {limits.max_channels}", field="file"
        )
    rows = max(t.time.size for t in tracks)
    if rows == 0:
        raise InputError("no data rows (0 samples)", field="file")
    if rows < limits.min_samples:
        raise InputError(
            f"too few samples: {rows}, at least {limits.min_samples} needed", field="file"
        )


def _check_shape(signals: Signals, limits: IngestLimits) -> None:
    if not signals.names:
        raise InputError("no data channels besides the time base", field="file")
    for name in signals.names:  # the rule of CSV headers, for MCAP and MDF channels too
        if bad_character(name) is not None:
            check_name(name, field=name, what="channel name")
    if len(signals.names) > limits.max_channels:
        raise InputError(
            f"{len(signals.names)} channels, the limit is {limits.max_channels}", field="file"
        )
    if len(signals) == 0:
        raise InputError("no data rows (0 samples)", field="file")
    if len(signals) < limits.min_samples:
        raise InputError(
            f"too few samples: {len(signals)}, at least {limits.min_samples} needed", field="file"
        )
