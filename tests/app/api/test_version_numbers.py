"""Version numbers per run: each run numbers its versions 1…n by step (``number``, beside the
database ``id`` every version document keeps); ``by-number`` looks one up, an unknown number
is a 404 naming it; exports and promoted base maps say "run R version N"."""

from __future__ import annotations

import re
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.services.base_maps import promoted_name
from tests.support.helpers import log_csv, run_body, start_run, upload_ok, wait_run


@pytest.fixture(scope="module")
def two_runs(client: TestClient) -> list[dict[str, Any]]:
    """Two finished runs of 3 and 4 versions: the second's database ids start after the first's,
    so its ids and numbers differ."""
    dataset = upload_ok(client, log_csv(2400, seed=3))
    runs = []
    for every, name in ((800, ""), (600, "numbered run")):
        body = run_body(dataset["id"], version_every={"samples": every}) | {"name": name}
        run = wait_run(client, start_run(client, body)["id"])
        assert run["status"] == "succeeded", run
        runs.append(run)
    return runs


def versions_of(client: TestClient, run_id: int) -> list[dict[str, Any]]:
    return client.get(f"/api/runs/{run_id}/versions").json()["items"]


def test_numbers_are_1_to_n_per_run(client: TestClient, two_runs) -> None:
    first, second = (versions_of(client, r["id"]) for r in two_runs)
    assert [v["number"] for v in first] == [1, 2, 3]
    assert [v["number"] for v in second] == [1, 2, 3, 4]
    assert [v["step"] for v in second] == sorted(v["step"] for v in second)
    assert [v["id"] for v in second] != [1, 2, 3, 4]  # the ids stay database ids
    # A page after the first still numbers from the run's start.
    page = client.get(
        f"/api/runs/{two_runs[1]['id']}/versions", params={"limit": 2, "offset": 2}
    ).json()
    assert [v["number"] for v in page["items"]] == [3, 4]
    # Every version document carries it: by id, the label reply, the compare document.
    run_id = two_runs[1]["id"]
    doc = client.get(f"/api/runs/{run_id}/versions/{second[1]['id']}").json()
    assert (doc["number"], doc["id"]) == (2, second[1]["id"])
    labelled = client.patch(f"/api/runs/{run_id}/versions/{second[2]['id']}", json={"label": "x"})
    assert labelled.json()["number"] == 3
    for bad in ("a\u0000b", "bench\u202e1"):  # a NUL, a right-to-left override
        refused = client.patch(
            f"/api/runs/{run_id}/versions/{second[2]['id']}", json={"label": bad}
        )
        assert refused.status_code == 422, refused.text
        assert refused.json()["error"]["field"] == "label"
    kept = client.get(f"/api/runs/{run_id}/versions/{second[2]['id']}").json()
    assert kept["label"] == "x"
    compared = client.get("/api/compare", params={"runs": f"{two_runs[0]['id']},{run_id}"})
    missing = client.get("/api/compare", params={"runs": f"{run_id},999999"})
    assert missing.status_code == 404, missing.text
    assert missing.json()["error"]["field"] == "runs[1]"  # the query's own name and place
    assert [r["final_version"]["number"] for r in compared.json()["runs"]] == [3, 4]


def test_by_number_finds_the_version_and_404_names_an_unknown_number(
    client: TestClient, two_runs
) -> None:
    run_id = two_runs[1]["id"]
    versions = versions_of(client, run_id)
    for k, summary in enumerate(versions, start=1):
        by_number = client.get(f"/api/runs/{run_id}/versions/by-number/{k}")
        assert by_number.status_code == 200, by_number.text
        by_id = client.get(f"/api/runs/{run_id}/versions/{summary['id']}").json()
        assert by_number.json() == by_id

    missing = client.get(f"/api/runs/{run_id}/versions/by-number/9")
    assert missing.status_code == 404
    error = missing.json()["error"]
    assert error["field"] == "number"
    assert f"run {run_id} has no version 9" in error["message"]
    assert "1…4" in error["message"]
    assert client.get(f"/api/runs/{run_id}/versions/by-number/0").status_code == 422
    assert client.get("/api/runs/2147483000/versions/by-number/1").status_code == 404


def test_dcm_export_names_the_version_number(client: TestClient, two_runs) -> None:
    run = two_runs[1]
    url = f"/api/runs/{run['id']}/export"
    versions = versions_of(client, run["id"])

    final = client.get(url, params={"format": "dcm"})
    assert final.status_code == 200, final.text
    assert f"mapwise run {run['id']} (skf), version 4 " in final.text
    assert re.search(r'filename="run\d+-skf-v4\.dcm"', final.headers["content-disposition"])

    second = client.get(url, params={"format": "dcm", "version": versions[1]["id"]})
    assert f"mapwise run {run['id']} (skf), version 2 " in second.text
    assert '-v2.dcm"' in second.headers["content-disposition"]
    # The same version asked for by its number: the same file.
    by_number = client.get(url, params={"format": "dcm", "number": 2})
    assert by_number.text == second.text
    assert by_number.headers["content-disposition"] == second.headers["content-disposition"]
    json_doc = client.get(url, params={"format": "json", "number": 1})
    assert '-v1.json"' in json_doc.headers["content-disposition"]

    unknown = client.get(url, params={"format": "dcm", "number": 7})
    assert unknown.status_code == 404
    assert f"run {run['id']} has no version 7" in unknown.json()["error"]["message"]
    both = client.get(url, params={"format": "dcm", "number": 1, "version": versions[0]["id"]})
    assert both.status_code == 422
    assert both.json()["error"]["field"] == "number"


def test_promoted_base_map_is_named_by_run_and_number(client: TestClient, two_runs) -> None:
    unnamed, named = two_runs
    # A run always has a name (given, else e.g. "skf on log.csv"); "run R" stands in for none.
    assert unnamed["name"]
    for run, expected in ((unnamed, f"{unnamed['name']} v2"), (named, "numbered run v2")):
        version = versions_of(client, run["id"])[1]
        made = client.post(
            "/api/base-maps", json={"run_id": run["id"], "version_id": version["id"]}
        )
        assert made.status_code == 201, made.text
        assert made.json()["name"] == expected
        lineage = made.json()["lineage"]
        assert (lineage["version_id"], lineage["version_number"]) == (version["id"], 2)
        listed = client.get(f"/api/base-maps/{made.json()['id']}").json()
        assert listed["lineage"]["version_number"] == 2
    # A name given is kept as given.
    version = versions_of(client, named["id"])[0]
    made = client.post(
        "/api/base-maps",
        json={"run_id": named["id"], "version_id": version["id"], "name": "mine"},
    )
    assert made.json()["name"] == "mine"


def test_the_default_name_falls_back_to_the_run_id() -> None:
    assert promoted_name("", 7, 3) == "run 7 v3"
    assert promoted_name("  ", 7, 3) == "run 7 v3"
    assert promoted_name("cold start", 7, 12) == "cold start v12"
