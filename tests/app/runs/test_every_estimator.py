"""Every registered estimator runs to ``succeeded`` through the REST API, as the dashboard
starts it: a dataset simulated from a scenario the estimator applies to, the catalog's
defaults overridden by the dataset's scenario setup (``GET /api/datasets/{id}/setup``: the
scenario's grid, signals and settings), on SQLite and PostgreSQL. Its stored series each
carry a role, and their keys are unique even where an estimate has the name of an input
channel (the EKF's ``p_im_pa``, once a UNIQUE violation when the run stored its results)."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.domain import SeriesRole
from estimation.registry import names
from estimation.scenarios import Scenario, scenarios
from tests.support.helpers import start_run, wait_run

# Long enough for every estimator's results (the torque metrics start 5 s in), short
# enough for a quick test; None: the whole (short) scenario.
DURATION_S = {"skf-sim1": None, "maf-whtc": 120.0, "maf-1d-whtc": 120.0, "torque-si": 6.0}


def _scenario_for(estimator: str) -> Scenario:
    """A scenario suggesting ``estimator`` (the one it was made for), else the first one
    it applies to."""
    applies = [s for s in scenarios().values() if s.configs(estimator) is not None]
    assert applies, f"no scenario applies to {estimator}"
    return next((s for s in applies if estimator in s.suggested), applies[0])


def _request(client: TestClient, estimator: str, scenario: Scenario) -> dict[str, Any]:
    """The run request the dashboard sends with "Use the scenario's setup" on: the catalog's
    defaults overridden by ``GET /api/datasets/{id}/setup`` (the scenario's grid, signals and
    settings with this realisation's drawn constants)."""
    dataset = _simulated(client, scenario)
    response = client.get(f"/api/datasets/{dataset['id']}/setup")
    assert response.status_code == 200, response.text
    doc = response.json()
    assert doc["scenario"] == scenario.name
    assert estimator in doc["estimators"], sorted(doc["estimators"])
    setup = doc["estimators"][estimator]
    entry = next(e for e in client.get("/api/estimators").json()["items"] if e["name"] == estimator)
    assert (setup["table"] is not None) == entry["needs_table"], setup
    body: dict[str, Any] = {
        "dataset_id": dataset["id"],
        "estimator": estimator,
        "signals": setup["signals"],
        "config": entry["defaults"] | setup["config"],
    }
    if setup["table"] is not None:
        body["table"] = setup["table"]
    return body


_SIMULATED: dict[tuple[int, str], dict[str, Any]] = {}


def _simulated(client: TestClient, scenario: Scenario) -> dict[str, Any]:
    """One dataset per scenario and test module (shared by the estimators of a family)."""
    key = (id(client), scenario.name)
    if key not in _SIMULATED:
        simulate: dict[str, Any] = {"scenario": scenario.name, "seed": 0}
        if DURATION_S.get(scenario.name) is not None:
            simulate["duration_s"] = DURATION_S[scenario.name]
        response = client.post("/api/datasets/simulate", json=simulate)
        assert response.status_code == 201, response.text
        _SIMULATED[key] = response.json()
    return _SIMULATED[key]


@pytest.mark.parametrize("estimator", names())
def test_every_estimator_succeeds_through_the_api(client: TestClient, estimator: str) -> None:
    scenario = _scenario_for(estimator)
    body = _request(client, estimator, scenario)
    done = wait_run(client, start_run(client, body)["id"], timeout=300)
    assert done["status"] == "succeeded", f"{estimator} on {scenario.name}: {done['error']}"
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
    body = _request(client, "ekf-def", scenarios()["maf-1d-whtc"])
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
