"""Uploaded log → validated dataset: a time base in seconds plus named float64 channels.

The format is taken from the file's first bytes, never from the client's filename or
content type: MCAP magic ``\\x89MCAP0\\r\\n``, MDF magic ``MDF     `` (versions 3 and 4 via
asammdf), otherwise text → CSV. Every problem raises :class:`~app.io.errors.InputError`
with a ``code`` (``validation_error`` / ``unsupported_format`` / ``payload_too_large``),
the ``field`` it concerns (column, channel, ``"file"``) and a message naming the line/sample.

Validation common to all formats (:func:`ingest`): at least one channel besides time, at
least ``min_samples`` rows, strictly increasing finite time, finite values everywhere
(enforced by :class:`estimation.Signals`), and the size limits of :class:`IngestLimits`.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np

from app.io.errors import InputError, too_large, unsupported
from app.io.names import bad_character, check_name
from estimation import Signals

MCAP_MAGIC = b"\x89MCAP0\r\n"
MDF_MAGIC = b"MDF     "
# Bytes that never occur in a text log: NUL and the C0 controls other than tab, LF, FF, CR.
_BINARY = re.compile(rb"[\x00-\x08\x0b\x0e-\x1f\x7f]")


@dataclass(frozen=True, slots=True)
class IngestLimits:
    """Bounds on what an upload may make the server do."""

    max_bytes: int = 512 * 2**20
    max_header_bytes: int = 64 * 2**10
    max_channels: int = 2000
    min_samples: int = 2
    max_decompressed_bytes: int = 512 * 2**20


@dataclass(frozen=True, slots=True)
class ParsedLog:
    """A validated log: ``signals`` (time in s, float64 channels with units) and provenance."""

    signals: Signals
    source: str
    time_column: str | None
    notes: tuple[str, ...] = ()

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
    if _BINARY.search(head[:4096]):
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
) -> ParsedLog:
    """Parse and validate an uploaded log.

    ``source``: the file's bytes, a binary file object (read from its current position), or
    a server-side path. ``units``: unit overrides by channel name (a units sidecar).
    ``time_column``: the time column/field; default the first of ``time, time_s, t,
    timestamp`` present.
    """
    limits = limits or IngestLimits()
    data = _read_bounded(source, limits.max_bytes)
    kind = detect_format(data[:4096])
    if kind == "mcap":
        from app.io.mcap_files import read_mcap

        signals, used_time, notes = read_mcap(
            data, time_column=time_column, max_decompressed_bytes=limits.max_decompressed_bytes
        )
        signals = _apply_units(signals, units)
    elif kind == "mdf4":
        from app.io.mdf_files import read_mdf

        signals, used_time, notes = read_mdf(
            data, max_decompressed_bytes=limits.max_decompressed_bytes
        )
        signals = _apply_units(signals, units)
    else:
        from app.io.csv_upload import read_csv_upload

        signals, used_time, notes = read_csv_upload(
            data,
            units=units,
            time_column=time_column,
            max_header_bytes=limits.max_header_bytes,
            max_channels=limits.max_channels,
        )
    _check_shape(signals, limits)
    return ParsedLog(signals, kind, used_time, tuple(notes))


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
            data = f.read(max_bytes + 1)
    else:
        data = source.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise _too_large(len(data), max_bytes)
    return data


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
    return Signals(signals.time, signals.channels, merged)


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
