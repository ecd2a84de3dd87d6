"""Read drive logs from MCAP: JSON-encoded messages whose channels carry a JSON schema.

Each channel (topic) whose message encoding is ``json`` and whose schema encoding is
``jsonschema`` contributes its numeric schema properties as channels (nested objects are
flattened with ``.``; the ``unit`` keyword of a property, if any, is its unit). The time
base is a top-level numeric property named like a time column (``time_s`` in mapwise's own
export), else the message ``log_time`` in seconds relative to the first message.

Untrusted input: the leading and trailing magic are checked, no record may declare more
bytes than the file holds, chunk CRCs are validated, and decompression is capped.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import struct
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.io.csv_sniff import TIME_COLUMNS
from app.io.errors import InputError, too_large, unsupported
from estimation import Signals
from estimation.errors import SignalError

MAGIC = b"\x89MCAP0\r\n"
MAP_VERSION_SCHEMA = "mapwise.MapVersion"
# mapwise writes "time_s"; a data channel called "time" must not shadow it.
TIME_PROPERTIES = ("time_s", *(c for c in TIME_COLUMNS if c != "time_s"))


@dataclass
class _Topic:
    topic: str
    properties: list[tuple[tuple[str, ...], str]]  # (path, unit) of numeric properties
    time_property: str | None
    messages: list[tuple[int, bytes]] = dataclasses.field(default_factory=list)


def read_mcap(
    data: bytes, *, time_column: str | None = None, max_decompressed_bytes: int
) -> tuple[Signals, str | None, list[str]]:
    """Signals, the time property used (``None``: ``log_time``) and notes of an MCAP file."""
    if not data.startswith(MAGIC):
        raise unsupported("not an MCAP file (no leading magic)")
    if len(data) < 2 * len(MAGIC) or not data.endswith(MAGIC):
        raise InputError("truncated MCAP file: the trailing magic is missing", field="file")
    schemas, channels, messages = _read_records(data, max_decompressed_bytes)
    notes: list[str] = []
    topics: list[_Topic] = []
    for channel_id, channel in sorted(channels.items()):
        topic = _usable_topic(channel, schemas.get(channel.schema_id), time_column, notes)
        if topic is not None:
            topic.messages = messages.get(channel_id, [])
            if topic.messages:
                topics.append(topic)
            else:
                notes.append(f"topic {topic.topic}: no messages")
    if not topics:
        detail = "; ".join(notes) or "the file has no channels"
        raise unsupported(
            "no usable channel: mapwise reads JSON messages with a jsonschema schema "
            f"and numeric properties ({detail})"
        )
    t0 = min(log_time for t in topics for log_time, _ in t.messages)
    blocks = [_decode_topic(t, prefix=len(topics) > 1, t0=t0) for t in topics]
    time_used = blocks[0][3] if len(blocks) == 1 else None
    time, channels_out, units = _merge(blocks, notes)
    try:
        signals = Signals(time, channels_out, units)
    except SignalError as exc:
        raise InputError(str(exc), field=time_used or "log_time") from None
    return signals, time_used, notes


def _read_records(
    data: bytes, max_decompressed_bytes: int
) -> tuple[dict[int, Any], dict[int, Any], dict[int, list[tuple[int, bytes]]]]:
    from mcap.exceptions import McapError
    from mcap.records import Channel, Chunk, Message, Schema
    from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk

    schemas: dict[int, Any] = {}
    channels: dict[int, Any] = {}
    messages: dict[int, list[tuple[int, bytes]]] = defaultdict(list)
    budget = max_decompressed_bytes
    reader = StreamReader(
        io.BytesIO(data), emit_chunks=True, validate_crcs=True, record_size_limit=len(data)
    )

    def records() -> Iterator[Any]:
        nonlocal budget
        for record in reader.records:
            if isinstance(record, Chunk):
                if record.uncompressed_size > budget:
                    raise too_large(
                        f"MCAP chunks decompress to more than {max_decompressed_bytes} bytes"
                    )
                budget -= record.uncompressed_size
                plain = dataclasses.replace(
                    record, compression="", data=_decompress(record), uncompressed_size=0
                )
                yield from breakup_chunk(plain, validate_crc=True)
            else:
                yield record

    try:
        for record in records():
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                messages[record.channel_id].append((record.log_time, record.data))
    except InputError:
        raise
    except (McapError, CRCValidationError, struct.error, UnicodeDecodeError, ValueError) as exc:
        raise InputError(
            f"corrupt MCAP file: {type(exc).__name__}: {exc}".rstrip(": "), field="file"
        ) from None
    return schemas, channels, messages


def _decompress(chunk: Any) -> bytes:
    """Chunk data, never more than the declared ``uncompressed_size`` bytes."""
    size = chunk.uncompressed_size
    if chunk.compression == "":
        out = chunk.data
    elif chunk.compression == "zstd":
        import zstandard

        reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(chunk.data))
        out = reader.read(size + 1)
    elif chunk.compression == "lz4":
        import lz4.frame

        out = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=size + 1)
    else:
        raise unsupported(f"MCAP chunk compression {chunk.compression!r} is not supported")
    if len(out) != size:
        raise InputError(
            f"corrupt MCAP chunk: declares {size} bytes uncompressed, holds "
            f"{'more' if len(out) > size else len(out)}",
            field="file",
        )
    return out


def _usable_topic(
    channel: Any, schema: Any, time_column: str | None, notes: list[str]
) -> _Topic | None:
    topic = channel.topic
    if channel.message_encoding != "json":
        notes.append(f"topic {topic}: skipped, message encoding {channel.message_encoding!r}")
        return None
    if schema is None:
        notes.append(f"topic {topic}: skipped, no schema")
        return None
    if schema.encoding != "jsonschema":
        notes.append(f"topic {topic}: skipped, schema encoding {schema.encoding!r}")
        return None
    if schema.name == MAP_VERSION_SCHEMA:
        notes.append(f"topic {topic}: map versions, not a signal")
        return None
    try:
        document = json.loads(schema.data)
        properties = list(_numeric_properties(document, ()))
    except RecursionError:
        raise InputError(f"topic {topic}: the schema is nested too deeply", field=topic) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(
            f"topic {topic}: the schema is not valid JSON ({exc})", field=topic
        ) from None
    names = [p[0] for p, _ in properties if len(p) == 1]
    wanted = [time_column] if time_column else list(TIME_PROPERTIES)
    time_property = next((n for n in wanted if n in names), None)
    if time_column and time_property is None:
        raise InputError(
            f"topic {topic}: no numeric property {time_column!r} for the time base", field=topic
        )
    properties = [(p, u) for p, u in properties if p != (time_property,)]
    if not properties:
        notes.append(f"topic {topic}: skipped, its schema has no numeric properties")
        return None
    return _Topic(topic, properties, time_property)


def _numeric_properties(
    schema: Any, path: tuple[str, ...]
) -> Iterator[tuple[tuple[str, ...], str]]:
    if not isinstance(schema, dict) or not isinstance(schema.get("properties"), dict):
        return
    for name, sub in schema["properties"].items():
        if not isinstance(sub, dict):
            continue
        kind = sub.get("type")
        kinds = kind if isinstance(kind, list) else [kind]
        if any(k in ("number", "integer") for k in kinds):
            yield (*path, name), str(sub.get("unit", ""))
        elif "object" in kinds:
            yield from _numeric_properties(sub, (*path, name))


def _decode_topic(
    topic: _Topic, *, prefix: bool, t0: int
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, str], str | None]:
    """Time, channels, units and time property of one topic's messages."""
    messages = topic.messages
    if topic.time_property is None:
        messages = sorted(messages, key=lambda m: m[0])
    decoded = []
    for k, (_, raw) in enumerate(messages):
        try:
            message = json.loads(raw)
        except RecursionError:
            raise InputError(
                f"topic {topic.topic}: message {k} is nested too deeply", field=topic.topic
            ) from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputError(
                f"topic {topic.topic}: message {k} is not valid JSON ({exc})", field=topic.topic
            ) from None
        if not isinstance(message, dict):
            raise InputError(
                f"topic {topic.topic}: message {k} is not a JSON object", field=topic.topic
            )
        decoded.append(message)
    if topic.time_property is None:
        time = np.array([(log_time - t0) for log_time, _ in messages], dtype=np.float64) * 1e-9
    else:
        time = _column(decoded, (topic.time_property,), topic.topic)
    base = topic.topic.strip("/")
    channels: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    for path, unit in topic.properties:
        name = ".".join(path)
        key = f"{base}.{name}" if prefix else name
        channels[key] = _column(decoded, path, topic.topic)
        units[key] = unit
    return time, channels, units, topic.time_property


def _column(messages: list[dict[str, Any]], path: tuple[str, ...], topic: str) -> np.ndarray:
    name = ".".join(path)
    field = f"{topic}.{name}"
    out = np.empty(len(messages))
    for k, message in enumerate(messages):
        value: Any = message
        for part in path:
            if not isinstance(value, dict) or part not in value:
                raise InputError(
                    f"topic {topic}: message {k} has no property {name!r} required by its schema",
                    field=field,
                )
            value = value[part]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InputError(
                f"topic {topic}: message {k}, property {name!r}: non-numeric value {value!r}",
                field=field,
            )
        if not math.isfinite(value):
            raise InputError(
                f"topic {topic}: message {k}, property {name!r}: {value} is not allowed "
                "(values must be finite)",
                field=field,
            )
        out[k] = value
    return out


def _merge(
    blocks: list[tuple[np.ndarray, dict[str, np.ndarray], dict[str, str], str | None]],
    notes: list[str],
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, str]]:
    """One time base for all topics: shared if identical, else the longest topic's (linear)."""
    channels: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    base = max(range(len(blocks)), key=lambda i: blocks[i][0].size)
    time = blocks[base][0]
    if all(b[0].shape == time.shape and np.array_equal(b[0], time) for b in blocks):
        for _, ch, un, _ in blocks:
            channels.update(ch)
            units.update(un)
        return time, channels, units
    start = max(b[0][0] for b in blocks)
    stop = min(b[0][-1] for b in blocks)
    keep = (time >= start) & (time <= stop)
    if not np.any(keep):
        raise InputError("the topics' time ranges do not overlap", field="file")
    time = time[keep]
    for t, ch, un, _ in blocks:
        _require_increasing(t, next(iter(ch)))
        for name, values in ch.items():
            channels[name] = np.interp(time, t, values)
        units.update(un)
    notes.append(
        f"topics have different time bases: resampled linearly onto the {time.size} samples of "
        f"the longest topic within the common span {start:g}–{stop:g} s"
    )
    return time, channels, units


def _require_increasing(t: np.ndarray, name: str) -> None:
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0)) + 1
        raise InputError(
            f"time of {name!r} is not strictly increasing at message {k} ({t[k]:g} s after "
            f"{t[k - 1]:g} s)",
            field=name,
        )
