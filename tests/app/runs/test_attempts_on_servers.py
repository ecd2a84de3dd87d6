"""Attempts on real ``mapwise serve`` processes, on SQLite and PostgreSQL, each test with its
own servers (so the parallel phase runs them side by side, tests/conftest.py
``EACH_TEST_ALONE``):

* a poison run (its worker killed on every attempt) fails after ``max_lost_attempts``;
* two servers on one database leave each other's runs alone at start-up and shutdown.

Fencing and the heartbeat sweep, in-process: ``test_attempts.py``.
"""

from __future__ import annotations

import os
import signal
import time

import pytest

from tests.support.helpers import log_csv, run_body, start_run, upload_ok
from tests.support.server import Server


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
