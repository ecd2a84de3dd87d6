"""``POST /api/datasets/simulate/stream``: the plain simulate route's body and dataset, with
the plant integrator's progress streamed as newline-delimited JSON while it runs
(docs/rest-api.md#simulate-progress); bad input is the plain route's 422, before any line."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fastapi.testclient import TestClient


def _lines(client: TestClient, body: dict) -> tuple[int, str, list[dict]]:
    with client.stream("POST", "/api/datasets/simulate/stream", json=body) as response:
        text = "".join(response.iter_text())
        return response.status_code, response.headers["content-type"], _parse(text)


def _parse(text: str) -> list[dict]:
    assert text.endswith("\n"), text[-200:]
    return [json.loads(line) for line in text.splitlines()]


@pytest.mark.slow  # a full simulation streamed: 9 s
def test_progress_rises_then_the_dataset_arrives(client: TestClient) -> None:
    # The plant run is cached by its inputs (not the seed) in the server's simulating child,
    # which this module's app starts at its first simulation: this one, so nothing is cached.
    body = {"scenario": "maf-whtc", "seed": 4, "name": "streamed WHTC"}
    status, content_type, lines = _lines(client, body)
    assert status == 200
    assert content_type.startswith("application/x-ndjson")
    assert all(set(line) == {"progress", "stage"} for line in lines[:-1]), lines[:-1]
    # Each plant run is a stage (the cycle, then the model's identification segment): the
    # share of its integrator's steps rises within it and restarts with the next.
    stages = [line["stage"] for line in lines[:-1]]
    assert stages == sorted(stages)
    assert stages[-1] >= 2
    for stage in set(stages) - {0}:
        share = [line["progress"] for line in lines[:-1] if line["stage"] == stage]
        assert share == sorted(share), (stage, share)
    assert lines[-2]["progress"] == 1.0
    assert any(0.0 < line["progress"] < 1.0 for line in lines[:-1]), lines  # read mid-kernel
    dataset = lines[-1]["dataset"]
    assert dataset == client.get(f"/api/datasets/{dataset['id']}").json()
    assert (dataset["name"], dataset["scenario"], dataset["seed"]) == (
        "streamed WHTC",
        "maf-whtc",
        4,
    )

    # The same samples as the plain route (the progress counter changes no number).
    plain = client.post("/api/datasets/simulate", json=body | {"name": "plain WHTC"})
    assert plain.status_code == 201, plain.text

    def maf(dataset_id: int) -> np.ndarray:
        doc = client.get(f"/api/datasets/{dataset_id}/preview?points=20000").json()
        return np.array(doc["channels"]["maf_kg_s"]["values"], dtype=float)

    np.testing.assert_array_equal(maf(dataset["id"]), maf(plain.json()["id"]))


def test_bad_input_is_the_plain_routes_422_before_any_line(client: TestClient) -> None:
    before = client.get("/api/datasets?limit=1").json()["total"]
    for body, field in (
        ({"scenario": "skf-sim2", "duration_s": 1e6}, "duration_s"),
        ({"scenario": "no-such-scenario"}, "scenario"),
        ({"scenario": "skf-sim2", "seed": -1}, "seed"),
        ({"scenario": "skf-sim2", "name": "\u0084"}, "name"),  # a control character
    ):
        response = client.post("/api/datasets/simulate/stream", json=body)
        assert response.status_code == 422, response.text
        assert response.json()["error"]["field"] == field, response.text
    assert client.get("/api/datasets?limit=1").json()["total"] == before


def test_a_short_simulation_streams_its_end_at_once(client: TestClient) -> None:
    status, _, lines = _lines(client, {"scenario": "skf-sim2", "duration_s": 1.0})
    assert status == 200
    assert lines[-2] == {"progress": 1.0, "stage": 0}  # no plant run to count
    assert lines[-1]["dataset"]["rows"] >= 2
