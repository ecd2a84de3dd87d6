"""The NaN/Inf policy: non-finite numbers are refused on input — in every numeric field of
every JSON body (422, nothing stored) and in uploaded logs (the bad-file corpus) — and never
appear in a response (strict JSON: schemathesis checks every documented response)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.support.helpers import TABLE, log_csv, upload_ok

NON_FINITE = ("NaN", "Infinity", "-Infinity")
JSON = {"Content-Type": "application/json"}


def _numeric_paths(node: Any, path: tuple = ()) -> Iterator[tuple]:
    if isinstance(node, bool):
        return
    if isinstance(node, int | float):
        yield path
    elif isinstance(node, dict):
        for key, value in node.items():
            yield from _numeric_paths(value, (*path, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _numeric_paths(value, (*path, i))


def _with(body: Any, path: tuple, token: str) -> str:
    """``body`` as JSON text with the number at ``path`` replaced by the bare ``token``."""
    marker = "__non_finite__"
    copy = json.loads(json.dumps(body))
    node = copy
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = marker
    return json.dumps(copy).replace(f'"{marker}"', token)


def _bodies(dataset_id: int) -> dict[str, dict[str, Any]]:
    run = {
        "dataset_id": dataset_id,
        "estimator": "skf",
        "signals": {"y": "y"},
        "table": TABLE | {"values": 0.5},
        "config": {
            "sigma_w": 0.01,
            "sigma_v": 0.05,
            "p0": 10.0,
            "theta0": 1.0,
            "sensor": {"lag": 0.5, "delay_s": 0.1, "sigma_f": 1.0},
            "pace": 10,
            "version_every": {"samples": 500},
            "gates": [
                {"type": "range", "channel": "temp", "min": 20.0, "max": 90.0},
                {"type": "rate", "channel": "temp", "max_abs": 5.0},
                {"type": "holdoff", "channel": "temp", "below": 25.0, "seconds": 1.0},
            ],
        },
    }
    sweep = {
        **{k: v for k, v in run.items() if k != "config"},
        "config": {"p0": 10.0},
        "parameters": {"sigma_w": [0.01, 0.1], "sigma_v": {"min": 0.01, "max": 1.0}},
        "samples": 2,
        "seed": 1,
    }
    batch = {
        "dataset_ids": [dataset_id],
        "estimator": "kf",
        "signals": {"y": "y"},
        "table": TABLE,
        "config": {"sigma_w": 0.01, "sigma_v": 0.05, "p0": 10.0},
    }
    simulate = {"scenario": "skf-sim1", "seed": 3, "duration_s": 100.0}
    return {
        "/api/runs": run,
        "/api/sweeps": sweep,
        "/api/batches": batch,
        "/api/datasets/simulate": simulate,
    }


def _stored(client: TestClient) -> tuple[int, int]:
    runs = client.get("/api/runs", params={"limit": 1}).json()["total"]
    datasets = client.get("/api/datasets", params={"limit": 1}).json()["total"]
    return runs, datasets


def test_non_finite_numbers_are_refused_in_every_numeric_field(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(500, seed=90))
    bodies = _bodies(dataset["id"])
    for path, body in bodies.items():  # the bodies themselves are accepted
        assert client.post(path, json=body).status_code == 201, (path, body)
    before = _stored(client)
    checked = 0
    for path, body in bodies.items():
        for field in _numeric_paths(body):
            for token in NON_FINITE:
                response = client.post(
                    path,
                    content=_with(body, field, token),
                    headers={"Content-Type": "application/json"},
                )
                assert response.status_code == 422, (path, field, token, response.text)
                error = response.json()["error"]
                assert error["code"] == "validation_error"
                assert token in error["message"]
                checked += 1
    assert checked >= 3 * 30
    assert _stored(client) == before


@pytest.mark.parametrize("token", NON_FINITE)
def test_non_finite_numbers_are_refused_in_patches_and_promotions(
    client: TestClient, token: str
) -> None:
    promote = f'{{"run_id": {token}, "version_id": 1, "name": "x"}}'
    assert client.post("/api/base-maps", content=promote, headers=JSON).status_code == 422
    label = f'{{"label": "rc", "extra": {token}}}'
    assert client.patch("/api/runs/1/versions/1", content=label, headers=JSON).status_code == 422
