"""A run as MCAP: time series and map versions as JSON messages with JSON schemas.

Topics (message encoding ``json``, schema encoding ``jsonschema``, zstd chunks — what the
``mcap`` Python reader and Foxglove read):

- ``/signals`` (schema ``mapwise.Signals``): one message per sample,
  ``{"time_s": t, "<channel>": value, ...}``; each property's ``unit`` keyword (and
  description) gives its unit. Plot ``/signals.<channel>`` in Foxglove.
- ``/map`` (schema ``mapwise.MapVersion``): one message per persisted map version,
  ``{"step", "time_s", "label", "final", "axes": [{"name", "unit", "breakpoints"}],
  "shape", "values", "variances"}`` with values and variances flat in C order (``[]``: no
  variances) — Foxglove's JSON-schema reader takes no nested arrays.

``log_time`` is ``time_s − t₀`` in integer nanoseconds (t₀: the first sample). Numbers are
written with ``repr``, so :func:`app.io.ingest.ingest` reads ``/signals`` back exactly.
Non-finite variances (a diverged filter) are written as ``null``.
"""

from __future__ import annotations

import io
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.io.errors import InputError
from estimation import Signals
from estimation.table import Axis

SIGNALS_TOPIC = "/signals"
MAP_TOPIC = "/map"
SIGNALS_SCHEMA = "mapwise.Signals"
MAP_SCHEMA = "mapwise.MapVersion"
TIME_PROPERTY = "time_s"


@dataclass(frozen=True, slots=True)
class MapVersionRecord:
    """One persisted map version: values (and variances) shaped like the table."""

    step: int
    time_s: float
    values: np.ndarray
    variances: np.ndarray | None = None
    label: str | None = None
    final: bool = False


def signals_schema(signals: Signals) -> dict[str, Any]:
    """The JSON schema of a ``/signals`` message."""
    properties: dict[str, Any] = {
        TIME_PROPERTY: {"type": "number", "unit": "s", "description": "time [s]"}
    }
    for name in signals.names:
        unit = signals.units.get(name, "")
        properties[name] = {"type": "number", "unit": unit, "description": f"{name} [{unit}]"}
    return {
        "$schema": "http://json-schema.org/draft-07/schema#",
        "title": SIGNALS_SCHEMA,
        "type": "object",
        "properties": properties,
        "required": list(properties),
    }


def map_version_schema() -> dict[str, Any]:
    """The JSON schema of a ``/map`` message.

    Only constructs Foxglove's JSON-schema reader accepts: one ``type`` string per
    property, arrays of numbers/integers/objects (no nested arrays, ``null`` or ``anyOf``),
    hence flat C-order ``values``/``variances`` with their ``shape``.
    """
    numbers = {"type": "array", "items": {"type": "number"}}
    return {
        "$schema": "http://json-schema.org/draft-07/schema#",
        "title": MAP_SCHEMA,
        "type": "object",
        "properties": {
            "step": {"type": "integer", "description": "log samples consumed"},
            "time_s": {"type": "number", "unit": "s"},
            "label": {"type": "string", "description": "empty when unlabelled"},
            "final": {"type": "boolean"},
            "axes": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "name": {"type": "string"},
                        "unit": {"type": "string"},
                        "breakpoints": numbers,
                    },
                    "required": ["name", "unit", "breakpoints"],
                },
            },
            "shape": {"type": "array", "items": {"type": "integer"}},
            "values": {**numbers, "description": "table values, flat C order"},
            "variances": {
                **numbers,
                "description": "variance of each value, flat C order; empty when the "
                "estimator has none",
            },
        },
        "required": ["step", "time_s", "label", "final", "axes", "shape", "values", "variances"],
    }


def run_to_mcap(
    *,
    signals: Signals | None,
    axes: Sequence[Axis] | None,
    versions: Sequence[MapVersionRecord],
    metadata: Mapping[str, str] | None = None,
) -> bytes:
    """MCAP bytes of a run's time series and map versions (either may be empty)."""
    from mcap.writer import CompressionType, Writer

    if versions and not axes:
        raise InputError("map versions need the table axes", field="axes")
    if signals is not None and TIME_PROPERTY in signals:
        raise InputError(
            f"a channel is called {TIME_PROPERTY!r}, the name of the time property",
            field=TIME_PROPERTY,
        )
    t0 = _first_time(signals, versions)
    events: list[tuple[int, int, int, bytes]] = []  # (log_time, order, channel, data)
    buffer = io.BytesIO()
    writer = Writer(buffer, compression=CompressionType.ZSTD)
    writer.start(profile="", library="mapwise")
    if signals is not None and len(signals):
        schema_id = writer.register_schema(
            SIGNALS_SCHEMA, "jsonschema", json.dumps(signals_schema(signals)).encode()
        )
        channel_id = writer.register_channel(SIGNALS_TOPIC, "json", schema_id)
        for k, (log_time, data) in enumerate(_signal_messages(signals, t0)):
            events.append((log_time, k, channel_id, data))
    if versions:
        assert axes is not None
        schema_id = writer.register_schema(
            MAP_SCHEMA, "jsonschema", json.dumps(map_version_schema()).encode()
        )
        channel_id = writer.register_channel(MAP_TOPIC, "json", schema_id)
        axes_doc = [a.to_dict() for a in axes]
        for version in versions:
            data = _map_message(version, axes_doc)
            events.append((_log_time(version.time_s, t0), len(events), channel_id, data))
    events.sort(key=lambda e: (e[0], e[1]))
    sequence: dict[int, int] = {}
    for log_time, _, channel_id, data in events:
        sequence[channel_id] = sequence.get(channel_id, -1) + 1
        writer.add_message(
            channel_id=channel_id,
            log_time=log_time,
            data=data,
            publish_time=log_time,
            sequence=sequence[channel_id],
        )
    if metadata:
        writer.add_metadata("mapwise", {str(k): str(v) for k, v in metadata.items()})
    writer.finish()
    return buffer.getvalue()


def _first_time(signals: Signals | None, versions: Sequence[MapVersionRecord]) -> float:
    times = [float(v.time_s) for v in versions]
    if signals is not None and len(signals):
        times.append(float(signals.time[0]))
    return min(times) if times else 0.0


def _log_time(t: float, t0: float) -> int:
    return max(0, round((t - t0) * 1e9))


def _signal_messages(signals: Signals, t0: float) -> list[tuple[int, bytes]]:
    keys = [TIME_PROPERTY, *signals.names]
    template = "{" + ",".join(f"{json.dumps(k)}:%r" for k in keys) + "}"
    rows = np.column_stack([signals.time, *(signals[n] for n in signals.names)]).tolist()
    log_times = np.maximum(0, np.round((signals.time - t0) * 1e9)).astype(np.int64).tolist()
    return [
        (log_time, (template % tuple(row)).encode())
        for log_time, row in zip(log_times, rows, strict=True)
    ]


def _map_message(version: MapVersionRecord, axes: list[dict[str, Any]]) -> bytes:
    values = np.asarray(version.values, dtype=np.float64)
    document = {
        "step": int(version.step),
        "time_s": float(version.time_s),
        "label": version.label or "",
        "final": bool(version.final),
        "axes": axes,
        "shape": list(values.shape),
        "values": _flat(values),
        "variances": [] if version.variances is None else _flat(version.variances),
    }
    return json.dumps(document, allow_nan=False).encode()


def _flat(array: np.ndarray) -> list[float | None]:
    """Flat C-order list; a non-finite entry (never in values, only in a diverged filter's
    variances) is written as ``null``, the one strict-JSON spelling of "no number"."""
    arr = np.asarray(array, dtype=np.float64).reshape(-1)
    if np.all(np.isfinite(arr)):
        return arr.tolist()
    obj = arr.astype(object)
    obj[~np.isfinite(arr)] = None
    return obj.tolist()
