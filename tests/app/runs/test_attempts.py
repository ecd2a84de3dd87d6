"""Attempts, fencing and heartbeats, on SQLite and PostgreSQL:

* a newer attempt (a Dask retry, say) supersedes the running one: the old worker's writes are
  refused from then on, the run finishes once, on the uninterrupted map;
* the sweep finds attempts that stopped heartbeating — also one that died before its first
  heartbeat — and interrupts or re-queues them by policy;
* a poison run (its worker killed on every attempt) fails after ``max_lost_attempts``;
* two servers on one database leave each other's runs alone at start-up and shutdown.
"""

from __future__ import annotations

import os
import signal
import time
from datetime import UTC, datetime, timedelta
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import update

from app.api import create_app
from app.db.engine import Database
from app.db.models import RunRow
from app.db.repositories import RunRepo
from app.errors import SupersededError
from app.runs.executor import dead_local_owner, local_owner
from app.runs.worker import WorkerContext, execute_run
from tests.support.helpers import (
    final_values,
    log_csv,
    run_body,
    service_settings,
    start_run,
    upload_ok,
    wait_run,
)
from tests.support.server import Server


def _age(url: str, run_id: int, *, seconds: float, heartbeat: bool = True) -> None:
    """Make a running run look silent for ``seconds`` (its heartbeat, or none at all)."""
    db = Database(url)
    then = datetime.now(UTC) - timedelta(seconds=seconds)
    try:
        with db.write() as s:
            s.execute(
                update(RunRow)
                .where(RunRow.id == run_id)
                .values(
                    status="running",
                    owner="local:another-host:1:1",
                    started_at=then,
                    heartbeat_at=then if heartbeat else None,
                )
            )
    finally:
        db.dispose()


def test_fence_refuses_a_superseded_attempt(database_url: str, client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(500, seed=40))
    run = start_run(client, run_body(dataset["id"]))
    wait_run(client, run["id"])
    db = Database(database_url)
    try:
        with db.write() as s:
            s.execute(update(RunRow).where(RunRow.id == run["id"]).values(status="queued"))
        with db.write() as s:
            first = RunRepo(s).claim(run["id"], owner="a")
        with db.write() as s:
            assert RunRepo(s).claim(run["id"], owner="b") is None  # running: not claimable
            second = RunRepo(s).claim(run["id"], owner="b", statuses=("running",))
        assert (first, second) is not None
        assert second == first + 1
        with pytest.raises(SupersededError), db.write() as s:
            RunRepo(s).fence(run["id"], first)
        with db.write() as s:
            RunRepo(s).fence(run["id"], second)
            RunRepo(s).set_status(run["id"], "succeeded", finished=True)
    finally:
        db.dispose()


@pytest.mark.slow
def test_a_newer_attempt_supersedes_the_running_one(database_url: str, client: TestClient) -> None:
    text = log_csv(3000, seed=41, rate_hz=100.0)  # 30 s of log
    dataset = upload_ok(client, text)
    reference = start_run(client, run_body(dataset["id"]))
    wait_run(client, reference["id"])
    expected = final_values(client, reference["id"])["values"]
    slow = start_run(client, run_body(dataset["id"], pace=5, version_every={"samples": 500}))
    deadline = time.monotonic() + 60
    while client.get(f"/api/runs/{slow['id']}").json()["n_versions"] < 1:
        assert time.monotonic() < deadline
        time.sleep(0.05)
    # A second executor takes the run over, as a Dask retry would, and finishes it.
    context = WorkerContext(database_url=database_url, owner="test:retry", take_over=True)
    assert execute_run(slow["id"], context) == "succeeded"
    done = client.get(f"/api/runs/{slow['id']}").json()
    assert (done["status"], done["attempt"]) == ("succeeded", 2)
    time.sleep(1.5)  # the first attempt meets its fence at its next write, and stops
    after = client.get(f"/api/runs/{slow['id']}").json()
    assert after["status"] == "succeeded"
    assert after["finished_at"] == done["finished_at"]  # completed once
    versions = client.get(f"/api/runs/{slow['id']}/versions").json()["items"]
    assert sum(v["final"] for v in versions) == 1
    assert [v["step"] for v in versions] == sorted({v["step"] for v in versions})
    assert final_values(client, slow["id"])["values"] == expected


@pytest.fixture(scope="module")
def requeue_client(backend: str, fresh_url) -> Any:  # type: ignore[no-untyped-def]
    url = fresh_url(backend)
    settings = service_settings(
        url, heartbeat_s=0.2, heartbeat_timeout_s=1.0, lost_run_policy="requeue"
    )
    with TestClient(create_app(settings)) as c:
        yield c, url


def _stopped_mid_run(client: TestClient, dataset_id: int) -> int:
    """A run cancelled part-way, with versions persisted: what a dead attempt leaves."""
    run = start_run(client, run_body(dataset_id, pace=10, version_every={"samples": 200}))
    deadline = time.monotonic() + 60
    while client.get(f"/api/runs/{run['id']}").json()["n_versions"] < 2:
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert client.post(f"/api/runs/{run['id']}/cancel").status_code == 200
    assert wait_run(client, run["id"])["status"] == "cancelled"
    return int(run["id"])


@pytest.mark.slow
def test_sweep_requeues_silent_attempts_and_one_that_never_beat(requeue_client) -> None:  # type: ignore[no-untyped-def]
    client, url = requeue_client
    dataset = upload_ok(client, log_csv(1500, seed=42, rate_hz=100.0))
    reference = start_run(client, run_body(dataset["id"]))
    wait_run(client, reference["id"])
    expected = final_values(client, reference["id"])["values"]
    runs = [_stopped_mid_run(client, dataset["id"]) for _ in range(2)]
    _age(url, runs[0], seconds=60)  # an attempt elsewhere, silent for a minute
    _age(url, runs[1], seconds=60, heartbeat=False)  # one that died before its first beat
    for run_id in runs:
        done = wait_run(client, run_id, until=("succeeded", "failed", "interrupted"))
        assert done["status"] == "succeeded", done
        assert done["lost_attempts"] == 1
        assert done["attempt"] == 2
        assert final_values(client, run_id)["values"] == expected


def test_sweep_interrupts_by_default(client: TestClient, database_url: str) -> None:
    from app.config import Settings
    from app.runs.executor import RunExecutor
    from app.runs.hub import LiveHub

    dataset = upload_ok(client, log_csv(1500, seed=43, rate_hz=100.0))
    run_id = _stopped_mid_run(client, dataset["id"])
    _age(database_url, run_id, seconds=600)
    db = Database(database_url)
    try:
        executor = RunExecutor(Settings(database_url=database_url), db, LiveHub())
        assert executor.sweep() == [run_id]
        assert executor.sweep() == []  # swept once
    finally:
        db.dispose()
    doc = client.get(f"/api/runs/{run_id}").json()
    assert doc["status"] == "interrupted"
    assert "stopped heartbeating" in doc["error"]
    assert client.post(f"/api/runs/{run_id}/resume").status_code == 200
    assert wait_run(client, run_id)["status"] == "succeeded"


def test_owner_ids_tell_dead_local_processes() -> None:
    mine = local_owner()
    assert not dead_local_owner(mine)
    assert not dead_local_owner("local:another-host:1:1")  # not ours to judge: the sweep's
    host, pid, start = mine.split(":")[1:]
    assert dead_local_owner(f"local:{host}:{pid}:{int(start) + 1}")  # the pid was reused
    assert dead_local_owner(f"local:{host}:999999999:1")
    assert not dead_local_owner("dask:tcp://scheduler:8786")


@pytest.mark.slow
def test_a_poison_run_fails_after_three_lost_attempts(backend: str, fresh_url) -> None:  # type: ignore[no-untyped-def]
    env = {"MAPWISE_LOST_RUN_POLICY": "requeue", "MAPWISE_MAX_LOST_ATTEMPTS": "3"}
    srv = Server(fresh_url(backend), workers=1, env=env)
    try:
        dataset = upload_ok(srv.http, log_csv(3000, seed=44, rate_hz=100.0))
        run_id = int(start_run(srv.http, run_body(dataset["id"], pace=2))["id"])
        for attempt in (1, 2, 3):  # its worker is killed every time, as an OOM killer would
            deadline = time.monotonic() + 60
            while srv.get(f"/api/runs/{run_id}")["attempt"] < attempt or not srv.workers():
                assert time.monotonic() < deadline, srv.output()
                time.sleep(0.05)
            srv.wait_run(run_id, ("running",))
            time.sleep(0.3)
            for pid in srv.workers():
                os.kill(pid, signal.SIGKILL)
            done = srv.wait_run(run_id, ("queued", "failed", "running"), timeout=60)
            if attempt < 3:
                assert done["status"] in ("queued", "running"), done
        done = srv.wait_run(run_id, ("failed",), timeout=60)
        assert "given up after 3 lost attempts" in done["error"]
        assert done["lost_attempts"] == 3
    finally:
        srv.stop()


@pytest.mark.slow
def test_two_servers_on_one_database_leave_each_others_runs_alone(
    backend: str,
    fresh_url,  # type: ignore[no-untyped-def]
) -> None:
    """The run is paced to outlast any server start-up (30 s of log at 0.1× is 300 s), so the
    checks wait on conditions, never on the clock: it is running while the second server
    starts and stops, its attempt then writes its next version, and it obeys a cancel."""
    url = fresh_url(backend)
    first = Server(url)
    try:
        dataset = upload_ok(first.http, log_csv(3000, seed=45, rate_hz=100.0))
        body = run_body(dataset["id"], pace=0.1, version_every={"seconds": 0.2})  # one per 2 s
        run_id = int(start_run(first.http, body)["id"])
        first.wait_run(run_id, ("running",))
        second = Server(url)  # its start-up sweep must not touch the first one's run
        try:
            assert second.get(f"/api/runs/{run_id}")["status"] == "running"
        finally:
            second.stop()  # nor its shutdown
        run = first.get(f"/api/runs/{run_id}")
        assert run["status"] == "running", run
        assert (run["attempt"], run["lost_attempts"]) == (1, 0), run
        first.wait_versions(run_id, run["n_versions"] + 1)  # the first attempt still writes
        assert first.post(f"/api/runs/{run_id}/cancel").status_code == 200
        done = first.wait_run(run_id, ("succeeded", "failed", "cancelled", "interrupted"))
        assert done["status"] == "cancelled", done
        assert (done["attempt"], done["lost_attempts"]) == (1, 0), done
    finally:
        first.stop()
