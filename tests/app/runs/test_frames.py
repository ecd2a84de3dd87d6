"""The live stream's JSON, pinned: the keys of every message a worker publishes and of every
frame a viewer receives (the dashboard and external scripts read them; README "Live
stream"). A run is executed in this process to collect its worker messages, which then go
through a hub to a viewer; the finished run's full frame comes over the WebSocket."""

from __future__ import annotations

import asyncio
import json
from typing import Any

from fastapi.testclient import TestClient

from app.db.engine import Database
from app.runs.frames import DeltaFrame, ErrorFrame, FullFrame, StatusFrame, TickMessage
from app.runs.hub import LiveHub
from app.runs.worker import WorkerContext, execute_run
from app.services.run_plan import RunRequest
from app.services.runs import RunService
from tests.support.helpers import log_csv, run_body, service_settings, upload_ok

STATUS_MESSAGE = {"kind", "run_id", "status", "error", "progress"}
START_MESSAGE = {"kind", "run_id", "axes", "n_samples", "trajectory_channels", "units", "roles"}
MAP_KEYS = {"values", "variances", "visits", "active_cell", "trajectory", "series", "metrics"}
TICK_MESSAGE = (
    {"kind", "run_id", "seq", "sample", "n_samples", "progress", "time_s"}
    | {
        "emitted_at",
        "rejected",
    }
    | MAP_KEYS
)
DELTA = {"type", "sample", "progress", "time_s", "emitted_at", "rejected"} | MAP_KEYS
FULL = {"type", "run", "axes", "rejected", "sample", "n_samples"} | MAP_KEYS
STATUS = {"type", "status", "error", "progress"}


class _Later:
    """A submitter that keeps the run queued: the test executes it itself."""

    def submit(self, run_id: int) -> None:
        pass

    def deliver_local(self, message: dict[str, Any]) -> None:
        pass


def _worker_messages(client: TestClient, url: str) -> tuple[int, list[dict[str, Any]]]:
    dataset = upload_ok(client, log_csv(800, seed=70))
    db = Database(url)
    try:
        runs = RunService(db, service_settings(url), _Later())
        run = runs.create(RunRequest.model_validate(run_body(dataset["id"])))
    finally:
        db.dispose()
    messages: list[dict[str, Any]] = []
    status = execute_run(run.id, WorkerContext(database_url=url), messages.append)
    assert status == "succeeded"
    return run.id, json.loads(json.dumps(messages))  # what crosses a process queue


def test_worker_messages_and_viewer_frames_keep_their_keys(
    client: TestClient, database_url: str
) -> None:
    run_id, messages = _worker_messages(client, database_url)
    kinds = [m["kind"] for m in messages]
    assert kinds[:2] == ["status", "start"]
    assert kinds[-1] == "status"
    assert set(kinds[2:-1]) == {"tick"}
    assert [m["status"] for m in messages if m["kind"] == "status"] == ["running", "succeeded"]
    for message in messages:
        expected = {"status": STATUS_MESSAGE, "start": START_MESSAGE, "tick": TICK_MESSAGE}
        assert set(message) == expected[message["kind"]], message["kind"]
    tick = next(m for m in messages if m["kind"] == "tick")
    assert set(tick["trajectory"]) == {"time", "points"}
    assert all(set(line) == {"time", "values"} for line in tick["series"].values())
    start = messages[1]
    assert set(start["roles"]) == set(start["units"]) == set(tick["series"])
    assert start["roles"]["u1"] == "input"
    assert start["roles"]["measured"] == "measured"
    assert start["roles"]["prediction"] == "output"

    async def through_a_hub() -> list[dict[str, Any]]:
        hub = LiveHub()
        viewer = hub.subscribe(run_id)
        received = []
        for message in messages:
            hub.handle(message)
            if message["kind"] == "start":
                viewer.reset()  # the full frame it asked for is the stream route's to send
                continue
            text = await viewer.next()
            assert text is not None
            received.append(json.loads(text))
        return received

    frames = asyncio.run(through_a_hub())
    assert [f["type"] for f in frames] == ["status"] + ["delta"] * (len(frames) - 2) + ["status"]
    for frame in frames:
        assert set(frame) == (DELTA if frame["type"] == "delta" else STATUS)

    with client.websocket_connect(f"/api/runs/{run_id}/stream") as ws:
        full, status = ws.receive_json(), ws.receive_json()
    assert set(full) == FULL
    assert full["run"]["id"] == run_id
    assert all(set(line) == {"unit", "role", "time", "values"} for line in full["series"].values())
    assert full["series"]["u1"]["role"] == "input"
    assert set(status) == STATUS
    assert status["status"] == "succeeded"


def test_frame_classes_build_the_documented_documents() -> None:
    tick = TickMessage(run_id=3, seq=1, sample=10, n_samples=20, progress=0.5)
    assert set(tick.to_json()) == TICK_MESSAGE
    assert TickMessage.from_json(tick.to_json()) == tick
    assert set(DeltaFrame(tick).to_json()) == DELTA
    status = StatusFrame(run_id=3, status="failed", error="boom", progress=0.5)
    assert status.to_message() == {
        "kind": "status",
        "run_id": 3,
        "status": "failed",
        "error": "boom",
        "progress": 0.5,
    }
    assert status.to_json() == {
        "type": "status",
        "status": "failed",
        "error": "boom",
        "progress": 0.5,
    }
    full = FullFrame(
        run={"id": 3, "status": "failed", "error": "boom", "progress": 0.5},
        axes=None,
        values=None,
        variances=None,
        visits=None,
        active_cell=None,
        trajectory={"time": [], "points": []},
        series={},
        metrics={},
        rejected={},
        sample=10,
        n_samples=20,
    )
    assert set(full.to_json()) == FULL
    assert full.status() == status
    assert ErrorFrame({"code": "not_found"}).to_json() == {
        "type": "error",
        "error": {"code": "not_found"},
    }
