"""Datasets through the service with their samples in the artifact store (either backend):
upload, run and export read the object; a missing or changed object is a 500 naming the
dataset and the key, and a run on it fails with that message; delete removes the object, and
an object that cannot be removed does not fail the request."""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app.db.repositories import DatasetRepo
from app.store import ArtifactStore
from tests.support.helpers import log_csv, start_run, upload_ok, wait_run
from tests.support.server import run_body


def _store(client: TestClient) -> ArtifactStore:
    return client.app.state.services.datasets.store  # type: ignore[attr-defined]


def _object(client: TestClient, dataset_id: int) -> tuple[str, str, Path]:
    with client.app.state.services.db.read() as s:  # type: ignore[attr-defined]
        stored = DatasetRepo(s).samples(dataset_id)
    return stored.key, stored.sha256, Path(_store(client).path(stored.key))


def test_upload_stores_a_parquet_object_and_runs_and_exports_read_it(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(2000))
    key, sha256, path = _object(client, dataset["id"])
    assert key.startswith(f"datasets/{dataset['id']}-{sha256[:16]}-")
    assert hashlib.sha256(path.read_bytes()).hexdigest() == sha256
    assert path.read_bytes()[:4] == b"PAR1"
    preview = client.get(f"/api/datasets/{dataset['id']}/preview", params={"points": 100})
    assert preview.status_code == 200
    assert preview.json()["channels"]["u1"]["unit"] == "rpm"
    run = start_run(client, run_body(dataset["id"], "skf"))
    assert wait_run(client, run["id"])["status"] == "succeeded"
    export = client.get(f"/api/runs/{run['id']}/export", params={"format": "csv", "part": "series"})
    assert export.status_code == 200, export.text
    assert export.text.count("\n") > 1000


def test_simulated_datasets_keep_their_truth_beside_the_object(client: TestClient) -> None:
    body = {"scenario": "skf-sim1", "seed": 3, "duration_s": 5.0}
    dataset = client.post("/api/datasets/simulate", json=body).json()
    assert dataset["has_truth"] is True
    _, _, path = _object(client, dataset["id"])
    assert path.is_file()


@pytest.mark.parametrize("damage", ["missing", "changed"])
def test_a_missing_or_changed_object_is_named_and_fails_runs(
    client: TestClient, damage: str
) -> None:
    dataset = upload_ok(client, log_csv(500))
    run = start_run(client, run_body(dataset["id"], "skf"))
    assert wait_run(client, run["id"])["status"] == "succeeded"
    key, _, path = _object(client, dataset["id"])
    if damage == "missing":
        path.unlink()
    else:
        data = bytearray(path.read_bytes())
        data[-20] ^= 0xFF  # in the footer's metadata
        path.write_bytes(bytes(data))
    code = {"missing": "artifact_missing", "changed": "artifact_corrupt"}[damage]

    preview = client.get(f"/api/datasets/{dataset['id']}/preview")
    assert preview.status_code == 500
    error = preview.json()["error"]
    assert error["code"] == code
    assert f"dataset {dataset['id']}" in error["message"]
    assert key in error["message"]

    again = start_run(client, run_body(dataset["id"], "skf"))
    failed = wait_run(client, again["id"])
    assert failed["status"] == "failed"
    assert f"dataset {dataset['id']}" in failed["error"]
    assert key in failed["error"]

    assert (
        client.delete(f"/api/datasets/{dataset['id']}", params={"force": True}).status_code == 204
    )


def test_delete_removes_the_object_and_survives_one_that_cannot_go(
    client: TestClient, caplog: pytest.LogCaptureFixture
) -> None:
    first = upload_ok(client, log_csv(300))
    _, _, path = _object(client, first["id"])
    assert client.delete(f"/api/datasets/{first['id']}").status_code == 204
    assert not path.exists()

    second = upload_ok(client, log_csv(300, seed=1))
    _, _, path = _object(client, second["id"])
    path.unlink()
    path.mkdir()  # a non-empty directory where the file was: removing it as a file fails
    (path / "x").write_text("x")
    with caplog.at_level(logging.WARNING, logger="mapwise.store"):
        assert client.delete(f"/api/datasets/{second['id']}").status_code == 204
    assert f"dataset {second['id']} deleted, but its object" in caplog.text
    assert client.get(f"/api/datasets/{second['id']}").status_code == 404
