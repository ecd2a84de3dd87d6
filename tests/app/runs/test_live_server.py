"""Against one real ``mapwise serve`` process per backend (SQLite and PostgreSQL), shared by
the module's tests:

* the WebSocket stream: a full frame first, deltas at ≤ 20 frames/s, many viewers, a viewer
  that stops reading never slows the run, a late joiner starts from the current state, a
  finished run replays its final frame;
* a killed run worker interrupts only its own run and is replaced.

Servers killed, stopped and restarted, each test with its own: ``test_server_lifecycle.py``.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
from websockets.sync.client import connect

from tests.support.helpers import log_csv, run_body
from tests.support.server import Server

pytestmark = pytest.mark.slow  # a real server, its run workers killed

LIVE_FPS = 20


@pytest.fixture(scope="module")
def server(backend: str, fresh_url) -> Iterator[Server]:  # type: ignore[no-untyped-def]
    srv = Server(fresh_url(backend))
    yield srv
    srv.stop()


def _upload(server: Server, text: str) -> int:
    response = server.post("/api/datasets", files={"file": ("log.csv", text.encode())})
    assert response.status_code == 201, response.text
    return int(response.json()["id"])


def _start(server: Server, body: dict[str, Any]) -> int:
    response = server.post("/api/runs", json=body)
    assert response.status_code == 201, response.text
    return int(response.json()["id"])


class Viewer(threading.Thread):
    """A WebSocket client recording (arrival time, message); with ``hold`` it connects and
    reads nothing until the event is set (a stalled browser tab)."""

    def __init__(self, url: str, *, hold: threading.Event | None = None) -> None:
        super().__init__(daemon=True)
        self.url = url
        self.hold = hold
        self.messages: list[tuple[float, dict[str, Any]]] = []
        self.wall: list[float] = []  # arrival, s since epoch (to compare with emitted_at)
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            with connect(self.url, max_size=None, open_timeout=30) as ws:
                if self.hold is not None:
                    self.hold.wait(timeout=120)
                while True:
                    message = json.loads(ws.recv(timeout=60))
                    self.messages.append((time.monotonic(), message))
                    self.wall.append(time.time())
                    if message["type"] == "status" and message["status"] in (
                        "succeeded",
                        "failed",
                        "cancelled",
                    ):
                        return
        except BaseException as exc:
            self.error = exc

    def of_type(self, kind: str) -> list[tuple[float, dict[str, Any]]]:
        return [(t, m) for t, m in self.messages if m["type"] == kind]

    def wall_of_type(self, kind: str) -> list[tuple[float, dict[str, Any]]]:
        return [
            (w, m) for w, (_, m) in zip(self.wall, self.messages, strict=True) if m["type"] == kind
        ]


def test_stream_full_then_rate_limited_deltas_for_many_viewers(server: Server) -> None:
    dataset = _upload(server, log_csv(6000, seed=31, rate_hz=100.0))  # 60 s of log
    run_id = _start(server, run_body(dataset, pace=20, version_every={"samples": 1000}))  # ~3 s
    url = f"{server.ws_base}/api/runs/{run_id}/stream"
    viewers = [Viewer(url) for _ in range(3)]
    # The stalled viewer reads nothing until the run has succeeded: if the hub ever waited
    # for a viewer, the run could not finish and the wait below would time out.
    release_stalled = threading.Event()
    stalled = Viewer(url, hold=release_stalled)
    for v in [*viewers, stalled]:
        v.start()
    server.wait_run(run_id, ("running",))
    # The late joiner comes once the run has samples behind it (a wall-clock sleep was not
    # enough on a loaded machine: the worker may not have finished its first chunk by then).
    deadline = time.monotonic() + 60
    while server.get(f"/api/runs/{run_id}")["progress"] <= 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    late = Viewer(url)
    late.start()
    for v in [*viewers, late]:
        v.join(timeout=90)
    finished = server.wait_run(run_id, ("succeeded", "failed", "cancelled"), timeout=90)
    assert finished["status"] == "succeeded", finished
    assert stalled.messages == []  # it has read nothing yet: the run never waited for it
    release_stalled.set()
    for v in [*viewers, stalled, late]:
        v.join(timeout=90)
        assert v.error is None, v.error
        assert not v.is_alive()

    for v in [*viewers, stalled, late]:
        assert v.messages[0][1]["type"] == "full"
        assert v.messages[-1][1] == {
            "type": "status",
            "status": "succeeded",
            "error": None,
            "progress": 1.0,
        }
    reader = viewers[0]
    deltas = reader.of_type("delta")
    assert len(deltas) >= 20
    # The rate is the worker's: frames leave it at least 1/20 s apart (arrival times bunch
    # when the machine is busy, so they say nothing about the limit).
    emitted = [m["emitted_at"] for _, m in deltas]
    busiest = max(sum(1 for u in emitted if t <= u < t + 1.0) for t in emitted)
    assert busiest <= LIVE_FPS
    arrived = [t for t, _ in deltas]
    assert len(deltas) / (arrived[-1] - arrived[0]) <= LIVE_FPS + 1
    delays = [t_wall - m["emitted_at"] for t_wall, m in reader.wall_of_type("delta")]
    # A reader that keeps up sees frames promptly (a generous bound: the machine is shared;
    # a hub that held frames back for the stalled viewer would delay them to the run's end).
    assert max(delays) < 10.0
    samples = [m["sample"] for _, m in deltas]
    assert samples == sorted(samples)
    assert samples[-1] == 6000
    first = reader.messages[0][1]
    assert first["run"]["id"] == run_id
    assert first["n_samples"] == 6000
    last_delta = deltas[-1][1]
    final = server.get(f"/api/runs/{run_id}/export", params={"format": "json"})
    assert last_delta["values"] == final["values"]
    assert last_delta["variances"] == final["variance"]

    late_full = late.messages[0][1]
    assert late_full["sample"] > 0  # the current state, not an empty one
    assert late_full["values"] is not None
    assert len(late_full["trajectory"]["points"]) > 0

    done = server.get(f"/api/runs/{run_id}")
    wall = reader.messages[-1][0] - deltas[0][0]
    assert wall > 2.0  # 60 s of log paced at 20x takes ~3 s: the pacing holds
    assert done["status"] == "succeeded"

    with connect(url, max_size=None) as ws:  # a finished run replays its final frame
        full = json.loads(ws.recv(timeout=30))
        status = json.loads(ws.recv(timeout=30))
    assert full["type"] == "full"
    assert full["values"] == final["values"]
    assert full["run"]["status"] == "succeeded"
    assert len(full["trajectory"]["points"]) > 100
    assert status["type"] == "status"
    assert status["status"] == "succeeded"


def test_unknown_run_stream_reports_not_found(server: Server) -> None:
    with connect(f"{server.ws_base}/api/runs/987654/stream") as ws:
        message = json.loads(ws.recv(timeout=30))
    assert message["type"] == "error"
    assert message["error"]["code"] == "not_found"


def test_a_killed_worker_interrupts_only_its_run_and_is_replaced(server: Server) -> None:
    import os
    import signal
    from pathlib import Path

    dataset = _upload(server, log_csv(3000, seed=33, rate_hz=100.0))  # 30 s of log
    running = [_start(server, run_body(dataset, pace=3)) for _ in range(2)]  # both workers
    for run_id in running:
        server.wait_run(run_id, ("running",))
    queued = _start(server, run_body(dataset))
    workers = server.workers()
    assert len(workers) == 2
    victim = workers[0]
    os.kill(victim, signal.SIGSTOP)  # so it cannot move on before it is named and killed
    name = Path(f"/proc/{victim}/comm").read_text().strip()
    os.kill(victim, signal.SIGKILL)  # as the OOM killer would
    killed = int(name.removeprefix("mw-run-"))
    (other,) = [r for r in running if r != killed]
    run = server.wait_run(killed, ("interrupted", "failed", "succeeded"), timeout=60)
    assert run["status"] == "interrupted"
    assert "worker process died (killed by SIGKILL)" in run["error"]
    done = server.wait_run(other, ("interrupted", "failed", "succeeded"), timeout=60)
    assert done["status"] == "succeeded", done  # the other worker's run never noticed
    assert (done["attempt"], done["lost_attempts"]) == (1, 0)
    assert server.wait_run(queued, ("succeeded", "failed"))["status"] == "succeeded"
    workers = server.workers()
    assert len(workers) == 2
    assert victim not in workers  # replaced by a new worker
    expected = server.get(f"/api/runs/{queued}/export", params={"format": "json"})
    assert server.post(f"/api/runs/{killed}/resume").status_code == 200
    assert server.wait_run(killed, ("succeeded", "failed"))["status"] == "succeeded"
    got = server.get(f"/api/runs/{killed}/export", params={"format": "json"})
    assert got["values"] == expected["values"]
