"""JSON bodies and imported map files are parsed whole in the API process, so their size is
bounded before they are read (413: field ``body``, ``MAPWISE_MAX_JSON_MB``; field ``file``,
32 bytes a cell of ``MAPWISE_MAX_CELLS``), and a document nested too deeply to parse is a
422 naming where it came from, never a 500 (docs/configuration.md)."""

from __future__ import annotations

import json
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.api import create_app
from tests.support.helpers import log_csv, service_settings, upload

LIMIT_MB = 0.01  # 10 KiB
DEEP = "[" * 100_000 + "]" * 100_000  # deeper than json.loads recurses


@pytest.fixture(scope="module")
def client(database_url: str) -> Iterator[TestClient]:
    settings = service_settings(database_url, max_json_mb=LIMIT_MB)
    with TestClient(create_app(settings, execute_runs=False)) as c:
        yield c


def _stored(client: TestClient) -> tuple[int, int, int]:
    def total(path: str) -> int:
        return int(client.get(path).json()["total"])

    return total("/api/datasets"), total("/api/runs"), total("/api/base-maps")


def test_a_json_body_over_the_limit_is_413_before_it_is_read(client: TestClient) -> None:
    before = _stored(client)
    padded = {"scenario": "no-such-scenario", "seed": 0, "pad": "x" * 20_000}
    declared = client.post("/api/datasets/simulate", json=padded)
    raw = json.dumps(padded).encode()
    streamed = client.post(  # chunked, no Content-Length: counted as it arrives
        "/api/datasets/simulate",
        content=iter([raw[i : i + 4096] for i in range(0, len(raw), 4096)]),
        headers={"content-type": "application/json"},
    )
    for response in (declared, streamed):
        assert response.status_code == 413, response.text
        error = response.json()["error"]
        assert (error["code"], error["field"]) == ("payload_too_large", "body")
        assert "MAPWISE_MAX_JSON_MB" in error["message"]
    assert _stored(client) == before
    small = client.post("/api/datasets/simulate", json={**padded, "pad": "x"})
    assert small.status_code == 422, small.text  # read this time, and refused for its content
    assert small.json()["error"]["code"] == "validation_error"


def test_json_nested_too_deeply_is_422_naming_where(database_url: str) -> None:
    settings = service_settings(database_url)  # the default limit: the deep bodies fit
    with TestClient(create_app(settings, execute_runs=False)) as client:
        before = _stored(client)
        body = client.post(
            "/api/runs",
            content='{"dataset_id": 1, "config": {"x": ' + DEEP + "}}",
            headers={"content-type": "application/json"},
        )
        units = upload(client, log_csv(50), units='{"a": ' + DEEP + "}")
        channels = upload(client, log_csv(50), channels=DEEP)
        base_map = client.post(
            "/api/base-maps",
            files={"file": ("map.json", '{"axes": ' + DEEP + "}", "application/json")},
        )
        for response, field in ((body, "body"), (units, "units"), (channels, "channels")):
            assert response.status_code == 422, response.text
            error = response.json()["error"]
            assert error["field"] == field
            assert "nested too deeply" in error["message"]
        assert base_map.status_code == 422, base_map.text
        assert base_map.json()["error"]["field"] == "file"
        assert "nested too deeply" in base_map.json()["error"]["message"]
        assert _stored(client) == before


def test_a_map_file_too_large_for_any_allowed_map_is_413_unread(database_url: str) -> None:
    """A map file is parsed whole: one over 32 bytes a cell of MAPWISE_MAX_CELLS (at least
    1 MiB) is refused before it is read; one that fits is imported."""
    settings = service_settings(database_url, max_cells=100)
    assert settings.max_map_file_bytes == 1 << 20
    with TestClient(create_app(settings, execute_runs=False)) as client:
        before = _stored(client)
        axes = [{"name": "u1", "breakpoints": [0.0, 1.0]}, {"name": "u2", "breakpoints": [0, 1]}]
        fits = json.dumps({"axes": axes, "values": [[1.0, 2.0], [3.0, 4.0]]})
        padded = fits[:-1] + ', "pad": "' + "x" * (1 << 20) + '"}'
        response = client.post("/api/base-maps", files={"file": ("m.json", padded)})
        assert response.status_code == 413, response.text
        error = response.json()["error"]
        assert (error["code"], error["field"]) == ("payload_too_large", "file")
        assert "at most 100 cells" in error["message"]
        assert _stored(client) == before
        response = client.post("/api/base-maps", files={"file": ("m.json", fits)})
        assert response.status_code == 201, response.text
