"""The bad-file corpus: each upload gets the right 4xx and leaves the database unchanged
(SQLite and PostgreSQL); MCAP and MDF4 uploads that are fine are accepted."""

from __future__ import annotations

import io
import json
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.api import create_app
from tests.support.helpers import service_settings, upload


def _mcap(
    message: dict, schema: dict, *, schema_encoding: str = "jsonschema", encoding: str = "json"
) -> bytes:
    from mcap.writer import Writer

    buffer = io.BytesIO()
    writer = Writer(buffer)
    writer.start()
    schema_id = writer.register_schema("s", schema_encoding, json.dumps(schema).encode())
    channel = writer.register_channel("/t", encoding, schema_id)
    for k in range(5):
        data = json.dumps({**message, "time_s": k * 0.1}).encode()
        writer.add_message(channel, log_time=k * 10**8, data=data, publish_time=k * 10**8)
    writer.finish()
    return buffer.getvalue()


NUMBER_SCHEMA = {
    "type": "object",
    "properties": {"time_s": {"type": "number"}, "x": {"type": "number"}},
}

CORPUS = {
    "truncated": (b"time,a,b\n0,1,2\n1,2,3\n2,3", 422, "file"),
    "wrong delimiter": (b"time|a|b\n0|1|2\n1|2|3\n", 422, "file"),
    "only masked samples": (b"time,a\n0,nan\n1,-inf\n2,3\n", 422, "file"),  # 1 usable
    "inf in the time column": (b"time,a\n0,1\ninf,2\n2,3\n", 422, "time"),
    "text in a numeric column": (b"time,a\n0,1\n1,abc\n2,3\n", 422, "a"),
    "duplicate timestamps": (b"time,a\n0,1\n1,2\n1,3\n", 422, "time"),
    "decreasing time": (b"time,a\n0,1\n2,2\n1,3\n", 422, "time"),
    "0 rows": (b"time,a,b\n", 422, "file"),
    "empty file": (b"", 422, "file"),
    "huge header": (
        ("time," + ",".join(f"c{i}" for i in range(20000)) + "\n0" + ",1" * 20000).encode(),
        422,
        "header",
    ),
    "binary garbage": (bytes(range(256)) * 10, 415, "file"),
    "MCAP with a wrong schema": (_mcap({"x": "bad"}, NUMBER_SCHEMA), 422, "/t.x"),
    "MCAP with protobuf messages": (
        _mcap({"x": 1.0}, NUMBER_SCHEMA, schema_encoding="protobuf", encoding="protobuf"),
        415,
        "file",
    ),
}


def _count(database_url: str) -> dict[str, int]:
    """Rows in every table of the schema, read straight from the database."""
    from sqlalchemy import create_engine, func, select

    from app.db.engine import normalise_url
    from app.db.models import Base

    engine = create_engine(normalise_url(database_url))
    try:
        with engine.connect() as conn:
            return {
                name: conn.scalar(select(func.count()).select_from(table)) or 0
                for name, table in Base.metadata.tables.items()
            }
    finally:
        engine.dispose()


@pytest.mark.parametrize("case", list(CORPUS))
def test_bad_file_is_refused_and_nothing_is_stored(
    client: TestClient, database_url: str, case: str
) -> None:
    content, status, field = CORPUS[case]
    before = _count(database_url)
    assert "datasets" in before
    response = upload(client, content, name="upload.bin")
    assert response.status_code == status, response.text
    error = response.json()["error"]
    assert error["field"] == field
    assert error["code"] == ("unsupported_format" if status == 415 else "validation_error")
    assert error["message"]
    assert _count(database_url) == before


def test_messages_name_line_and_column(client: TestClient) -> None:
    error = upload(client, b"time,rpm\n0,1\n1,2\n2,x\n").json()["error"]
    assert "line 4" in error["message"]
    assert "'rpm'" in error["message"]


def test_missing_file_field_is_a_validation_error(client: TestClient) -> None:
    response = client.post("/api/datasets", data={"name": "x"})
    assert response.status_code == 422
    assert response.json()["error"]["field"] == "file"


def test_bad_units_field(client: TestClient, database_url: str) -> None:
    before = _count(database_url)
    response = upload(client, b"time,a\n0,1\n1,2\n", units="{not json")
    assert response.status_code == 422
    assert response.json()["error"]["field"] == "units"
    response = upload(client, b"time,a\n0,1\n1,2\n", units=json.dumps({"zzz": "bar"}))
    assert response.status_code == 422
    assert response.json()["error"]["field"] == "units.zzz"
    assert _count(database_url) == before


def test_good_mcap_and_mdf4_uploads(client: TestClient, tmp_path) -> None:  # type: ignore[no-untyped-def]
    response = upload(client, _mcap({"x": 1.5}, NUMBER_SCHEMA), name="log.mcap")
    assert response.status_code == 201, response.text
    assert response.json()["source"] == "mcap"
    assert response.json()["rows"] == 5

    from asammdf import MDF, Signal

    t = np.arange(100) * 0.01
    mdf = MDF(version="4.10")
    mdf.append([Signal(np.sin(t), t, name="rpm", unit="1/min")])
    path = tmp_path / "log.mf4"
    mdf.save(path, overwrite=True)
    response = upload(client, path.read_bytes(), name="log.mf4")
    assert response.status_code == 201, response.text
    doc = response.json()
    assert (doc["source"], doc["rows"]) == ("mdf4", 100)
    assert {"name": "rpm", "unit": "1/min"} in doc["channels"]


@pytest.fixture(scope="module")
def small_limit_client(database_url: str) -> Iterator[TestClient]:
    """The app with a 10 KiB upload limit (no run workers needed)."""
    settings = service_settings(database_url, max_upload_mb=0.01)
    with TestClient(create_app(settings, execute_runs=False)) as c:
        yield c


def test_file_too_large_is_413_and_stores_nothing(
    small_limit_client: TestClient, database_url: str
) -> None:
    client = small_limit_client
    before = _count(database_url)
    big = b"time,a\n" + b"".join(f"{k},{k}\n".encode() for k in range(3000))  # ~20 KB
    response = upload(client, big)
    assert response.status_code == 413
    assert response.json()["error"] == {
        "code": "payload_too_large",
        "message": response.json()["error"]["message"],
        "field": "file",
    }
    huge = b"time,a\n" + b"0,0\n" * 400_000  # over the body limit itself: cut while streaming
    response = upload(client, huge)
    assert response.status_code == 413
    assert response.json()["error"]["code"] == "payload_too_large"
    assert _count(database_url) == before
    small = upload(client, b"time,a\n0,1\n1,2\n")
    assert small.status_code == 201


def test_the_whole_read_limit_holds_through_the_api(database_url: str) -> None:
    """MAPWISE_MAX_WHOLE_MB bounds what is read whole even when MAPWISE_MAX_UPLOAD_MB is
    larger (a file under 16 MiB, an MCAP or MDF file, a CSV that cannot stream)."""
    settings = service_settings(database_url, max_upload_mb=1, max_whole_mb=0.01)
    with TestClient(create_app(settings, execute_runs=False)) as client:
        before = _count(database_url)
        big = b"time,a\n" + b"".join(f"{k},{k}\n".encode() for k in range(3000))  # ~20 KB
        response = upload(client, big)
        assert response.status_code == 413
        assert response.json()["error"]["code"] == "payload_too_large"
        assert _count(database_url) == before
        assert upload(client, b"time,a\n0,1\n1,2\n").status_code == 201


@pytest.fixture(scope="module")
def measurement_mf4(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    from tests.support.measurements import write_measurement

    return write_measurement(tmp_path_factory.mktemp("mf4")).bytes()


def test_multirate_mdf4_upload_reports_masked_samples_and_keeps_names(
    client: TestClient, measurement_mf4: bytes
) -> None:
    """Through the real app: the enumeration, the ±inf channel and the 1 kHz group among
    10 ms and 100 ms groups ingest; the default raster is the slowest (100 ms)."""
    from tests.support.measurements import NMOT, POLE, T100

    response = upload(client, measurement_mf4, name="canape.mf4")
    assert response.status_code == 201, response.text
    doc = response.json()
    assert (doc["source"], doc["rows"]) == ("mdf4", T100.size)
    assert doc["rate_hz"] == pytest.approx(10.0)
    assert {"name": NMOT, "unit": "1/min"} in doc["channels"]
    assert doc["masked"] == {POLE: 10, "lambda": 3}
    assert any("value table 0=off, 1=idle, 2=run" in n for n in doc["notes"])
    again = client.get(f"/api/datasets/{doc['id']}").json()
    assert again["channels"] == doc["channels"]
    assert (again["notes"], again["masked"]) == (doc["notes"], doc["masked"])  # stored
    preview = client.get(f"/api/datasets/{doc['id']}/preview").json()
    assert NMOT in preview["channels"]


def test_get_gives_what_the_upload_gave(client: TestClient, measurement_mf4: bytes) -> None:
    """Notes and masked counts are stored with the dataset: ``GET /api/datasets/{id}`` and
    the list give the upload's response field for field, on a multi-rate file and on a
    clean one (nothing to say: ``null`` both times)."""
    from tests.support.measurements import POLE

    response = upload(client, measurement_mf4, name="canape.mf4", raster="10ms")
    assert response.status_code == 201, response.text
    doc = response.json()
    assert doc["masked"] == {POLE: 10, "lambda": 3}
    assert any("onto the 10 ms raster (191 rows" in n for n in doc["notes"])
    assert client.get(f"/api/datasets/{doc['id']}").json() == doc
    listed = client.get("/api/datasets", params={"limit": 500}).json()["items"]
    assert next(d for d in listed if d["id"] == doc["id"]) == doc

    clean = upload(client, b"time,a\n0,1\n1,2\n")
    assert clean.status_code == 201, clean.text
    assert (clean.json()["notes"], clean.json()["masked"]) == (None, None)
    assert client.get(f"/api/datasets/{clean.json()['id']}").json() == clean.json()


def test_upload_keeps_the_chosen_channels_on_the_chosen_raster(
    client: TestClient, measurement_mf4: bytes
) -> None:
    from tests.support.measurements import NMOT

    for raster, rows in (("100Hz", 191), ("channel:mode", 190), ("10 ms", 191)):
        response = upload(client, measurement_mf4, channels=f"mode, {NMOT}", raster=raster)
        assert response.status_code == 201, response.text
        doc = response.json()
        assert [c["name"] for c in doc["channels"]] == ["mode", NMOT]
        assert doc["rows"] == rows, raster
        assert doc["rate_hz"] == pytest.approx(100.0)
        assert doc["masked"] is None  # nothing masked in these two channels
    as_json = upload(client, measurement_mf4, channels=json.dumps(["fast"]), raster="1kHz")
    assert as_json.status_code == 201, as_json.text
    assert (as_json.json()["rows"], as_json.json()["rate_hz"]) == (2000, pytest.approx(1000.0))


def test_a_run_on_a_channel_not_kept_names_it(client: TestClient, measurement_mf4: bytes) -> None:
    from tests.support.server import run_body

    dataset = upload(client, measurement_mf4, channels="fast,mode").json()
    response = client.post("/api/runs", json=run_body(dataset["id"], signals={"y": "lambda"}))
    assert response.status_code == 422, response.text
    assert "'lambda'" in response.json()["error"]["message"]


@pytest.mark.parametrize(
    ("form", "field", "message"),
    [
        ({"raster": "fast"}, "raster", "raster 'fast' is not understood"),
        ({"raster": "channel:nope"}, "raster", "raster channel 'nope'"),
        ({"raster": "0.1us"}, "raster", "choose a slower raster"),
        ({"channels": "fast,nope"}, "channels", "'nope' not in the file"),
        ({"channels": "[1, 2]"}, "channels", "JSON array of strings"),
    ],
)
def test_bad_raster_or_channels_are_refused_and_nothing_is_stored(
    client: TestClient,
    database_url: str,
    measurement_mf4: bytes,
    form: dict,
    field: str,
    message: str,
) -> None:
    before = _count(database_url)
    response = upload(client, measurement_mf4, **form)
    assert response.status_code == 422, response.text
    error = response.json()["error"]
    assert error["field"] == field
    assert message in error["message"]
    assert _count(database_url) == before


def test_sparse_csv_export_upload(client: TestClient, tmp_path) -> None:  # type: ignore[no-untyped-def]
    from tests.support.measurements import (
        NMOT,
        POLE,
        T10,
        T100,
        Measurement,
        write_measurement,
        write_sparse_csv,
    )

    measurement: Measurement = write_measurement(tmp_path, "3.30")
    csv_path = write_sparse_csv(tmp_path, measurement, ["fast", "mode", NMOT, POLE])
    response = upload(client, csv_path.read_bytes(), name="export.csv")
    assert response.status_code == 201, response.text
    doc = response.json()
    assert (doc["source"], doc["time_column"], doc["rows"]) == ("csv", "timestamps", T100.size)
    assert [c["name"] for c in doc["channels"]] == ["fast", "mode", POLE, NMOT]
    assert any("held (previous value) ['mode']" in n for n in doc["notes"])
    # the pole's written -inf: masked samples, counted (docs/data-formats.md#multi-rate)
    assert doc["masked"] == {POLE: 10}
    assert any(f"{POLE!r}: 10 of {T10.size} samples masked" in n for n in doc["notes"])


def test_a_dead_channel_is_dropped_and_a_run_that_needs_it_is_refused(
    client: TestClient, tmp_path
) -> None:  # type: ignore[no-untyped-def]
    """A channel with no usable sample never refuses the file: it is dropped with a note.
    Only a run that needs it is refused, naming the channel and the role it was given for."""
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    t = np.arange(200) * 0.01
    mdf.append(
        [
            Signal(np.linspace(0.0, 10.0, 200), t, name="u1"),
            Signal(np.sin(t), t, name="y"),
            Signal(np.full(200, np.inf), t, name="dead"),
        ]
    )
    path = tmp_path / "dead.mf4"
    mdf.save(path, overwrite=True)
    mdf.close()
    response = upload(client, path.read_bytes(), name="dead.mf4")
    assert response.status_code == 201, response.text
    dataset = response.json()
    assert [c["name"] for c in dataset["channels"]] == ["u1", "y"]
    assert any("'dead' dropped: 0 usable samples of 200" in n for n in dataset["notes"])
    table = {"axes": [{"name": "u1", "breakpoints": [0.0, 5.0, 10.0]}]}
    body = {"dataset_id": dataset["id"], "estimator": "nlms", "table": table}
    ok = client.post("/api/runs", json=body | {"signals": {"y": "y"}})
    assert ok.status_code == 201, ok.text
    refused = client.post("/api/runs", json=body | {"signals": {"y": "dead"}})
    assert refused.status_code == 422, refused.text
    error = refused.json()["error"]
    assert error["field"] == "signals.y", error
    assert "dead" in error["message"], error
