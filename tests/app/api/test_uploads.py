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
    "NaN": (b"time,a\n0,1\n1,nan\n2,3\n", 422, "a"),
    "Inf": (b"time,a\n0,1\n1,-inf\n2,3\n", 422, "a"),
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
