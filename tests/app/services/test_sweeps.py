"""Sweeps and fleet batches through the real app, on SQLite and PostgreSQL."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.services.sweeps import Range, expand_parameters
from estimation.merge import merge_maps
from tests.support.helpers import (
    TABLE,
    final_values,
    log_csv,
    reference_run,
    upload_ok,
    wait_group,
)


def _sweep_body(dataset_id: int, **extra: object) -> dict:
    return {
        "dataset_id": dataset_id,
        "estimator": "skf",
        "signals": {"y": "y"},
        "table": TABLE,
        "config": {"p0": 10.0},
        "parameters": {"sigma_w": [0.001, 0.01, 0.1], "sigma_v": [0.05, 0.5]},
        "metric": "output_rmse",
    } | extra


@pytest.mark.slow
def test_a_grid_sweep_runs_every_point_and_ranks_them(client: TestClient, tmp_path) -> None:  # type: ignore[no-untyped-def]
    text = log_csv(2000, seed=60)
    dataset = upload_ok(client, text)
    response = client.post("/api/sweeps", json=_sweep_body(dataset["id"]))
    assert response.status_code == 201, response.text
    sweep = response.json()
    assert len(sweep["runs"]) == 6
    assert {tuple(sorted(r["params"].items())) for r in sweep["runs"]} == {
        (("sigma_v", v), ("sigma_w", w)) for w in (0.001, 0.01, 0.1) for v in (0.05, 0.5)
    }
    done = wait_group(client, f"/api/sweeps/{sweep['id']}")
    assert done["counts"] == {"succeeded": 6}
    metrics = [r["metric"] for r in done["runs"]]
    assert metrics == sorted(metrics)  # best (lowest output RMSE) first
    assert done["best_run_id"] == done["runs"][0]["id"]
    best = done["runs"][0]
    expected = reference_run(text, tmp_path, "skf", p0=10.0, **best["params"])["values"]
    np.testing.assert_array_equal(np.array(final_values(client, best["id"])["values"]), expected)
    listed = client.get("/api/sweeps").json()
    assert sweep["id"] in [s["id"] for s in listed["items"]]


def test_a_random_sweep_is_seeded_and_bad_values_store_nothing(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(800, seed=61))
    params = {"sigma_w": {"min": 1e-3, "max": 1.0, "scale": "log"}, "sigma_v": [0.05, 0.1]}
    body = _sweep_body(dataset["id"], parameters=params, samples=4, seed=7, order="max")
    first = client.post("/api/sweeps", json=body).json()
    drawn = [r["params"] for r in sorted(first["runs"], key=lambda r: r["id"])]
    assert drawn == expand_parameters(
        {"sigma_w": Range(min=1e-3, max=1.0, scale="log"), "sigma_v": [0.05, 0.1]},
        samples=4,
        seed=7,
    )
    assert all(1e-3 <= p["sigma_w"] <= 1.0 for p in drawn)
    wait_group(client, f"/api/sweeps/{first['id']}")

    before = client.get("/api/runs", params={"limit": 1}).json()["total"]
    sweeps = client.get("/api/sweeps").json()["total"]
    bad = client.post(
        "/api/sweeps", json=_sweep_body(dataset["id"], parameters={"sigma_w": [0.01, -1.0]})
    )
    assert bad.status_code == 422
    assert bad.json()["error"]["field"] == "parameters.sigma_w"
    assert "-1.0" in bad.json()["error"]["message"]
    no_samples = client.post(
        "/api/sweeps", json=_sweep_body(dataset["id"], parameters={"sigma_w": {"min": 0, "max": 1}})
    )
    assert no_samples.status_code == 422
    assert no_samples.json()["error"]["field"] == "parameters.sigma_w"
    grid = {"sigma_w": list(range(1, 60)), "p0": list(range(1, 60))}  # 3481 points
    too_big = client.post("/api/sweeps", json=_sweep_body(dataset["id"], parameters=grid))
    assert too_big.status_code == 422
    for parameters, field in (
        ({"sensor": [None], "sensor.lag": [0.9]}, "parameters.sensor"),  # once a 500
        ({"sensor.lag": [0.9], "sensor": [0.5]}, "parameters.sensor"),
        ({"sensor..lag": [0.9]}, "parameters.sensor..lag"),
    ):
        overlap = client.post("/api/sweeps", json=_sweep_body(dataset["id"], parameters=parameters))
        assert overlap.status_code == 422, overlap.text
        assert overlap.json()["error"]["field"] == field
    unknown = client.post("/api/sweeps", json=_sweep_body(dataset["id"], metric="nonsense"))
    assert unknown.status_code == 422, unknown.text
    assert unknown.json()["error"]["field"] == "metric"
    assert "output_rmse" in unknown.json()["error"]["message"]
    assert client.get("/api/runs", params={"limit": 1}).json()["total"] == before
    assert client.get("/api/sweeps").json()["total"] == sweeps


def test_a_fleet_batch_merges_the_vehicles_maps(client: TestClient) -> None:
    datasets = [upload_ok(client, log_csv(2500, seed=70 + i))["id"] for i in range(4)]
    body = {
        "dataset_ids": datasets,
        "estimator": "kf",
        "signals": {"y": "y"},
        "table": TABLE,
        "config": {"sigma_w": 0.01, "sigma_v": 0.05, "p0": 10.0},
    }
    response = client.post("/api/batches", json=body)
    assert response.status_code == 201, response.text
    batch = response.json()
    assert [r["dataset_id"] for r in batch["runs"]] == datasets
    done = wait_group(client, f"/api/batches/{batch['id']}")
    assert done["counts"] == {"succeeded": 4}
    agg = done["aggregate"]
    versions = []
    for run in done["runs"]:
        last = client.get(f"/api/runs/{run['id']}/versions").json()["items"][-1]
        versions.append(client.get(f"/api/runs/{run['id']}/versions/{last['id']}").json())
    expected = merge_maps(
        np.array([v["values"] for v in versions]), np.array([v["variances"] for v in versions])
    )
    np.testing.assert_allclose(agg["values"], expected.values, rtol=1e-12)
    np.testing.assert_allclose(agg["z"], expected.z, rtol=1e-9, atol=1e-12)
    assert agg["run_ids"] == [r["id"] for r in done["runs"]]
    assert len(agg["deviating_cells"]) == 4

    bad = client.post("/api/batches", json=body | {"dataset_ids": [datasets[0], 999_999]})
    assert bad.status_code == 422
    assert bad.json()["error"]["field"] == "dataset_ids[1]"


def test_expand_parameters_grid_and_errors() -> None:
    grid = expand_parameters({"a": [1, 2], "b": ["x"]}, samples=None, seed=0)
    assert grid == [{"a": 1, "b": "x"}, {"a": 2, "b": "x"}]
    ints = expand_parameters({"n": Range(min=1, max=5, integer=True)}, samples=50, seed=1)
    assert {p["n"] for p in ints} <= {1, 2, 3, 4, 5}
    from app.errors import InvalidRequestError

    with pytest.raises(InvalidRequestError, match="log range"):
        expand_parameters({"a": Range(min=0, max=1, scale="log")}, samples=2, seed=0)
    with pytest.raises(InvalidRequestError, match="above max"):
        expand_parameters({"a": Range(min=2, max=1)}, samples=2, seed=0)


@pytest.mark.slow
def test_mapwise_sweep_cli_against_a_real_server(
    backend: str,
    fresh_url,  # type: ignore[no-untyped-def]
    capsys: pytest.CaptureFixture[str],
) -> None:
    from app.cli import main as cli_main
    from tests.support.server import Server

    srv = Server(fresh_url(backend))
    try:
        dataset = upload_ok(srv.http, log_csv(1000, seed=62))
        args = [
            "sweep", "--url", srv.base, "--dataset", str(dataset["id"]), "--estimator", "skf",
            "--y", "y", "--axis", "u1=500,1500,2500,3500", "--axis", "u2=0,20,40,60",
            "--set", "p0=10", "--set", "sigma_v=0.05", "--grid", "sigma_w=0.001,0.01,0.1",
        ]  # fmt: skip
        assert cli_main(args) == 0
        out = capsys.readouterr().out
        assert out.splitlines()[0].startswith("sweep ")
        ranked = [line.split() for line in out.splitlines()[3:]]
        assert [row[0] for row in ranked] == ["1", "2", "3"]
        metrics = [float(row[-1]) for row in ranked]
        assert metrics == sorted(metrics)
        assert cli_main([*args[:-2], "--grid", "sigma_w=0.01,-5"]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("mapwise: error: parameters.sigma_w:")
        assert len(err.splitlines()) == 1
        assert cli_main(["sweep", "--url", "http://127.0.0.1:9", "--dataset", "1",
                         "--estimator", "skf", "--grid", "sigma_w=1"]) == 2  # fmt: skip
        assert "cannot reach" in capsys.readouterr().err
    finally:
        srv.stop()
