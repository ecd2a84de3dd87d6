"""Attempts, fencing and heartbeats, on SQLite and PostgreSQL, in-process (the app under a
``TestClient``):

* a newer attempt (a Dask retry, say) supersedes the running one: the old worker's writes are
  refused from then on, the run finishes once, on the uninterrupted map;
* the sweep finds attempts that stopped heartbeating — also one that died before its first
  heartbeat — and interrupts or re-queues them by policy.

Attempts on real ``mapwise serve`` processes (a poison run, two servers on one database):
``test_attempts_on_servers.py``.
"""

from __future__ import annotations

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
