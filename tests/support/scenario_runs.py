"""Runs started as the dashboard starts them with *Use the scenario's setup* on: a dataset
simulated from a scenario, the catalog's defaults overridden by the dataset's scenario setup
(``GET /api/datasets/{id}/setup``). Shared by tests/app/runs/test_every_estimator.py and
test_every_scenario.py."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from estimation.scenarios import Scenario, scenarios

# Long enough for every estimator's results (the torque metrics start 5 s in), short
# enough for a quick test; None: the whole (short) scenario.
DURATION_S = {
    "skf-sim1": None,
    "nox-sdmp": 30.0,
    "nox-nedc": 30.0,
    "maf-whtc": 120.0,
    "maf-ftp75": 120.0,
    "maf-1d-whtc": 120.0,
    "torque-si": 6.0,
    "torque-rig": 6.0,
}


def scenario_for(estimator: str) -> Scenario:
    """A scenario suggesting ``estimator`` (the one it was made for), else the first one
    it applies to."""
    applies = [s for s in scenarios().values() if s.configs(estimator) is not None]
    assert applies, f"no scenario applies to {estimator}"
    return next((s for s in applies if estimator in s.suggested), applies[0])


def scenario_request(client: TestClient, estimator: str, scenario: Scenario) -> dict[str, Any]:
    """The run request the dashboard sends with "Use the scenario's setup" on: the catalog's
    defaults overridden by ``GET /api/datasets/{id}/setup`` (the scenario's grid, signals and
    settings with this realisation's drawn constants)."""
    dataset = simulated(client, scenario)
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


SIMULATED: dict[tuple[int, str], dict[str, Any]] = {}


def simulated(client: TestClient, scenario: Scenario) -> dict[str, Any]:
    """One dataset per scenario and test module (shared by the estimators of a family)."""
    key = (id(client), scenario.name)
    if key not in SIMULATED:
        simulate: dict[str, Any] = {"scenario": scenario.name, "seed": 0}
        if DURATION_S.get(scenario.name) is not None:
            simulate["duration_s"] = DURATION_S[scenario.name]
        response = client.post("/api/datasets/simulate", json=simulate)
        assert response.status_code == 201, response.text
        SIMULATED[key] = response.json()
    return SIMULATED[key]
