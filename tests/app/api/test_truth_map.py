"""``GET /api/runs/{run_id}/truth-map``: a simulated dataset's true map on the run's grid
(app/services/truth_map.py), for the run view's "estimated − true" map."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient

from estimation.plants.nox import nox_axes
from estimation.scenarios import get_scenario
from tests.support.helpers import start_run, upload_ok, wait_run

SEED, DURATION_S = 5, 5.0


@pytest.fixture(scope="module")
def nox(client: TestClient) -> dict:
    """5 s of simulated NEDC NOx (perfect model: the truth is a table on the NOx grid)."""
    body = {"scenario": "nox-nedc", "seed": SEED, "duration_s": DURATION_S, "mismatch": "none"}
    response = client.post("/api/datasets/simulate", json=body)
    assert response.status_code == 201, response.text
    return response.json()


def kf_run(client: TestClient, dataset_id: int, axes: list[dict], y: str = "nox_ppm") -> dict:
    body = {
        "dataset_id": dataset_id,
        "estimator": "kf",
        "signals": {"y": y},
        "table": {"axes": axes},
        "config": {"sigma_w": 5, "sigma_v": 50, "p0": 1000},
    }
    return wait_run(client, start_run(client, body)["id"])


def test_truth_on_the_truths_own_grid_is_exact(client: TestClient, nox: dict) -> None:
    axes = [{"name": a.name, "breakpoints": a.breakpoints.tolist()} for a in nox_axes()]
    run = kf_run(client, nox["id"], axes)
    response = client.get(f"/api/runs/{run['id']}/truth-map")
    assert response.status_code == 200, response.text
    body = response.json()
    built = get_scenario("nox-nedc").build(seed=SEED, duration_s=DURATION_S, mismatch="none")
    assert built.true_map is not None
    np.testing.assert_array_equal(np.array(body["values"]), built.true_map.values)
    assert body["exact"] is True
    assert (body["name"], body["unit"]) == ("nox_ppm", "ppm")
    assert [a["name"] for a in body["axes"]] == ["speed_rpm", "fuel_mg_per_stroke"]


def test_truth_on_another_grid_follows_the_runs_axes(client: TestClient, nox: dict) -> None:
    """Axes in the other order, other breakpoints: the truth interpolated at the run's nodes."""
    fuel = [0.0, 12.5, 40.0, 80.0]
    speed = [800.0, 2200.0, 4500.0]
    axes = [
        {"name": "fuel_mg_per_stroke", "breakpoints": fuel},
        {"name": "speed_rpm", "breakpoints": speed},
    ]
    run = kf_run(client, nox["id"], axes)
    body = client.get(f"/api/runs/{run['id']}/truth-map").json()
    built = get_scenario("nox-nedc").build(seed=SEED, duration_s=DURATION_S, mismatch="none")
    assert built.true_map is not None
    values = np.array(body["values"])
    assert values.shape == (len(fuel), len(speed))
    for i, f in enumerate(fuel):
        for j, n in enumerate(speed):
            assert values[i, j] == pytest.approx(float(built.true_map.evaluate([[n, f]])[0]))
    assert body["exact"] is False


def test_no_truth_is_404_naming_the_run(client: TestClient, example_csv) -> None:
    dataset = upload_ok(client, example_csv.read_bytes(), "example_nox.csv")
    axes = [
        {"name": "speed_rpm", "breakpoints": [1000, 2000, 3000]},
        {"name": "fuel_mg_per_stroke", "breakpoints": [0, 20, 40]},
    ]
    run = kf_run(client, dataset["id"], axes)
    response = client.get(f"/api/runs/{run['id']}/truth-map")
    assert response.status_code == 404
    error = response.json()["error"]
    assert error["field"] == "run_id"
    assert "no truth" in error["message"]

    missing = client.get("/api/runs/987654/truth-map")
    assert missing.status_code == 404
    assert missing.json()["error"]["field"] == "run_id"


def test_truth_without_a_map_is_404(client: TestClient) -> None:
    sim = client.post(
        "/api/datasets/simulate", json={"scenario": "torque-si", "seed": 1, "duration_s": 6.0}
    )
    assert sim.status_code == 201, sim.text
    body = {"dataset_id": sim.json()["id"], "estimator": "uio", "signals": {}, "config": {}}
    run = wait_run(client, start_run(client, body)["id"])
    response = client.get(f"/api/runs/{run['id']}/truth-map")
    assert response.status_code == 404
    assert "no true map" in response.json()["error"]["message"]


def test_grid_over_other_inputs_has_no_true_map(client: TestClient, nox: dict) -> None:
    axes = [
        {"name": "speed_rpm", "breakpoints": [1000, 2000, 3000]},
        {"name": "nox_ppm", "breakpoints": [0, 200, 400]},
    ]
    run = kf_run(client, nox["id"], axes, y="fuel_mg_per_stroke")
    response = client.get(f"/api/runs/{run['id']}/truth-map")
    assert response.status_code == 200  # an answer the run view asks for, not an error
    doc = response.json()
    assert doc["values"] is None
    assert "nox_ppm" in doc["reason"]
