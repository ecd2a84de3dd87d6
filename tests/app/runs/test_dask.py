"""Runs on a Dask cluster (a scheduler and two workers as local processes) sharing
PostgreSQL with the API processes (``MAPWISE_EXECUTOR=dask``):

* a run through Dask ends on the map of the estimator run directly;
* its live frames reach a viewer connected to *another* API process;
* a worker killed mid-run, and mid-sweep: the run finishes on the other worker, resumed
  from its last version, once, on the uninterrupted map, with the lost attempt counted;
* the API process killed mid-sweep: every run still reaches a terminal state, correctly.
"""

from __future__ import annotations

import json
import os
import signal
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from websockets.sync.client import connect

from tests.support.cluster import DaskCluster
from tests.support.helpers import log_csv, reference_run, run_body, start_run, upload_ok
from tests.support.server import Server

TERMINAL = ("succeeded", "failed", "cancelled", "interrupted")


@pytest.fixture(scope="module")
def cluster() -> Iterator[DaskCluster]:
    c = DaskCluster(workers=2)
    yield c
    c.stop()


def _dask_server(url: str, cluster: DaskCluster) -> Server:
    env = {"MAPWISE_EXECUTOR": "dask", "MAPWISE_DASK_ADDRESS": cluster.address}
    return Server(url, env=env)


@pytest.fixture(scope="module")
def database(fresh_url) -> str:  # type: ignore[no-untyped-def]
    return str(fresh_url("postgresql"))


def _final(server: Server, run_id: int) -> np.ndarray:
    return np.array(server.get(f"/api/runs/{run_id}/export", params={"format": "json"})["values"])


@pytest.mark.dask
@pytest.mark.postgres
def test_runs_on_dask_equal_the_estimator_run_directly(
    cluster: DaskCluster, database: str, tmp_path: Any
) -> None:
    server = _dask_server(database, cluster)
    try:
        assert server.get("/api/health")["status"] == "ok"
        text = log_csv(2500, seed=50)
        dataset = upload_ok(server.http, text)
        runs = {e: start_run(server.http, run_body(dataset["id"], e)) for e in ("kf", "skf")}
        for estimator, run in runs.items():
            done = server.wait_run(int(run["id"]), TERMINAL)
            assert done["status"] == "succeeded", done["error"]
            assert done["attempt"] == 1
            expected = reference_run(text, tmp_path, estimator)["values"]
            np.testing.assert_array_equal(_final(server, int(run["id"])), expected)
    finally:
        server.stop()


@pytest.mark.dask
@pytest.mark.postgres
def test_live_frames_reach_a_viewer_on_another_api_process(
    cluster: DaskCluster, database: str
) -> None:
    submitter, watcher = _dask_server(database, cluster), _dask_server(database, cluster)
    try:
        dataset = upload_ok(submitter.http, log_csv(3000, seed=51, rate_hz=100.0))
        run_id = int(start_run(submitter.http, run_body(dataset["id"], pace=10))["id"])  # 3 s
        messages: list[dict[str, Any]] = []
        with connect(f"{watcher.ws_base}/api/runs/{run_id}/stream", open_timeout=30) as ws:
            while True:
                message = json.loads(ws.recv(timeout=60))
                messages.append(message)
                if message["type"] == "status" and message["status"] in TERMINAL:
                    break
        assert messages[0]["type"] == "full"
        deltas = [m for m in messages if m["type"] == "delta"]
        assert len(deltas) >= 10  # frames published on a Dask worker, fanned out by Dask
        assert messages[-1]["status"] == "succeeded"
        assert deltas[-1]["values"] == _final(watcher, run_id).tolist()
    finally:
        submitter.stop()
        watcher.stop()


@pytest.mark.dask
@pytest.mark.postgres
def test_a_killed_worker_mid_run_is_resumed_elsewhere_once(
    cluster: DaskCluster, database: str, tmp_path: Any
) -> None:
    server = _dask_server(database, cluster)
    try:
        text = log_csv(4000, seed=52, rate_hz=100.0)  # 40 s of log
        dataset = upload_ok(server.http, text)
        body = run_body(dataset["id"], pace=5, version_every={"samples": 500})  # 8 s
        run_id = int(start_run(server.http, body)["id"])
        server.wait_versions(run_id, 2)
        address = cluster.worker_running(f"mapwise-run-{run_id}-")
        os.kill(cluster.worker_pids()[address], signal.SIGKILL)  # as the OOM killer would
        done = server.wait_run(run_id, TERMINAL, timeout=120)
        assert done["status"] == "succeeded", (done, cluster.output())
        assert (done["attempt"], done["lost_attempts"]) == (2, 1)
        expected = reference_run(text, tmp_path, "skf")["values"]
        np.testing.assert_array_equal(_final(server, run_id), expected)
        versions = server.get(f"/api/runs/{run_id}/versions")["items"]
        steps = [v["step"] for v in versions]
        assert steps == sorted(set(steps))  # nothing written twice
        assert [v["final"] for v in versions].count(True) == 1
        cluster.wait_for_workers(2)  # the nanny restarted the worker
    finally:
        server.stop()


@pytest.mark.dask
@pytest.mark.postgres
def test_a_worker_killed_mid_sweep_loses_no_run_and_doubles_none(
    cluster: DaskCluster, database: str, tmp_path: Any
) -> None:
    server = _dask_server(database, cluster)
    text = log_csv(2000, seed=54, rate_hz=100.0)  # 20 s of log: 2–4 s a run at pace 5–10
    try:
        cluster.wait_for_workers(2)
        dataset = upload_ok(server.http, text)
        body = run_body(dataset["id"], version_every={"samples": 250}) | {
            "parameters": {"sigma_w": [0.003, 0.01, 0.03], "pace": [5, 10]},
            "metric": "output_rmse",
        }
        sweep = server.http.post("/api/sweeps", json=body).json()
        victim = sweep["runs"][0]["id"]
        server.wait_versions(victim, 1)
        address = cluster.worker_running(f"mapwise-run-{victim}-")
        os.kill(cluster.worker_pids()[address], signal.SIGKILL)
        deadline = time.monotonic() + 180
        while True:
            doc = server.get(f"/api/sweeps/{sweep['id']}")
            if all(r["status"] in TERMINAL for r in doc["runs"]):
                break
            assert time.monotonic() < deadline, (doc["counts"], cluster.output())
            time.sleep(0.2)
        assert doc["counts"] == {"succeeded": 6}
        runs = [server.get(f"/api/runs/{r['id']}") for r in doc["runs"]]
        assert sum(r["lost_attempts"] for r in runs) == 1
        assert next(r for r in runs if r["id"] == victim)["lost_attempts"] == 1
        for run in doc["runs"]:
            config = {k: v for k, v in run["params"].items() if k != "pace"}
            expected = reference_run(text, tmp_path, "skf", **config)["values"]
            np.testing.assert_array_equal(_final(server, run["id"]), expected)
            versions = server.get(f"/api/runs/{run['id']}/versions")["items"]
            assert [v["final"] for v in versions].count(True) == 1
        cluster.wait_for_workers(2)
    finally:
        server.stop()


@pytest.mark.dask
@pytest.mark.postgres
def test_the_api_process_killed_mid_sweep_loses_no_run(
    cluster: DaskCluster, database: str, tmp_path: Any
) -> None:
    first = _dask_server(database, cluster)
    text = log_csv(2000, seed=53, rate_hz=100.0)
    sigma_w = [0.003, 0.01, 0.03]
    try:
        dataset = upload_ok(first.http, text)
        body = run_body(dataset["id"]) | {
            "parameters": {"sigma_w": sigma_w, "pace": [10, 20]},
            "metric": "output_rmse",
        }
        response = first.http.post("/api/sweeps", json=body)
        assert response.status_code == 201, response.text
        sweep = response.json()
        first.wait_run(sweep["runs"][0]["id"], ("running", "succeeded"))
    finally:
        first.kill()  # kill -9 mid-sweep: the submitted runs live on in the cluster
    second = _dask_server(database, cluster)
    try:
        deadline = time.monotonic() + 180
        while True:
            doc = second.get(f"/api/sweeps/{sweep['id']}")
            if all(r["status"] in TERMINAL for r in doc["runs"]):
                break
            assert time.monotonic() < deadline, (doc["counts"], cluster.output())
            time.sleep(0.2)
        assert doc["counts"] == {"succeeded": 6}
        for run in doc["runs"]:
            config = {k: v for k, v in run["params"].items() if k != "pace"}
            expected = reference_run(text, tmp_path, "skf", **config)["values"]
            np.testing.assert_array_equal(_final(second, run["id"]), expected)
    finally:
        second.stop()


def test_dask_needs_postgresql_and_an_address(tmp_path: Any) -> None:
    from pydantic import ValidationError

    from app.config import Settings

    with pytest.raises(ValidationError, match="postgresql"):
        Settings(executor="dask", dask_address="tcp://x:1", database_url="sqlite:///x.db")
    with pytest.raises(ValidationError, match="dask_address"):
        Settings(executor="dask", database_url="postgresql+psycopg://u@h/d")
