"""Run management over HTTP, on SQLite and PostgreSQL: rename (PATCH), delete with the
run's versions (DELETE; an active run refused), clone (POST …/clone, validated as a new
run), and the runs list's filters (name, estimator, dataset, status, group, top level)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from tests.support.helpers import (
    TABLE,
    final_values,
    log_csv,
    run_body,
    start_run,
    upload_ok,
    wait_group,
    wait_run,
)


@pytest.fixture(scope="module")
def finished(client: TestClient) -> dict[str, Any]:
    """A finished skf run of three versions on its own dataset."""
    dataset = upload_ok(client, log_csv(1500, seed=81))
    body = run_body(dataset["id"], version_every={"samples": 500}) | {"name": "Base NOx fit"}
    run = wait_run(client, start_run(client, body)["id"])
    assert run["status"] == "succeeded", run
    return run


def _error(response: Any) -> dict[str, Any]:
    return response.json()["error"]


def test_rename_and_its_422s(client: TestClient, finished) -> None:
    run_id = finished["id"]
    renamed = client.patch(f"/api/runs/{run_id}", json={"name": "  Warm-up fit  "})
    assert renamed.status_code == 200, renamed.text
    assert renamed.json()["name"] == "Warm-up fit"
    assert client.get(f"/api/runs/{run_id}").json()["name"] == "Warm-up fit"

    for bad in ("", "   ", "x" * 201, "tab\there"):
        response = client.patch(f"/api/runs/{run_id}", json={"name": bad})
        assert response.status_code == 422, (bad, response.text)
        assert _error(response)["field"] == "name", response.text
    assert client.patch(f"/api/runs/{run_id}", json={"nam": "x"}).status_code == 422
    missing = client.patch("/api/runs/2147483000", json={"name": "x"})
    assert missing.status_code == 404
    assert _error(missing)["field"] == "run_id"
    client.patch(f"/api/runs/{run_id}", json={"name": "Base NOx fit"})


def test_clone_queues_the_same_run_and_validates_overrides(client: TestClient, finished) -> None:
    run_id = finished["id"]
    response = client.post(f"/api/runs/{run_id}/clone")
    assert response.status_code == 201, response.text
    copy = response.json()
    assert copy["id"] != run_id
    assert copy["name"] == "Base NOx fit (copy)"
    for key in ("dataset_id", "estimator", "signals", "table", "config", "estimator_config"):
        assert copy[key] == finished[key], key
    done = wait_run(client, copy["id"])
    assert done["status"] == "succeeded", done
    # Same inputs, same estimator: the same map.
    np.testing.assert_array_equal(
        np.array(final_values(client, copy["id"])["values"]),
        np.array(final_values(client, run_id)["values"]),
    )

    tuned = client.post(
        f"/api/runs/{run_id}/clone", json={"name": "Tuned", "config": {"sigma_w": 0.02}}
    )
    assert tuned.status_code == 201, tuned.text
    assert tuned.json()["name"] == "Tuned"
    assert tuned.json()["config"] == finished["config"] | {"sigma_w": 0.02}
    wait_run(client, tuned.json()["id"])

    # Overrides are validated exactly as POST /api/runs validates a config.
    bad = client.post(f"/api/runs/{run_id}/clone", json={"config": {"sigma_w": -1.0}})
    assert bad.status_code == 422
    direct = client.post("/api/runs", json=run_body(finished["dataset_id"], sigma_w=-1.0))
    assert _error(bad) == _error(direct)
    assert "sigma_w" in _error(bad)["message"]
    assert _error(bad)["field"].startswith("config")
    unknown = client.post(f"/api/runs/{run_id}/clone", json={"colour": "red"})
    assert unknown.status_code == 422
    long_name = client.post(f"/api/runs/{run_id}/clone", json={"name": "n" * 201})
    assert long_name.status_code == 422
    assert _error(long_name)["field"] == "name"
    assert client.post("/api/runs/2147483000/clone").status_code == 404


def test_clone_of_a_long_name_stays_within_200_characters(client: TestClient, finished) -> None:
    body = run_body(finished["dataset_id"]) | {"name": "L" * 200}
    run = start_run(client, body)
    copy = client.post(f"/api/runs/{run['id']}/clone").json()
    assert len(copy["name"]) == 200
    assert copy["name"].endswith(" (copy)")
    for r in (run, copy):
        wait_run(client, r["id"])


def test_delete_removes_the_run_and_its_versions_but_not_base_map_lineage(
    client: TestClient, finished
) -> None:
    run = wait_run(client, client.post(f"/api/runs/{finished['id']}/clone").json()["id"])
    versions = client.get(f"/api/runs/{run['id']}/versions").json()["items"]
    assert len(versions) == run["n_versions"] >= 2
    base_map = client.post(
        "/api/base-maps", json={"run_id": run["id"], "version_id": versions[-1]["id"]}
    )
    assert base_map.status_code == 201, base_map.text

    deleted = client.delete(f"/api/runs/{run['id']}")
    assert deleted.status_code == 204, deleted.text
    assert client.get(f"/api/runs/{run['id']}").status_code == 404
    assert client.get(f"/api/runs/{run['id']}/versions").status_code == 404
    assert client.get(f"/api/runs/{run['id']}/series").status_code == 404
    gone = client.get(f"/api/runs/{run['id']}/versions/{versions[0]['id']}")
    assert gone.status_code == 404
    kept = client.get(f"/api/base-maps/{base_map.json()['id']}").json()
    assert kept["lineage"]["run_id"] == run["id"]  # lineage is a record: it survives its run

    again = client.delete(f"/api/runs/{run['id']}")
    assert again.status_code == 404
    assert _error(again)["field"] == "run_id"
    assert client.get(f"/api/runs/{finished['id']}").status_code == 200  # the original stays


def test_an_active_run_is_refused_until_cancelled(client: TestClient, finished) -> None:
    body = run_body(finished["dataset_id"], pace=2, version_every={"samples": 300})
    run = start_run(client, body)
    wait_run(client, run["id"], until=("running",))
    refused = client.delete(f"/api/runs/{run['id']}")
    assert refused.status_code == 409
    error = _error(refused)
    assert error["field"] == "run_id"
    assert "running" in error["message"]
    assert "cancel" in error["message"]
    client.post(f"/api/runs/{run['id']}/cancel")
    wait_run(client, run["id"])
    assert client.delete(f"/api/runs/{run['id']}").status_code == 204


def test_list_filters_and_pages(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(600, seed=82))
    names = ["Idle map alpha", "Idle map beta", "Full load ALPHA"]
    runs = [start_run(client, run_body(dataset["id"]) | {"name": n}) for n in names]
    rls = start_run(client, run_body(dataset["id"], "rls") | {"name": "rls idle"})
    for r in [*runs, rls]:
        wait_run(client, r["id"])

    def ids(**params: Any) -> list[int]:
        page = client.get("/api/runs", params={"dataset_id": dataset["id"], **params})
        assert page.status_code == 200, page.text
        return [r["id"] for r in page.json()["items"]]

    assert ids(q="alpha") == [runs[2]["id"], runs[0]["id"]]  # any case, newest first
    assert ids(q="IDLE") == [rls["id"], runs[1]["id"], runs[0]["id"]]
    assert ids(estimator="rls") == [rls["id"]]
    assert ids(q="idle", estimator="skf") == [runs[1]["id"], runs[0]["id"]]
    assert ids(status="failed") == []
    assert ids(q="100%_") == []  # LIKE wildcards are plain characters
    page = client.get("/api/runs", params={"dataset_id": dataset["id"], "limit": 3, "offset": 3})
    assert page.json()["total"] == 4
    assert [r["id"] for r in page.json()["items"]] == [runs[0]["id"]]
    assert client.get("/api/runs", params={"q": "x" * 201}).status_code == 422
    # Control characters (NUL was a 500 on PostgreSQL, whose text cannot hold one): 422
    # naming the parameter, on both backends.
    for params in ({"q": "a\x00b"}, {"q": "tab\t"}, {"estimator": "sk\x00f"}):
        response = client.get("/api/runs", params=params)
        assert response.status_code == 422, (params, response.text)
        assert response.json()["error"]["field"] == next(iter(params)), response.text


def test_sweep_children_group_and_delete_keeps_counts_consistent(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(600, seed=83))
    sweep = client.post(
        "/api/sweeps",
        json={
            "dataset_id": dataset["id"],
            "estimator": "skf",
            "signals": {"y": "y"},
            "table": TABLE,
            "config": {"p0": 10.0, "sigma_v": 0.05},
            "parameters": {"sigma_w": [0.001, 0.01, 0.1]},
            "metric": "output_rmse",
            "name": "Noise sweep",
        },
    ).json()
    done = wait_group(client, f"/api/sweeps/{sweep['id']}")
    loose = wait_run(client, start_run(client, run_body(dataset["id"]) | {"name": "loose"})["id"])
    children = sorted(r["id"] for r in done["runs"])

    top = client.get("/api/runs", params={"dataset_id": dataset["id"], "top_level": True}).json()
    assert top["total"] == 2
    first, plain = top["items"][1], top["items"][0]
    assert plain["id"] == loose["id"]
    assert plain["group"] is None
    assert plain["group_id"] is None
    assert first["id"] == children[0]
    assert first["group"] == {"id": sweep["id"], "kind": "sweep", "name": "Noise sweep", "size": 3}
    grouped = client.get("/api/runs", params={"group": sweep["id"]}).json()
    assert sorted(r["id"] for r in grouped["items"]) == children
    assert all(r["group_id"] == sweep["id"] for r in grouped["items"])
    # A filter chooses the group's representative among its matching runs (named "#k: …").
    rep = client.get(
        "/api/runs", params={"dataset_id": dataset["id"], "top_level": True, "q": "sweep #2"}
    ).json()["items"]
    assert [r["id"] for r in rep] == [children[1]]

    # A child may be cloned (on its own) and deleted; the sweep counts what remains.
    copy = client.post(f"/api/runs/{children[1]}/clone").json()
    assert copy["group_id"] is None
    wait_run(client, copy["id"])
    assert client.delete(f"/api/runs/{children[1]}").status_code == 204
    after = client.get(f"/api/sweeps/{sweep['id']}").json()
    assert sorted(r["id"] for r in after["runs"]) == [children[0], children[2]]
    assert sum(after["counts"].values()) == 2
    assert client.get("/api/runs", params={"group": sweep["id"]}).json()["total"] == 2
    top = client.get("/api/runs", params={"dataset_id": dataset["id"], "top_level": True}).json()
    assert top["items"][-1]["group"]["size"] == 2
