"""``POST /api/base-maps`` with an edited grid (the run view's editor): the values saved as a
base map with the run's lineage and the edit log, source "edit"; a grid of the wrong shape,
a non-finite or non-number cell and values sent as source "run" refused with 422 naming the
field; a plain promotion unchanged."""

from __future__ import annotations

import math
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.errors import InvalidRequestError
from app.services.base_map_edits import checked_values
from tests.support.helpers import log_csv, run_body, start_run, upload_ok, wait_run

EDITS = [
    {"op": "select", "cells": [0, 1, 4, 5]},
    {"op": "smooth", "cells": [0, 1, 4, 5], "kernel": "binomial-3"},
    {"op": "lock", "cells": [5]},
    {"op": "reset", "cells": [0, 1]},
]


@pytest.fixture(scope="module")
def finished(client: TestClient) -> dict[str, Any]:
    """A finished SKF run on the 4 × 4 table and its final version (with its values)."""
    dataset = upload_ok(client, log_csv(800, seed=21))
    run = start_run(client, run_body(dataset["id"]))
    assert wait_run(client, run["id"])["status"] == "succeeded"
    summary = client.get(f"/api/runs/{run['id']}/versions").json()["items"][-1]
    version = client.get(f"/api/runs/{run['id']}/versions/{summary['id']}").json()
    return {"run": run, "version": version, "dataset": dataset}


def test_edited_values_are_saved_with_lineage_and_edits(
    client: TestClient, finished: dict[str, Any]
) -> None:
    run, version = finished["run"], finished["version"]
    edited = [
        [round(v + 0.25 * (i - j), 6) for j, v in enumerate(row)]
        for i, row in enumerate(version["values"])
    ]
    body = {
        "run_id": run["id"],
        "version_id": version["id"],
        "name": "edited v1",
        "values": edited,
        "edits": EDITS,
        "source": "edit",
    }
    response = client.post("/api/base-maps", json=body)
    assert response.status_code == 201, response.text
    saved = response.json()
    assert saved["source"] == "edit"
    assert saved["name"] == "edited v1"
    assert saved["values"] == edited
    assert saved["axes"] == version["axes"]
    lineage = saved["lineage"]
    assert lineage["run_id"] == run["id"]
    assert lineage["version_id"] == version["id"]
    assert lineage["dataset_id"] == finished["dataset"]["id"]
    assert lineage["config"]["edits"] == EDITS
    assert lineage["config"]["sigma_w"] == run["config"]["sigma_w"]  # the run's config kept
    again = client.get(f"/api/base-maps/{saved['id']}").json()
    assert again["values"] == edited
    assert again["lineage"]["config"]["edits"] == EDITS

    # The saved map starts the next run.
    second = start_run(client, run_body(finished["dataset"]["id"]) | {"base_map_id": saved["id"]})
    assert client.get(f"/api/runs/{second['id']}").json()["estimator_config"]["theta0"] == edited
    assert wait_run(client, second["id"])["status"] == "succeeded"


def test_values_imply_source_edit_and_edits_alone_keep_the_version(
    client: TestClient, finished: dict[str, Any]
) -> None:
    run, version = finished["run"], finished["version"]
    ones = [[1.0] * len(row) for row in version["values"]]
    implied = client.post(
        "/api/base-maps",
        json={"run_id": run["id"], "version_id": version["id"], "name": "ones", "values": ones},
    )
    assert implied.status_code == 201, implied.text
    assert implied.json()["source"] == "edit"
    assert implied.json()["lineage"]["config"]["edits"] == []
    accepted = client.post(
        "/api/base-maps",
        json={
            "run_id": run["id"],
            "version_id": version["id"],
            "name": "accepted",
            "edits": [{"op": "accept", "cells": []}],
        },
    )
    assert accepted.status_code == 201, accepted.text
    assert accepted.json()["source"] == "edit"
    assert accepted.json()["values"] == version["values"]
    plain = client.post(
        "/api/base-maps", json={"run_id": run["id"], "version_id": version["id"], "name": "plain"}
    )
    assert plain.status_code == 201, plain.text
    assert plain.json()["source"] == "run"
    assert "edits" not in (plain.json()["lineage"]["config"] or {})


@pytest.mark.parametrize(
    ("values", "problem"),
    [
        ([[1.0, 2.0, 3.0, 4.0]] * 3, "shape 3 × 4"),  # one row short
        ([[1.0, 2.0, 3.0]] * 4, "shape 4 × 3"),
        ([1.0] * 16, "shape 16"),  # flat, not nested
        ([[1.0, 2.0, 3.0, 4.0]] * 3 + [[1.0, 2.0]], "nested lists of equal length"),
        ([[1.0, 2.0, 3.0, 4.0]] * 3 + [[1.0, None, 3.0, 4.0]], "values[3, 1] is None"),
        ([[1.0, 2.0, 3.0, 4.0]] * 3 + [[1.0, 2.0, "3", 4.0]], "values[3, 2] is '3'"),
        ([[1.0, 2.0, 3.0, 4.0]] * 3 + [[1.0, 2.0, 3.0, True]], "values[3, 3] is True"),
        ([[1.0, 2.0, 3.0, 4.0]] * 3 + [[1.0, 2.0, 3.0, -1e308]], "at most 1e+75"),
        (5.0, "valid array"),  # refused by the schema itself
    ],
)
def test_bad_values_are_refused_naming_the_field(
    client: TestClient, finished: dict[str, Any], values: Any, problem: str
) -> None:
    run, version = finished["run"], finished["version"]
    body = {"run_id": run["id"], "version_id": version["id"], "name": "bad", "values": values}
    response = client.post("/api/base-maps", json=body)
    assert response.status_code == 422, response.text
    error = response.json()["error"]
    assert error["field"] is not None
    assert error["field"].split(".")[0] == "values", error
    if error["field"] == "values":  # pydantic refuses a scalar before the service sees it
        assert problem in error["message"], error


def test_non_finite_values_and_source_run_with_values_are_refused(
    client: TestClient, finished: dict[str, Any]
) -> None:
    run, version = finished["run"], finished["version"]
    base = {"run_id": run["id"], "version_id": version["id"], "name": "bad"}
    rows = "[NaN, 1, 2, 3], [1, 2, 3, 4], [1, 2, 3, 4], [1, 2, 3, 4]"
    text = '{"run_id": %d, "version_id": %d, "name": "nan", "values": [%s]}'
    response = client.post(
        "/api/base-maps",
        content=text % (run["id"], version["id"], rows),
        headers={"content-type": "application/json"},
    )
    assert response.status_code == 422, response.text  # strict JSON, before any handler
    assert "NaN" in response.json()["error"]["message"]
    # The service checks for itself (a caller in process, or a body parsed leniently).
    with pytest.raises(InvalidRequestError, match=r"values\[1, 2\] is inf") as refused:
        checked_values([[1.0, 1.0, 1.0], [1.0, 1.0, math.inf]], (2, 3))
    assert refused.value.field == "values"
    response = client.post(
        "/api/base-maps", json=base | {"values": version["values"], "source": "run"}
    )
    assert response.status_code == 422, response.text
    assert response.json()["error"]["field"] == "source"
    response = client.post("/api/base-maps", json=base | {"source": "sculpted"})
    assert response.status_code == 422, response.text
    assert response.json()["error"]["field"] == "source"
    response = client.post("/api/base-maps", json=base | {"edits": ["smooth"]})
    assert response.status_code == 422, response.text
    assert response.json()["error"]["field"].startswith("edits")
    before = client.get("/api/base-maps").json()["total"]
    notes = [{"op": "note", "text": "x" * 5000}] * 60  # 2000 items are allowed, not 300 KB
    response = client.post("/api/base-maps", json=base | {"edits": notes})
    assert response.status_code == 422, response.text
    assert response.json()["error"]["field"] == "edits"
    assert "at most 262,144" in response.json()["error"]["message"]
    assert client.get("/api/base-maps").json()["total"] == before


def test_start_values_near_the_float_limit_are_refused(
    client: TestClient, finished: dict[str, Any]
) -> None:
    """θ0 (in config or as the table's values) is bounded like the sigmas: a run from
    -1e308 once "succeeded" with NaN metrics and overflow warnings."""
    dataset_id = finished["dataset"]["id"]
    before = client.get("/api/runs").json()["total"]
    theta0 = client.post("/api/runs", json=run_body(dataset_id, theta0=-1e308))
    table = run_body(dataset_id)
    table["table"] = {**table["table"], "values": [[1.0] * 4] * 3 + [[1.0, 1.0, 1.0, 1e80]]}
    valued = client.post("/api/runs", json=table)
    for response in (theta0, valued):
        assert response.status_code == 422, response.text
        error = response.json()["error"]
        assert "at most 1e+75" in error["message"], error
    assert theta0.json()["error"]["field"] == "config.theta0"
    assert client.get("/api/runs").json()["total"] == before
