"""Read drive logs from MDF (ASAM MDF 4, and 3) with asammdf.

Every numeric scalar channel becomes a :class:`~app.io.resample.Track`: its own group's
timestamps and float64 physical values (conversions applied) with its unit; master (time)
channels form the time bases, text/array/structure channels are skipped (noted). A sample
that is non-finite (a rational conversion's pole gives ±inf) or flagged in the invalidation
bits is *masked* — counted per channel, never a reason to refuse the file. The channels are
then put on one raster by :func:`app.io.resample.resample`.

Hold or interpolate is decided per channel from its metadata
(`docs/data-formats.md#multi-rate`): held (previous value) when the conversion is a table
without interpolation — value→value (TAB), range→value (RTAB), value→text (TABX),
range→text (RTABX), bitfield — or when the raw value is an integer of at most 8 bits shown
as recorded (no conversion), which covers status bytes and booleans (1 bit); every other
channel is interpolated linearly. A value→text channel keeps its raw number (asammdf's
``ignore_value2text_conversions``); its table is written in the notes.

Untrusted input: zipped data blocks (``##DZ``) are inflated once here, bounded, before
asammdf sees the file, so a block that lies about its size or a decompression bomb is
refused instead of exhausting memory.
"""

from __future__ import annotations

import io
import re
import struct
import sys
import zlib
from collections.abc import Sequence
from typing import Any

import numpy as np
from asammdf.blocks import v2_v3_constants as v3c
from asammdf.blocks import v4_constants as v4c

from app.io.errors import InputError, too_large, unsupported
from app.io.resample import Track
from estimation import Signals
from estimation.errors import SignalError

MAGIC = b"MDF     "
_DZ = struct.Struct("<4s4xQQ2sBxIQQ")  # id, length, links, org type, zip type, param, org, data


def read_mdf(
    data: bytes, *, max_decompressed_bytes: int, channels: Sequence[str] | None = None
) -> tuple[list[Track], str, list[str]]:
    """The numeric channels of an MDF file as tracks (only ``channels``, if given), the
    master channel name of the first group read, and notes."""
    if not data.startswith(MAGIC):
        raise unsupported("not an MDF file (no 'MDF     ' magic)")
    version = data[8:16].decode("ascii", "replace").strip()
    if version[:1] not in ("3", "4"):
        raise unsupported(f"MDF version {version!r} is not supported (3.x and 4.x are)")
    _check_zipped_blocks(data, max_decompressed_bytes)
    notes: list[str] = []
    tracks, master = _read_tracks(data, set(channels) if channels is not None else None, notes)
    if not tracks:
        raise InputError("the MDF file has no numeric channels", field="file")
    return tracks, master, notes


def _check_zipped_blocks(data: bytes, budget: int) -> None:
    """Inflate every plausible ``##DZ`` block with an output cap (MDF 4.1 §6.25)."""
    total = 0
    start = data.find(b"##DZ")
    while start != -1:
        if start % 8 == 0 and start + _DZ.size <= len(data):
            _, length, links, _, zip_type, _, org_size, size = _DZ.unpack_from(data, start)
            if links == 0 and length == _DZ.size + size and start + length <= len(data):
                if zip_type not in (0, 1):
                    raise unsupported(
                        f"MDF data block compression type {zip_type} is not supported"
                    )
                total += org_size
                if total > budget:
                    raise too_large(f"MDF data blocks inflate to more than {budget} bytes")
                payload = data[start + _DZ.size : start + length]
                inflater = zlib.decompressobj()
                try:
                    out = inflater.decompress(payload, org_size + 1)
                except zlib.error as exc:
                    raise InputError(
                        f"corrupt MDF data block at byte {start}: {exc}", field="file"
                    ) from None
                if len(out) != org_size or inflater.unconsumed_tail:
                    raise InputError(
                        f"corrupt MDF data block at byte {start}: declares {org_size} bytes, "
                        "inflates to a different size",
                        field="file",
                    )
        start = data.find(b"##DZ", start + 4)


# Conversions that map by table without interpolation: the physical value is a state.
_TABLES = {
    4: {
        v4c.CONVERSION_TYPE_TAB,
        v4c.CONVERSION_TYPE_RTAB,
        v4c.CONVERSION_TYPE_TABX,
        v4c.CONVERSION_TYPE_RTABX,
        v4c.CONVERSION_TYPE_BITFIELD,
    },
    3: {v3c.CONVERSION_TYPE_TAB, v3c.CONVERSION_TYPE_TABX, v3c.CONVERSION_TYPE_RTABX},
}
_TEXT_TABLES = {
    4: {v4c.CONVERSION_TYPE_TABX, v4c.CONVERSION_TYPE_RTABX},
    3: {v3c.CONVERSION_TYPE_TABX, v3c.CONVERSION_TYPE_RTABX},
}
_NO_CONVERSION = {4: {None, v4c.CONVERSION_TYPE_NON}, 3: {None, v3c.CONVERSION_TYPE_NONE}}
_INTEGERS = {
    4: set(v4c.INT_TYPES),
    3: {
        v3c.DATA_TYPE_UNSIGNED,
        v3c.DATA_TYPE_SIGNED,
        v3c.DATA_TYPE_UNSIGNED_INTEL,
        v3c.DATA_TYPE_UNSIGNED_MOTOROLA,
        v3c.DATA_TYPE_SIGNED_INTEL,
        v3c.DATA_TYPE_SIGNED_MOTOROLA,
    },
}
MAX_HELD_BITS = 8
_TABLE_ENTRIES_NOTED = 8


def _read_tracks(data: bytes, wanted: set[str] | None, notes: list[str]) -> tuple[list[Track], str]:
    """Per channel group, its timestamps (checked strictly increasing) and the wanted
    numeric channels as tracks; unknown wanted names are a 422 on ``channels``."""
    from asammdf import MDF

    tracks: list[Track] = []
    first_master = ""
    # asammdf raises many exception types on malformed files; any of them means "unreadable".
    try:
        with MDF(io.BytesIO(data)) as mdf:
            major = 4 if str(mdf.version).startswith("4") else 3
            masters = mdf.masters_db
            named = _channel_names(mdf, masters)
            if wanted is not None:
                _check_wanted(wanted, named)
            for g, group in enumerate(mdf.groups):
                picked = [
                    (name, i)
                    for name, (gg, i) in named.items()
                    if gg == g and (wanted is None or name in wanted)
                ]
                if not picked:
                    continue
                selected = mdf.select(
                    [(group.channels[i].name, g, i) for _, i in picked],
                    ignore_value2text_conversions=True,
                )
                master_index = masters.get(g)
                master = group.channels[master_index].name if master_index is not None else ""
                master = master or "time"
                kept = []
                for (name, i), signal in zip(picked, selected, strict=True):
                    track = _track(name, signal, group.channels[i], major, notes)
                    if track is not None:
                        kept.append(track)
                if kept:
                    _check_time(kept[0].time, g, master)
                    first_master = first_master or master
                    tracks.extend(kept)
    except (InputError, MemoryError):
        raise
    except Exception as exc:
        raise InputError(
            f"the MDF file is truncated or corrupt ({_detail(exc, len(data))})", field="file"
        ) from None
    return tracks, first_master


def _channel_names(mdf: Any, masters: dict[int, int]) -> dict[str, tuple[int, int]]:
    """Name → (group, channel index) of every non-master channel, named as recorded; a
    name seen in an earlier group gets `` (group g)``."""
    named: dict[str, tuple[int, int]] = {}
    for g, group in enumerate(mdf.groups):
        for i, channel in enumerate(group.channels):
            if i == masters.get(g):
                continue
            name = channel.name if channel.name not in named else f"{channel.name} (group {g})"
            named[name] = (g, i)
    return named


def _check_wanted(wanted: set[str], named: dict[str, tuple[int, int]]) -> None:
    missing = sorted(wanted - named.keys())
    if missing:
        shown = list(named)[:50]
        more = f" (and {len(named) - 50} more)" if len(named) > 50 else ""
        raise InputError(
            f"channel{'s' if len(missing) > 1 else ''} {', '.join(repr(n) for n in missing)} "
            f"not in the file; it has {shown}{more}",
            field="channels",
        )


def _track(name: str, signal: Any, channel: Any, major: int, notes: list[str]) -> Track | None:
    """The channel as a track: float64 values, NaN where non-finite or invalid; ``None``
    (noted) for a channel that is not a numeric scalar."""
    samples = np.asarray(signal.samples)
    if samples.ndim != 1 or samples.dtype.kind not in "biuf":
        notes.append(f"channel {name!r} skipped: not numeric ({samples.dtype})")
        return None
    values = samples.astype(np.float64)  # a copy: the masked samples are overwritten
    invalid = getattr(signal, "invalidation_bits", None)
    masked = ~np.isfinite(values)
    if invalid is not None:
        masked |= np.asarray(invalid, dtype=bool)
    values[masked] = np.nan
    conversion = channel.conversion
    kind = conversion.conversion_type if conversion is not None else None
    hold = kind in _TABLES[major] or (
        kind in _NO_CONVERSION[major]
        and channel.data_type in _INTEGERS[major]
        and channel.bit_count <= MAX_HELD_BITS
    )
    if kind in _TEXT_TABLES[major]:
        notes.append(f"channel {name!r}: raw values kept, value table {_table(conversion, values)}")
    time = np.asarray(signal.timestamps, dtype=np.float64)
    return Track(name, str(signal.unit or ""), time, values, hold)


def _table(conversion: Any, values: np.ndarray) -> str:
    """``0='off', 1='idle'`` for the first distinct recorded values of a value→text table."""
    raw = np.unique(values[np.isfinite(values)])[:_TABLE_ENTRIES_NOTED]
    try:
        texts = conversion.convert(raw)
    except Exception:  # a table asammdf cannot apply: the raw values are still right
        return "(not readable)"
    shown = ", ".join(
        f"{v:g}={t.decode('latin-1', 'replace') if isinstance(t, bytes) else t!s}"
        for v, t in zip(raw, texts, strict=True)
    )
    return shown + (", …" if np.unique(values[np.isfinite(values)]).size > raw.size else "")


def _check_time(time: np.ndarray, group: int, master: str) -> None:
    """A group's timestamps: finite and strictly increasing (:class:`Signals`' rule)."""
    try:
        Signals(time, {})
    except SignalError as exc:
        raise InputError(f"channel group {group}: {exc}", field=master) from None


def _detail(exc: Exception, size: int) -> str:
    """What asammdf's exception says, in terms of the upload: its messages name the
    in-memory buffer (``'<_io.BytesIO object at 0x…>' is not a valid MDF file``) or the
    :mod:`struct` call that ran past the end (``unpack requires a buffer of 8 bytes``)."""
    text = " ".join(_BUFFER_REPR.sub("the file", str(exc)).split())
    if isinstance(exc, struct.error):
        return f"a block ends beyond the end of the {size}-byte file"
    if "is not a valid MDF file" in text:
        return "its identification or header block is not valid"
    return text or type(exc).__name__


def _quiet_asammdf_del(unraisable: Any) -> None:
    """Drop the exception asammdf's ``MDF4.__del__``/``MDF3.__del__`` raises for an object
    whose constructor failed on a corrupt file (it closes attributes never set): there is
    nothing to close, and the traceback in the server log would only alarm. Every other
    unraisable exception goes to the previous hook."""
    function = unraisable.object
    if getattr(function, "__name__", "") == "__del__" and getattr(
        function, "__module__", ""
    ).startswith("asammdf."):
        return
    _previous_hook(unraisable)


_BUFFER_REPR = re.compile(r"'?<_io\.BytesIO object at 0x[0-9a-fA-F]+>'?")
_previous_hook = sys.unraisablehook
sys.unraisablehook = _quiet_asammdf_del
