"""``WS /api/runs/{id}/stream?encoding=binary`` through the real app: an unknown encoding is
refused naming ``encoding``; the binary frames of a real run decode to its JSON frames (float32
precision); late joiners of a live run share one full frame per encoding."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Iterator
from contextlib import ExitStack
from typing import Any

import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from app.api import create_app
from app.db.engine import Database
from app.runs.frame_encoding import decode_binary
from app.runs.hub import LiveHub
from app.runs.worker import WorkerContext, execute_run
from app.services.run_plan import RunRequest
from app.services.runs import RunService
from tests.app.runs.test_frame_encoding import same_frame
from tests.support.helpers import log_csv, run_body, service_settings, upload_ok


@pytest.fixture(scope="module")
def app_url(fresh_url) -> str:  # type: ignore[no-untyped-def]
    return str(fresh_url("sqlite"))  # the encoding does not depend on the database


@pytest.fixture(scope="module")
def client(app_url: str) -> Iterator[TestClient]:
    """The app without run execution: runs stay queued unless a test executes them."""
    with TestClient(create_app(service_settings(app_url), execute_runs=False)) as c:
        yield c


class _Later:
    """A submitter that keeps the run queued: the test executes it, or plays its worker."""

    def submit(self, run_id: int) -> None:
        pass

    def deliver_local(self, message: dict[str, Any]) -> None:
        pass


def _queued_run(client: TestClient, url: str, seed: int) -> int:
    dataset = upload_ok(client, log_csv(800, seed=seed))
    db = Database(url)
    try:
        runs = RunService(db, service_settings(url), _Later())
        return runs.create(RunRequest.model_validate(run_body(dataset["id"]))).id
    finally:
        db.dispose()


def test_an_unknown_encoding_is_refused_naming_it(client: TestClient) -> None:
    with (
        pytest.raises(WebSocketDisconnect) as closed,
        client.websocket_connect("/api/runs/1/stream?encoding=msgpack") as ws,
    ):
        ws.receive()
    assert closed.value.code == 1008
    assert "encoding" in closed.value.reason
    assert "msgpack" in closed.value.reason
    # json (the default) and binary are both accepted: no such run, an error frame in each
    with client.websocket_connect("/api/runs/987654/stream?encoding=json") as ws:
        assert json.loads(ws.receive_text())["error"]["code"] == "not_found"
    with client.websocket_connect("/api/runs/987654/stream?encoding=binary") as ws:
        assert decode_binary(ws.receive_bytes())["error"]["code"] == "not_found"


def test_binary_frames_of_a_real_run_decode_to_its_json_frames(
    client: TestClient, app_url: str
) -> None:
    run_id = _queued_run(client, app_url, seed=71)
    messages: list[dict[str, Any]] = []
    assert execute_run(run_id, WorkerContext(database_url=app_url), messages.append) == "succeeded"
    messages = json.loads(json.dumps(messages))  # what crosses a process queue

    async def through_a_hub() -> list[tuple[str, bytes]]:
        hub = LiveHub()
        as_json, as_binary = hub.subscribe(run_id), hub.subscribe(run_id, encoding="binary")
        pairs = []
        for message in messages:
            hub.handle(message)
            if message["kind"] == "start":
                as_json.reset()
                as_binary.reset()
                continue
            pairs.append((await as_json.next(), await as_binary.next()))
        return pairs

    pairs = asyncio.run(through_a_hub())
    assert len(pairs) > 3
    for text, data in pairs:
        assert isinstance(text, str)
        assert isinstance(data, bytes)
        same_frame(decode_binary(data), json.loads(text))
    deltas = [json.loads(text) for text, _ in pairs if json.loads(text)["type"] == "delta"]
    assert any(d["values"] is not None for d in deltas)  # the maps went through as blocks

    # The finished run's full frame and status, over the socket, in both encodings.
    with client.websocket_connect(f"/api/runs/{run_id}/stream") as ws:
        full, status = ws.receive_json(), ws.receive_json()
    with client.websocket_connect(f"/api/runs/{run_id}/stream?encoding=binary") as ws:
        full_b, status_b = decode_binary(ws.receive_bytes()), decode_binary(ws.receive_bytes())
    assert full["type"] == "full"
    assert full["values"] is not None
    assert len(full["series"]) > 0
    same_frame(full_b, full)
    assert status_b == status


def test_late_joiners_of_a_live_run_share_one_full_frame_per_encoding(
    client: TestClient, app_url: str
) -> None:
    run_id = _queued_run(client, app_url, seed=72)
    hub = client.app.state.services.hub  # type: ignore[attr-defined]
    # The run's live state as its worker would publish it (no viewer yet: nothing to wake).
    hub.handle({"kind": "start", "run_id": run_id, "axes": None, "n_samples": 800, "units": {}})
    for seq in range(1, 6):
        hub.handle(
            {
                "kind": "tick",
                "run_id": run_id,
                "seq": seq,
                "sample": 100 * seq,
                "n_samples": 800,
                "progress": seq / 8,
                "values": [[float(seq), None], [0.5, 2.25]],
                "variances": [[1.0, 2.0], [3.0, 4.0]],
                "visits": [[1, 0], [2, 3]],
                "trajectory": {"time": [seq * 0.1], "points": [[1.0, 2.0]]},
                "series": {"u1": {"time": [seq * 0.1], "values": [float(seq)]}},
                "metrics": {"rmse": 0.1},
            }
        )
    before = dict(hub.encodes)
    url = f"/api/runs/{run_id}/stream"
    with ExitStack() as stack:
        texts = [stack.enter_context(client.websocket_connect(url)) for _ in range(4)]
        binaries = [
            stack.enter_context(client.websocket_connect(f"{url}?encoding=binary"))
            for _ in range(4)
        ]
        got_text = [ws.receive_text() for ws in texts]
        got_bytes = [ws.receive_bytes() for ws in binaries]
    assert len(set(got_text)) == 1
    assert len(set(got_bytes)) == 1
    assert {k: hub.encodes[k] - before[k] for k in before} == {"json": 1, "binary": 1}
    full = json.loads(got_text[0])
    assert full["type"] == "full"
    assert full["sample"] == 500
    assert len(full["trajectory"]["points"]) == 5
    same_frame(decode_binary(got_bytes[0]), full)
