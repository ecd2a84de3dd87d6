"""A short run of the load test (scripts/load.py) against a real server on SQLite and on
PostgreSQL: 6 users uploading, starting paced runs and watching their streams for 15 s —
no error, no lost run, live frames delivered, p99 latency bounded."""

from __future__ import annotations

import pytest

from scripts.load import run_load
from tests.support.server import Server

pytestmark = pytest.mark.serial  # bounds p99 latency and frame delay


@pytest.mark.soak
def test_concurrent_users_get_no_errors_and_lose_no_run(backend: str, fresh_url) -> None:  # type: ignore[no-untyped-def]
    server = Server(fresh_url(backend))
    try:
        result = run_load(server.base, users=6, seconds=15.0, settle_s=180.0)
    finally:
        server.stop()
    assert result["error_count"] == 0, result["errors"]
    assert result["lost_runs"] == []
    assert result["runs_started"] >= 6
    assert result["frames"] >= result["runs_started"]  # every viewer got at least its full frame
    assert result["p99_ms"] < 2000, result


@pytest.mark.soak
def test_a_short_soak_with_streaming_runs(fresh_url) -> None:  # type: ignore[no-untyped-def]
    """The soak of README in short: users plus long runs streamed throughout; no error, no
    lost run, live frames reach their viewers within a second."""
    server = Server(fresh_url("sqlite"), workers=4)  # the two long runs hold two workers
    try:
        result = run_load(
            server.base,
            users=4,
            seconds=20.0,
            streams=2,
            settle_s=180.0,
            server_pid=server.process.pid,
        )
    finally:
        server.stop()
    assert result["error_count"] == 0, result["errors"]
    assert result["lost_runs"] == []
    assert result["frames"] > 2 * 10 * 15  # two streams at ~20 frames/s for ~15 s at least
    assert result["frame_delay_p99_s"] < 1.0, result
    assert result["memory_growth_pct"] is not None
