"""When the local executor's run workers start (``MAPWISE_RUN_WORKERS_PRESTART``), read off
``/api/health``'s ``workers_alive`` of the real app: all at start-up by default; without
prestart, none until a run needs one, and the worker that ran it is kept."""

from __future__ import annotations

import time

from fastapi.testclient import TestClient

from app.api import create_app
from tests.support.helpers import (
    log_csv,
    run_body,
    service_settings,
    start_run,
    upload_ok,
    wait_run,
)


def _alive_reaches(client: TestClient, count: int, timeout: float = 60.0) -> int:
    """``workers_alive`` once it equals ``count`` (or, after ``timeout``, what it is then)."""
    deadline = time.monotonic() + timeout
    while True:
        alive = client.get("/api/health").json()["workers_alive"]
        if alive == count or time.monotonic() > deadline:
            return int(alive)
        time.sleep(0.05)


def test_workers_start_with_the_server_by_default(fresh_url) -> None:  # type: ignore[no-untyped-def]
    settings = service_settings(fresh_url("sqlite"), run_workers_prestart=True)
    with TestClient(create_app(settings)) as client:
        assert client.get("/api/health").json()["workers"] == 2
        assert _alive_reaches(client, 2) == 2  # before any run


def test_without_prestart_a_worker_starts_with_the_first_run_and_stays(fresh_url) -> None:  # type: ignore[no-untyped-def]
    settings = service_settings(fresh_url("sqlite"), run_workers_prestart=False)
    with TestClient(create_app(settings)) as client:
        dataset = upload_ok(client, log_csv(600, seed=41))
        assert client.get("/api/health").json()["workers_alive"] == 0
        first = start_run(client, run_body(dataset["id"]))
        assert wait_run(client, first["id"])["status"] == "succeeded"
        assert client.get("/api/health").json()["workers_alive"] == 1  # kept, idle
        second = start_run(client, run_body(dataset["id"]))
        assert wait_run(client, second["id"])["status"] == "succeeded"
        # Two runs at once need the second slot's worker too.
        slow = [start_run(client, run_body(dataset["id"], pace=2)) for _ in range(2)]
        assert _alive_reaches(client, 2) == 2
        for run in slow:
            client.post(f"/api/runs/{run['id']}/cancel")
            assert wait_run(client, run["id"])["status"] in ("cancelled", "succeeded")
