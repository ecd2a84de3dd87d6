"""Real ``mapwise serve`` processes started, stopped and killed, one set per test (each test
starts its own servers on a fresh database of each backend, so the parallel phase runs them
side by side, tests/conftest.py ``EACH_TEST_ALONE``):

* kill -9 mid-run: after a restart the run is ``interrupted``; resumed, it ends on exactly
  the map of an uninterrupted run; the run workers die with the server;
* SIGTERM mid-run: the run persists a version where it stopped and is ``interrupted``;
  resumed, it ends on the uninterrupted map;
* an empty database is given the schema and the demo run;
* the WebSocket token never reaches the access log.

The stream and a killed run worker, on one shared server: ``test_live_server.py``.
"""

from __future__ import annotations

import json
import time
from typing import Any

import pytest
from websockets.sync.client import connect

from tests.support.helpers import log_csv, run_body, start_run, upload_ok
from tests.support.server import Server, is_dead

pytestmark = pytest.mark.slow  # real servers killed, stopped and restarted


def _upload(server: Server, text: str) -> int:
    return int(upload_ok(server.http, text)["id"])


def _start(server: Server, body: dict[str, Any]) -> int:
    return int(start_run(server.http, body)["id"])


def _wait_progress(server: Server, run_id: int, timeout: float = 60.0) -> None:
    """Until run ``run_id`` has executed some of its samples."""
    deadline = time.monotonic() + timeout
    while server.get(f"/api/runs/{run_id}")["progress"] <= 0:
        assert time.monotonic() < deadline, server.output()
        time.sleep(0.05)


def test_kill_9_mid_run_then_resume_gives_the_uninterrupted_map(
    backend: str,
    fresh_url,  # type: ignore[no-untyped-def]
) -> None:
    url = fresh_url(backend)
    first = Server(url)
    try:
        dataset = _upload(first, log_csv(6000, seed=32, rate_hz=100.0))
        reference = _start(first, run_body(dataset))
        assert first.wait_run(reference, ("succeeded", "failed"))["status"] == "succeeded"
        expected = first.get(f"/api/runs/{reference}/export", params={"format": "json"})
        run_id = _start(first, run_body(dataset, pace=10, version_every={"samples": 500}))
        first.wait_versions(run_id, 3)
        workers = first.descendants()
        first.kill()
    except BaseException:
        first.stop()
        raise
    deadline = time.monotonic() + 10
    while not all(is_dead(pid) for pid in workers):
        assert time.monotonic() < deadline, "run workers outlived the killed server"
        time.sleep(0.1)

    second = Server(url)
    try:
        run = second.get(f"/api/runs/{run_id}")
        assert run["status"] == "interrupted"
        assert 0 < run["progress"] < 1
        assert "resume" in run["error"]
        response = second.post(f"/api/runs/{run_id}/resume")
        assert response.status_code == 200, response.text
        done = second.wait_run(run_id, ("succeeded", "failed", "interrupted"))
        assert done["status"] == "succeeded", done["error"]
        got = second.get(f"/api/runs/{run_id}/export", params={"format": "json"})
        assert got["values"] == expected["values"]
        assert got["variance"] == expected["variance"]
        assert got["rejected"] == expected["rejected"]
        versions = second.get(f"/api/runs/{run_id}/versions")["items"]
        assert versions[-1]["final"]
        assert [v["step"] for v in versions] == sorted(v["step"] for v in versions)
    finally:
        second.stop()


def test_graceful_stop_interrupts_then_resume_completes(backend: str, fresh_url) -> None:  # type: ignore[no-untyped-def]
    url = fresh_url(backend)
    first = Server(url)
    try:
        dataset = _upload(first, log_csv(4000, seed=34, rate_hz=100.0))
        reference = _start(first, run_body(dataset))
        first.wait_run(reference, ("succeeded",))
        expected = first.get(f"/api/runs/{reference}/export", params={"format": "json"})
        run_id = _start(first, run_body(dataset, pace=5, version_every={"samples": 1000}))
        first.wait_run(run_id, ("running",))
        _wait_progress(first, run_id)  # part-way through when it is stopped
    finally:
        first.stop()  # SIGTERM: the run persists where it is and is marked interrupted
    # uvicorn re-raises SIGTERM after its graceful shutdown, so the exit is "terminated by 15".
    assert first.process.returncode in (0, -15), first.output()
    second = Server(url)
    try:
        run = second.get(f"/api/runs/{run_id}")
        assert run["status"] == "interrupted"
        assert 0 < run["progress"] < 1
        versions = second.get(f"/api/runs/{run_id}/versions")["items"]
        assert versions[-1]["step"] == run["sample"]  # a version at the stopping point
        assert second.post(f"/api/runs/{run_id}/resume").status_code == 200
        assert second.wait_run(run_id, ("succeeded", "failed"))["status"] == "succeeded"
        got = second.get(f"/api/runs/{run_id}/export", params={"format": "json"})
        assert got["values"] == expected["values"]
        assert got["variance"] == expected["variance"]
    finally:
        second.stop()


def test_empty_database_gets_schema_and_demo(backend: str, fresh_url) -> None:  # type: ignore[no-untyped-def]
    srv = Server(fresh_url(backend), demo=True)
    try:
        runs = srv.get("/api/runs")["items"]
        assert len(runs) == 1
        assert runs[0]["status"] == "succeeded"
        assert runs[0]["estimator"] == "skf"
        assert f"mapwise: demo run at http://localhost:{srv.port}/runs/{runs[0]['id']}" in (
            srv.output()
        )
        datasets = srv.get("/api/datasets")["items"]
        assert datasets[0]["rows"] == 7500
        assert srv.http.get("/", follow_redirects=False).headers["location"] == "/datasets"
        plotly = srv.http.get("/static/vendor/plotly.min.js")
        assert plotly.status_code == 200
        assert len(plotly.content) > 1_000_000
    finally:
        srv.stop()


def test_the_websocket_token_never_reaches_the_log(backend: str, fresh_url) -> None:  # type: ignore[no-untyped-def]
    from app.cli import main as cli_main

    url = fresh_url(backend)
    assert cli_main(["db", "upgrade", "--database-url", url]) == 0
    from app.db.engine import Database
    from app.services.tokens import TokenService

    db = Database(url)
    _, secret = TokenService(db).create("log test")
    db.dispose()
    srv = Server(url, log_level="info", env={"MAPWISE_REQUIRE_AUTH": "1"})
    try:
        headers = {"Authorization": f"Bearer {secret}"}
        assert srv.http.get("/api/runs", headers=headers).status_code == 200
        with connect(f"{srv.ws_base}/api/runs/999/stream?token={secret}") as ws:
            assert json.loads(ws.recv(timeout=30))["type"] == "error"  # no such run
        deadline = time.monotonic() + 30
        while "/api/runs/999/stream" not in srv.output():  # the access log line, once written
            assert time.monotonic() < deadline, srv.output()
            time.sleep(0.05)
        log = srv.output()
        assert "/api/runs/999/stream?token=***" in log
        assert secret not in log
    finally:
        srv.stop()
