"""Fifty ``kill -9``s of run workers at random points (during start-up, mid-run, at a version
write) on a real server that re-queues lost attempts: afterwards no run is left running,
none is finished twice, and every run ends on the map of an uninterrupted run."""

from __future__ import annotations

import os
import random
import signal
import time
from typing import Any

import numpy as np
import pytest

from tests.support.helpers import log_csv, reference_run, run_body, start_run, upload_ok
from tests.support.server import Server

KILLS = 50
RUNS = 12


def _count(server: Server, status: str) -> int:
    """How many runs of the server have ``status``."""
    return int(server.get("/api/runs", params={"status": status})["total"])


@pytest.mark.slow
def test_fifty_worker_kills_lose_and_double_nothing(backend: str, fresh_url, tmp_path: Any) -> None:  # type: ignore[no-untyped-def]
    env = {
        "MAPWISE_LOST_RUN_POLICY": "requeue",
        "MAPWISE_MAX_LOST_ATTEMPTS": "100",
        "MAPWISE_HEARTBEAT_S": "0.2",
        "MAPWISE_HEARTBEAT_TIMEOUT_S": "1.0",
    }
    server = Server(fresh_url(backend), env=env)
    rng = random.Random(7)
    try:
        text = log_csv(3000, seed=97, rate_hz=100.0)  # 30 s of log
        dataset = upload_ok(server.http, text)
        body = run_body(dataset["id"], pace=10, version_every={"samples": 300})  # 3 s a run
        ids = [int(start_run(server.http, body)["id"]) for _ in range(RUNS)]
        kills = 0
        deadline = time.monotonic() + 400
        while kills < KILLS:
            assert time.monotonic() < deadline, server.output()
            if kills % 2:  # every other kill hits a worker while a run is executing
                while _count(server, "running") == 0:
                    assert time.monotonic() < deadline, server.output()
                    if _count(server, "queued") == _count(server, "running") == 0:
                        # Every run finished before the kills did: one more for them to hit
                        # (waiting for a running run would otherwise wait forever).
                        ids.append(int(start_run(server.http, body)["id"]))
                    time.sleep(0.02)
                time.sleep(rng.uniform(0.0, 0.4))  # anywhere in it: a chunk, a version write
            else:  # the others at any moment, start-up of the new pool included
                time.sleep(rng.uniform(0.05, 1.0))
            workers = server.workers()
            if not workers:
                continue
            try:
                os.kill(rng.choice(workers), signal.SIGKILL)
                kills += 1
            except ProcessLookupError:
                pass
        expected = reference_run(text, tmp_path, "skf")["values"]
        lost = 0
        for run_id in ids:
            done = server.wait_run(run_id, ("succeeded", "failed", "interrupted"), timeout=300)
            assert done["status"] == "succeeded", done
            lost += done["lost_attempts"]
            got = server.get(f"/api/runs/{run_id}/export", params={"format": "json"})
            np.testing.assert_array_equal(np.array(got["values"]), expected)
            versions = server.get(f"/api/runs/{run_id}/versions")["items"]
            steps = [v["step"] for v in versions]
            assert steps == sorted(set(steps)), steps  # nothing written twice
            assert [v["final"] for v in versions].count(True) == 1
        assert lost > 0  # the kills did hit runs mid-way
        assert _count(server, "running") == 0
    finally:
        server.stop()
