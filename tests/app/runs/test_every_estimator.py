"""Every registered estimator runs to ``succeeded`` through the REST API, as the dashboard
starts it: a dataset simulated from a scenario the estimator applies to, the catalog's
defaults overridden by the dataset's scenario setup (``GET /api/datasets/{id}/setup``: the
scenario's grid, signals and settings), on SQLite and PostgreSQL. Its stored series each
carry a role, and their keys are unique even where an estimate has the name of an input
channel (the EKF's ``p_im_pa``, once a UNIQUE violation when the run stored its results)."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from app.domain import SeriesRole
from app.services.sweeps import check_metric
from estimation.registry import names
from estimation.scenarios import scenarios
from tests.support.helpers import start_run, wait_run
from tests.support.scenario_runs import scenario_for, scenario_request


@pytest.mark.parametrize("estimator", names())
def test_every_estimator_succeeds_through_the_api(client: TestClient, estimator: str) -> None:
    scenario = scenario_for(estimator)
    body = scenario_request(client, estimator, scenario)
    done = wait_run(client, start_run(client, body)["id"], timeout=300)
    assert done["status"] == "succeeded", f"{estimator} on {scenario.name}: {done['error']}"
    for metric in done["metrics"]:
        check_metric(metric)  # a sweep may rank by every metric a run records
    if done["produces_map"] and estimator != "ekf-def":
        # On the scenario's own grid the run is scored against the known truth.
        assert {"map_rmse", "rmse"} & set(done["metrics"]), done["metrics"]

    series = client.get(f"/api/runs/{done['id']}/series", params={"points": 50}).json()
    lines = series["series"]
    roles = {name: line["role"] for name, line in lines.items()}
    assert set(roles.values()) <= {str(r) for r in SeriesRole}, roles
    assert SeriesRole.OUTPUT in roles.values(), roles
    inputs = {n for n, r in roles.items() if r == SeriesRole.INPUT}
    assert inputs <= set(body["signals"].values()) | {
        a["name"] for a in body.get("table", {}).get("axes", [])
    } | {a["name"] for a in (done["table"] or {}).get("axes", [])}
    for name, role in roles.items():
        if role == SeriesRole.OUTPUT and name.startswith("output:"):
            assert name.removeprefix("output:") in inputs  # renamed only where it collided

    frame_kinds = _stream_kinds(client, done["id"])
    assert frame_kinds[:2] == ["full", "status"]


def test_an_uploaded_log_has_no_scenario_setup(client: TestClient, example_csv) -> None:  # type: ignore[no-untyped-def]
    with example_csv.open("rb") as f:
        response = client.post("/api/datasets", files={"file": ("example.csv", f, "text/csv")})
    assert response.status_code == 201, response.text
    doc = client.get(f"/api/datasets/{response.json()['id']}/setup").json()
    assert doc["scenario"] is None
    assert doc["estimators"] == {}
    assert client.get("/api/datasets/999999/setup").status_code == 404


def test_an_estimate_named_like_an_input_keeps_both(client: TestClient) -> None:
    """ekf-def estimates ``p_im_pa`` and reads the channel ``p_im_pa``: both are stored,
    the input under its name, the estimate as ``output:p_im_pa``."""
    body = scenario_request(client, "ekf-def", scenarios()["maf-1d-whtc"])
    done = wait_run(client, start_run(client, body)["id"], timeout=300)
    assert done["status"] == "succeeded", done["error"]
    lines = client.get(f"/api/runs/{done['id']}/series", params={"points": 50}).json()["series"]
    assert lines["p_im_pa"]["role"] == "input"
    assert lines["output:p_im_pa"]["role"] == "output"
    assert lines["p_im_pa"]["unit"] == lines["output:p_im_pa"]["unit"] == "Pa"
    assert lines["p_im_pa"]["values"] != lines["output:p_im_pa"]["values"]
    assert lines["w_c_kg_s_true"]["role"] == "truth"
    assert lines["w_c_kg_s_error"]["role"] == "error"
    assert "rmse" in done["metrics"]
    csv = client.get(f"/api/runs/{done['id']}/export", params={"format": "csv"})
    assert csv.status_code == 200, csv.text
    header = csv.text.splitlines()[0].split(",")
    assert "p_im_pa [Pa]" in header
    assert "output:p_im_pa" in [column.split(" [")[0] for column in header]


def _stream_kinds(client: TestClient, run_id: int) -> list[str]:
    """The frame types a viewer of the finished run gets first."""
    with client.websocket_connect(f"/api/runs/{run_id}/stream") as ws:
        return [ws.receive_json()["type"], ws.receive_json()["type"]]
