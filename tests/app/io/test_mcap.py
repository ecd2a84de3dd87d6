"""MCAP: mapwise's own export reads back exactly (with the ``mcap`` reader, schemas valid),
generic JSON-schema logs ingest, and broken or hostile files get the right error."""

from __future__ import annotations

import io
import json
import struct

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from app.io.errors import InputError
from app.io.ingest import IngestLimits, ingest
from app.io.mcap_export import MapVersionRecord, run_to_mcap
from estimation import Signals
from estimation.table import Axis

AXES = [Axis("rpm", "1/min", [800.0, 2000.0, 4000.0]), Axis("load", "%", [0.0, 50.0, 100.0])]


def drive(n: int = 500) -> Signals:
    rng = np.random.default_rng(0)
    t = 12.5 + np.arange(n) * 0.01
    return Signals(
        t,
        {"rpm": rng.uniform(800, 4000, n), "load": -rng.normal(0, 1e-7, n), "time": t * 2},
        {"rpm": "1/min", "load": "%", "time": "s"},
    )


def versions() -> list[MapVersionRecord]:
    v = np.arange(9.0).reshape(3, 3) - 4.0
    return [
        MapVersionRecord(100, 13.5, v, np.full((3, 3), 1e4), label=None),
        MapVersionRecord(500, 17.49, v * 2, None, "final", final=True),
    ]


def test_export_reads_back_exactly_and_messages_match_their_schemas() -> None:
    signals = drive()
    data = run_to_mcap(signals=signals, axes=AXES, versions=versions(), metadata={"run_id": "7"})
    reader = make_reader(io.BytesIO(data), validate_crcs=True)
    summary = reader.get_summary()
    assert summary is not None
    assert summary.chunk_indexes
    schemas = {s.id: s for s in summary.schemas.values()}
    counts: dict[str, int] = {}
    for schema, channel, message in reader.iter_messages(log_time_order=True):
        assert (channel.message_encoding, schema.encoding) == ("json", "jsonschema")
        assert schemas[schema.id].name in ("mapwise.Signals", "mapwise.MapVersion")
        document = json.loads(schema.data)
        jsonschema.Draft7Validator.check_schema(document)
        jsonschema.validate(json.loads(message.data), document)
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert counts == {"/signals": 500, "/map": 2}
    metadata = list(reader.iter_metadata())
    assert [(m.name, m.metadata) for m in metadata] == [("mapwise", {"run_id": "7"})]

    maps = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=["/map"])]
    assert maps[1]["label"] == "final"
    assert maps[1]["final"] is True
    assert maps[1]["axes"] == [a.to_dict() for a in AXES]
    assert maps[1]["variances"] == []
    assert maps[0]["shape"] == [3, 3]
    np.testing.assert_array_equal(maps[0]["values"], versions()[0].values.ravel())
    np.testing.assert_array_equal(maps[0]["variances"], versions()[0].variances.ravel())

    ds = ingest(data)
    assert (ds.source, ds.time_column, ds.rows) == ("mcap", "time_s", 500)
    np.testing.assert_array_equal(ds.signals.time, signals.time)
    for name in signals.names:  # 'time' is a data channel here; time_s stays the time base
        np.testing.assert_array_equal(ds.signals[name], signals[name])
        assert ds.signals.units[name] == signals.units[name]


def test_non_finite_variances_are_null_in_strict_json() -> None:
    record = MapVersionRecord(1, 0.0, np.zeros((3, 3)), np.full((3, 3), np.inf))
    data = run_to_mcap(signals=None, axes=AXES, versions=[record])
    ((_, _, message),) = make_reader(io.BytesIO(data)).iter_messages()
    assert json.loads(message.data)["variances"] == [None] * 9


def foxglove_supports(schema: dict, path: str = "") -> None:
    """The subset of JSON schema Foxglove's parseJsonSchema (mcap-support) accepts."""
    assert schema.get("type") == "object", path
    for name, sub in schema["properties"].items():
        kind = sub.get("type")
        assert kind in ("boolean", "string", "number", "integer", "object", "array"), name
        if kind == "object":
            foxglove_supports(sub, f"{path}.{name}")
        if kind == "array":
            item = sub["items"]
            assert item.get("type") in ("boolean", "string", "number", "integer", "object"), name
            if item["type"] == "object":
                foxglove_supports(item, f"{path}.{name}[]")


def test_schemas_stay_within_what_foxglove_reads() -> None:
    data = run_to_mcap(signals=drive(3), axes=AXES, versions=versions())
    summary = make_reader(io.BytesIO(data)).get_summary()
    assert summary is not None
    for schema in summary.schemas.values():
        foxglove_supports(json.loads(schema.data))


def test_log_times_are_nanoseconds_from_the_first_sample() -> None:
    data = run_to_mcap(signals=drive(3), axes=None, versions=[])
    reader = make_reader(io.BytesIO(data))
    assert [m.log_time for _, _, m in reader.iter_messages()] == [0, 10_000_000, 20_000_000]


def test_export_refuses_a_channel_named_like_the_time_property() -> None:
    s = Signals([0.0, 1.0], {"time_s": [1.0, 2.0]})
    with pytest.raises(InputError, match="time_s"):
        run_to_mcap(signals=s, axes=None, versions=[])


def write_mcap(
    topics: dict[str, tuple[dict | str | None, list[tuple[int, bytes]]]],
    *,
    encoding: str = "json",
    schema_encoding: str = "jsonschema",
    compression: CompressionType = CompressionType.ZSTD,
) -> bytes:
    buffer = io.BytesIO()
    writer = Writer(buffer, compression=compression)
    writer.start()
    for topic, (schema, messages) in topics.items():
        schema_id = 0
        if schema is not None:
            raw = schema.encode() if isinstance(schema, str) else json.dumps(schema).encode()
            schema_id = writer.register_schema(topic.strip("/"), schema_encoding, raw)
        channel_id = writer.register_channel(topic, encoding, schema_id)
        for log_time, data in messages:
            writer.add_message(channel_id, log_time=log_time, data=data, publish_time=log_time)
    writer.finish()
    return buffer.getvalue()


def number_schema(*names: str, nested: str | None = None) -> dict:
    props: dict = {n: {"type": "number", "unit": "V"} for n in names}
    if nested:
        props = {nested: {"type": "object", "properties": props}, "label": {"type": "string"}}
    return {"type": "object", "properties": props}


def msgs(rows: list[dict], *, period_ns: int = 10_000_000, start: int = 1_700_000_000 * 10**9):
    return [(start + k * period_ns, json.dumps(r).encode()) for k, r in enumerate(rows)]


def test_generic_topics_are_flattened_prefixed_and_resampled() -> None:
    engine = [{"ecu": {"rpm": 1000.0 + k, "map": 50.0}, "label": "x"} for k in range(101)]
    coolant = [{"temp": 80.0 + k} for k in range(11)]
    data = write_mcap(
        {
            "/engine": (number_schema("rpm", "map", nested="ecu"), msgs(engine)),
            "/coolant": (number_schema("temp"), msgs(coolant, period_ns=100_000_000)),
            "/camera": ({"type": "object"}, msgs([{"x": 1}])),
        }
    )
    ds = ingest(data)
    assert ds.signals.names == ["engine.ecu.rpm", "engine.ecu.map", "coolant.temp"]
    assert ds.time_column is None  # log_time
    np.testing.assert_allclose(ds.signals.time, np.arange(101) * 0.01, atol=1e-12)
    np.testing.assert_allclose(ds.signals["coolant.temp"], 80.0 + np.arange(101) * 0.1)
    assert any("resampled linearly" in n for n in ds.notes)
    assert any("/camera: skipped" in n for n in ds.notes)


def test_single_topic_keeps_plain_names_and_its_time_property() -> None:
    rows = [{"t": 0.5 * k, "rpm": 900.0 + k} for k in range(4)]
    data = write_mcap({"/log": (number_schema("t", "rpm"), msgs(rows))})
    ds = ingest(data)
    assert (ds.signals.names, ds.time_column) == (["rpm"], "t")
    np.testing.assert_array_equal(ds.signals.time, [0.0, 0.5, 1.0, 1.5])


def patch_first(data: bytes, opcode: int, offset: int, fmt: str, value: int) -> bytes:
    """Overwrite a field ``offset`` bytes into the body of the first record ``opcode``."""
    pos = 8
    while pos < len(data) - 8:
        op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        if op == opcode:
            out = bytearray(data)
            struct.pack_into(fmt, out, pos + 9 + offset, value)
            return bytes(out)
        pos += 9 + length
    raise AssertionError(f"no record {opcode:#x}")


GOOD = [{"time_s": 0.1 * k, "rpm": 1000.0} for k in range(5)]
SCHEMA = number_schema("time_s", "rpm")
CHUNK = 0x06


DEEP = b"[" * 100_000 + b"]" * 100_000  # deeper than json.loads recurses


def bad_mcaps() -> list:
    good = write_mcap({"/e": (SCHEMA, msgs(GOOD))})
    bomb_rows = [{"time_s": 0.0, "rpm": 1.0, "pad": "0" * 4_000_000}, {"time_s": 1.0, "rpm": 2.0}]
    return [
        ("truncated", good[: len(good) // 2], "validation_error", "file", "trailing magic"),
        (
            "truncated after magic",
            good[:12] + good[-8:],
            "validation_error",
            "file",
            "corrupt MCAP",
        ),
        (
            "lying record length",
            patch_first(good, 0x01, -8, "<Q", 2**40),
            "validation_error",
            "file",
            "corrupt MCAP",
        ),
        (
            "lying chunk size",
            patch_first(good, CHUNK, 16, "<Q", 10),
            "validation_error",
            "file",
            "declares 10 bytes uncompressed",
        ),
        (
            "bad chunk crc",
            patch_first(good, CHUNK, 24, "<I", 12345),
            "validation_error",
            "file",
            "corrupt MCAP",
        ),
        (
            "decompression bomb",
            write_mcap({"/e": (SCHEMA, msgs(bomb_rows))}),
            "payload_too_large",
            "file",
            "decompress to more than",
        ),
        (
            "protobuf only",
            write_mcap(
                {"/e": ("message E {}", msgs(GOOD))},
                encoding="protobuf",
                schema_encoding="protobuf",
            ),
            "unsupported_format",
            "file",
            "message encoding 'protobuf'",
        ),
        (
            "schemaless json",
            write_mcap({"/e": (None, msgs(GOOD))}),
            "unsupported_format",
            "file",
            "no schema",
        ),
        (
            "schema not json",
            write_mcap({"/e": ("{not json", msgs(GOOD))}),
            "validation_error",
            "/e",
            "schema is not valid JSON",
        ),
        (
            "schema without numbers",
            write_mcap({"/e": ({"type": "string"}, msgs(GOOD))}),
            "unsupported_format",
            "file",
            "no numeric properties",
        ),
        (
            "string where schema says number",
            write_mcap({"/e": (SCHEMA, msgs([*GOOD, {"time_s": 9.0, "rpm": "fast"}]))}),
            "validation_error",
            "/e.rpm",
            "message 5, property 'rpm': non-numeric value 'fast'",
        ),
        (
            "missing property",
            write_mcap({"/e": (SCHEMA, msgs([*GOOD, {"time_s": 9.0}]))}),
            "validation_error",
            "/e.rpm",
            "message 5 has no property 'rpm'",
        ),
        (
            "NaN in message",
            write_mcap({"/e": (SCHEMA, [(0, b'{"time_s": 0, "rpm": NaN}')])}),
            "validation_error",
            "/e.rpm",
            "nan is not allowed",
        ),
        (
            "message not json",
            write_mcap({"/e": (SCHEMA, [(0, b"\x00\x01")])}),
            "validation_error",
            "/e",
            "message 0 is not valid JSON",
        ),
        (
            "duplicate time",
            write_mcap({"/e": (SCHEMA, msgs([GOOD[0], GOOD[0]]))}),
            "validation_error",
            "time_s",
            "duplicate time 0 s at sample 1",
        ),
        (
            "one message",
            write_mcap({"/e": (SCHEMA, msgs(GOOD[:1]))}),
            "validation_error",
            "file",
            "too few samples",
        ),
        ("no channels", write_mcap({}), "unsupported_format", "file", "no usable channel"),
        (
            "message nested too deeply",
            write_mcap({"/e": (SCHEMA, [(0, b'{"time_s": 0, "x": ' + DEEP + b"}")])}),
            "validation_error",
            "/e",
            "message 0 is nested too deeply",
        ),
        (
            "schema nested too deeply",
            write_mcap({"/e": ('{"properties": ' + DEEP.decode() + "}", msgs(GOOD))}),
            "validation_error",
            "/e",
            "the schema is nested too deeply",
        ),
    ]


@pytest.mark.parametrize(
    ("data", "code", "field", "message"), [pytest.param(*c[1:], id=c[0]) for c in bad_mcaps()]
)
def test_bad_mcap_corpus(data: bytes, code: str, field: str, message: str) -> None:
    with pytest.raises(InputError) as info:
        ingest(data, limits=IngestLimits(max_decompressed_bytes=1_000_000))
    err = info.value
    assert (err.code, err.field) == (code, field), str(err)
    assert message in err.message


def test_uncompressed_and_lz4_chunks_read_too() -> None:
    for compression in (CompressionType.NONE, CompressionType.LZ4):
        data = write_mcap({"/e": (SCHEMA, msgs(GOOD))}, compression=compression)
        assert ingest(data).rows == 5
