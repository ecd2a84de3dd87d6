"""CSV uploads: decode the bytes, then the shared reader
:func:`app.io.csv_files.parse_sparse_csv` (every column numeric; an empty cell is no sample
of that channel).

A CSV without a time column has no time base. An upload (``time_required``) refuses it,
naming ``time``, unless the rows' sample rate is given (``rate_hz``: row k at k / rate s),
which is then stated in the dataset's notes; guessing 1 Hz would silently put every map
and metric on the wrong time scale."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping

from app.io.csv_files import SparseCsv, parse_sparse_csv
from app.io.csv_sniff import DELIMITERS, TIME_COLUMNS, split_lines, time_column_note
from app.io.errors import InputError, unsupported

BINARY = re.compile(r"[\x00-\x08\x0b\x0e-\x1f\x7f]")


def read_csv_upload(
    data: bytes,
    *,
    units: Mapping[str, str] | None,
    time_column: str | None,
    max_header_bytes: int,
    max_channels: int,
    rate_hz: float | None = None,
    time_required: bool = False,
) -> tuple[SparseCsv, list[str]]:
    """The columns and notes of a CSV upload (UTF-8, else Latin-1). ``rate_hz``: the rows'
    sample rate, for a file without a time column only; ``time_required``: refuse such a
    file when no rate is given (else its time is the sample index, 1 Hz, as noted)."""
    notes: list[str] = []
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
        notes.append("decoded as Latin-1 (the file is not valid UTF-8)")
    match = BINARY.search(text)
    if match:
        raise unsupported(
            f"binary data at byte {match.start()}: not CSV text, and no MCAP or MDF4 magic"
        )
    reject_unknown_delimiter(text)
    log = parse_sparse_csv(
        text,
        units=units,
        time_column=time_column,
        max_header_chars=max_header_bytes,
        max_columns=max_channels + 1,
    )
    if log.decimal == ",":
        notes.append("decimal comma")
    if (note := time_column_note(log.time_column, list(log.columns))) is not None:
        notes.append(note)
    if log.time_column is not None:
        if rate_hz is not None:
            raise InputError(
                f"rate_hz is only for a file without a time column; this file's time column "
                f"is {log.time_column!r}",
                field="rate_hz",
                line=None,
            )
    elif rate_hz is not None:
        log = dataclasses.replace(log, time=log.time / rate_hz)
        notes.append(f"no time column: rows taken at the given rate of {rate_hz:g} Hz")
    elif time_required:
        raise InputError(
            "the file has no time column (one of "
            f"{', '.join(TIME_COLUMNS)}, in s unless its unit says ms, us, ns, min or h); add "
            "one, or give the rows' sample "
            "rate as rate_hz",
            field="time",
            line=None,
        )
    else:
        notes.append("no time column: time is the sample index (1 Hz)")
    return log, notes


def reject_unknown_delimiter(text: str) -> None:
    """A header and first row split alike by ``|``, ``:`` or spaces but holding none of
    ``, ; tab`` is a file with an unsupported delimiter."""
    content = []
    for line in split_lines(text):
        if line.strip() and not line.lstrip().startswith("#"):
            content.append(line[:4096])
            if len(content) == 2:
                break
    if len(content) < 2 or any(d in content[0] for d in DELIMITERS):
        return
    for sep in ("|", ":", None):
        parts = [line.split(sep) for line in content]
        if len(parts[0]) > 1 and len(parts[0]) == len(parts[1]):
            shown = "whitespace" if sep is None else repr(sep)
            raise InputError(
                f"columns are separated by {shown}; use ',', ';' or tab as the delimiter",
                field="file",
                line=None,
            )
