"""Read drive logs from MDF (ASAM MDF 4, and 3) with asammdf.

Every numeric scalar channel becomes a float64 channel with its unit (physical values,
conversions applied); master (time) channels form the time base, text/array/structure
channels are skipped (noted). When the channel groups have different time bases, every
channel is resampled by linear interpolation onto the time base of the group with the most
samples, restricted to the span all groups cover — a resampling stated in the notes.

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
from typing import Any

import numpy as np

from app.io.errors import InputError, too_large, unsupported
from estimation import Signals
from estimation.errors import SignalError

MAGIC = b"MDF     "
_DZ = struct.Struct("<4s4xQQ2sBxIQQ")  # id, length, links, org type, zip type, param, org, data


def read_mdf(data: bytes, *, max_decompressed_bytes: int) -> tuple[Signals, str, list[str]]:
    """Signals, the master channel name and notes of an MDF file."""
    if not data.startswith(MAGIC):
        raise unsupported("not an MDF file (no 'MDF     ' magic)")
    version = data[8:16].decode("ascii", "replace").strip()
    if version[:1] not in ("3", "4"):
        raise unsupported(f"MDF version {version!r} is not supported (3.x and 4.x are)")
    _check_zipped_blocks(data, max_decompressed_bytes)
    groups = _read_groups(data)
    notes: list[str] = []
    groups = [g for g in groups if _usable(g, notes)]
    if not groups:
        raise InputError("the MDF file has no numeric channels", field="file")
    time, channels, units, master = _common_base(groups, notes)
    try:
        signals = Signals(time, channels, units)
    except SignalError as exc:
        raise InputError(str(exc), field=master) from None
    return signals, master, notes


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


def _read_groups(data: bytes) -> list[dict[str, Any]]:
    """Per channel group: master name, timestamps and ``(name, unit, samples)`` of channels."""
    from asammdf import MDF

    groups = []
    # asammdf raises many exception types on malformed files; any of them means "unreadable".
    try:
        with MDF(io.BytesIO(data)) as mdf:
            masters = mdf.masters_db
            seen: set[str] = set()
            for g, group in enumerate(mdf.groups):
                master_index = masters.get(g)
                wanted = [
                    (ch.name, g, i) for i, ch in enumerate(group.channels) if i != master_index
                ]
                if not wanted:
                    continue
                signals = mdf.select(wanted, ignore_value2text_conversions=False)
                master = group.channels[master_index].name if master_index is not None else ""
                entries = []
                for signal in signals:
                    name = signal.name if signal.name not in seen else f"{signal.name} (group {g})"
                    seen.add(name)
                    entries.append((name, signal))
                groups.append({"index": g, "master": master or "time", "channels": entries})
    except InputError:
        raise
    except Exception as exc:
        raise InputError(
            f"the MDF file is truncated or corrupt ({_detail(exc, len(data))})", field="file"
        ) from None
    return groups


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


def _usable(group: dict[str, Any], notes: list[str]) -> bool:
    """Keep the numeric scalar channels of a group (as float64); note the others."""
    kept = []
    time = None
    for name, signal in group["channels"]:
        samples = np.asarray(signal.samples)
        if samples.ndim != 1 or samples.dtype.kind not in "biuf":
            notes.append(f"channel {name!r} skipped: not numeric ({samples.dtype})")
            continue
        values = samples.astype(np.float64)
        invalid = getattr(signal, "invalidation_bits", None)
        if invalid is not None and np.any(np.asarray(invalid)):
            k = int(np.argmax(np.asarray(invalid)))
            raise InputError(
                f"channel {name!r}: sample {k} is marked invalid in the file", field=name
            )
        if not np.all(np.isfinite(values)):
            k = int(np.argmax(~np.isfinite(values)))
            raise InputError(
                f"channel {name!r} has a non-finite value ({values[k]}) at sample {k}", field=name
            )
        time = np.asarray(signal.timestamps, dtype=np.float64)
        kept.append((name, str(signal.unit or ""), values))
    group["channels"] = kept
    group["time"] = time
    return bool(kept)


def _common_base(
    groups: list[dict[str, Any]], notes: list[str]
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, str], str]:
    base = max(groups, key=lambda g: g["time"].size)
    time = base["time"]
    channels: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    if all(np.array_equal(g["time"], time) for g in groups):
        for g in groups:
            for name, unit, values in g["channels"]:
                channels[name], units[name] = values, unit
        return time, channels, units, base["master"]
    for g in groups:
        t = g["time"]
        if t.size == 0:
            raise InputError(f"channel group {g['index']} has no samples", field="file")
        steps = np.diff(t)
        if np.any(steps <= 0):
            k = int(np.argmax(steps <= 0)) + 1
            raise InputError(
                f"time of channel group {g['index']} is not strictly increasing at sample {k} "
                f"({t[k]:g} s after {t[k - 1]:g} s)",
                field=g["master"],
            )
    start = max(float(g["time"][0]) for g in groups)
    stop = min(float(g["time"][-1]) for g in groups)
    time = time[(time >= start) & (time <= stop)]
    if time.size == 0:
        raise InputError("the channel groups' time ranges do not overlap", field="file")
    for g in groups:
        for name, unit, values in g["channels"]:
            channels[name] = np.interp(time, g["time"], values)
            units[name] = unit
    notes.append(
        f"{len(groups)} channel groups with different time bases: resampled linearly onto the "
        f"{time.size} samples of group {base['index']} within {start:g}–{stop:g} s"
    )
    return time, channels, units, base["master"]
