"""PostgreSQL restarted under a running server and a running run: requests meanwhile get 503
(never a 500), the API answers again within 10 s of the database, and the run finishes on
the uninterrupted map without a restart of mapwise."""

from __future__ import annotations

import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from tests.support.helpers import log_csv, reference_run, run_body, start_run, upload_ok
from tests.support.server import Server


def _restart_postgresql() -> None:
    version = sorted(p.name for p in Path("/etc/postgresql").iterdir())[0]
    subprocess.run(
        ["pg_ctlcluster", "--skip-systemctl-redirect", version, "main", "restart", "-m", "fast"],
        check=True,
        timeout=120,
    )


@pytest.mark.slow
@pytest.mark.postgres
@pytest.mark.serial  # restarts the PostgreSQL server every other test uses
def test_a_postgresql_restart_mid_run_is_survived(fresh_url, tmp_path: Any) -> None:  # type: ignore[no-untyped-def]
    srv = Server(fresh_url("postgresql"))
    statuses: list[int] = []
    stop = threading.Event()

    def poll() -> None:
        with httpx.Client(base_url=srv.base, timeout=30) as client:
            while not stop.is_set():
                try:
                    statuses.append(client.get("/api/runs", params={"limit": 1}).status_code)
                except httpx.TransportError:
                    statuses.append(-1)
                time.sleep(0.05)

    try:
        text = log_csv(4000, seed=80, rate_hz=100.0)  # 40 s of log
        dataset = upload_ok(srv.http, text)
        body = run_body(dataset["id"], pace=5, version_every={"samples": 500})  # 8 s
        run_id = int(start_run(srv.http, body)["id"])
        srv.wait_versions(run_id, 1)
        poller = threading.Thread(target=poll, daemon=True)
        poller.start()
        _restart_postgresql()
        back = time.monotonic()
        while srv.http.get("/api/health").status_code != 200:
            assert time.monotonic() - back < 10.0, "the API did not recover within 10 s"
            time.sleep(0.1)
        stop.set()
        poller.join(timeout=30)
        assert set(statuses) <= {200, 503}, sorted(set(statuses))
        done = srv.wait_run(run_id, ("succeeded", "failed", "interrupted"), timeout=120)
        assert done["status"] == "succeeded", (done, srv.output())
        got = np.array(srv.get(f"/api/runs/{run_id}/export", params={"format": "json"})["values"])
        np.testing.assert_array_equal(got, reference_run(text, tmp_path, "skf")["values"])
    finally:
        stop.set()
        srv.stop()
