"""CSV uploads: decode the bytes, then the shared reader
:func:`app.io.csv_files.parse_sparse_csv` (every column numeric; an empty cell is no sample
of that channel)."""

from __future__ import annotations

import re
from collections.abc import Mapping

from app.io.csv_files import DELIMITERS, SparseCsv, parse_sparse_csv, split_lines
from app.io.errors import InputError, unsupported

_BINARY = re.compile(r"[\x00-\x08\x0b\x0e-\x1f\x7f]")


def read_csv_upload(
    data: bytes,
    *,
    units: Mapping[str, str] | None,
    time_column: str | None,
    max_header_bytes: int,
    max_channels: int,
) -> tuple[SparseCsv, list[str]]:
    """The columns and notes of a CSV upload (UTF-8, else Latin-1)."""
    notes: list[str] = []
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
        notes.append("decoded as Latin-1 (the file is not valid UTF-8)")
    match = _BINARY.search(text)
    if match:
        raise unsupported(
            f"binary data at byte {match.start()}: not CSV text, and no MCAP or MDF4 magic"
        )
    _reject_unknown_delimiter(text)
    log = parse_sparse_csv(
        text,
        units=units,
        time_column=time_column,
        max_header_chars=max_header_bytes,
        max_columns=max_channels + 1,
    )
    if log.decimal == ",":
        notes.append("decimal comma")
    if log.time_column is None:
        notes.append("no time column: time is the sample index (1 Hz)")
    return log, notes


def _reject_unknown_delimiter(text: str) -> None:
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
