"""The live hub on its own event loop: a viewer that does not read never blocks the others
(its deltas are dropped and it gets a full frame), late state is kept, gaps force a resync."""

from __future__ import annotations

import asyncio
import json

from app.runs.hub import MAX_POINTS, VIEWER_QUEUE, LiveHub


def _tick(run_id: int, seq: int, sample: int) -> dict:
    return {
        "kind": "tick",
        "run_id": run_id,
        "seq": seq,
        "sample": sample,
        "n_samples": 1000,
        "progress": sample / 1000,
        "values": [[float(seq)]],
        "trajectory": {"time": [float(sample)], "points": [[1.0, 2.0]]},
        "series": {"residual": {"time": [float(sample)], "values": [0.5]}},
        "metrics": {},
    }


def test_slow_viewer_is_dropped_to_a_full_frame_fast_viewer_gets_every_delta() -> None:
    async def scenario() -> None:
        hub = LiveHub()
        fast, slow = hub.subscribe(1), hub.subscribe(1)
        hub.handle({"kind": "start", "run_id": 1, "axes": None, "n_samples": 1000, "units": {}})
        fast.reset()
        slow.reset()
        received = []
        for k in range(1, 51):
            hub.handle(_tick(1, k, 10 * k))
            received.append(json.loads(await fast.next()))  # the fast viewer reads each delta
        assert [m["sample"] for m in received] == [10 * k for k in range(1, 51)]
        assert slow.queue.qsize() <= VIEWER_QUEUE
        assert await slow.next() is None  # a full frame is due, not 50 stale deltas
        state = hub.state(1)
        assert state is not None
        assert state.sample == 500
        assert len(state.trajectory_time) == 50

    asyncio.run(scenario())


def test_sequence_gap_resyncs_and_terminal_status_drops_live_state() -> None:
    async def scenario() -> None:
        hub = LiveHub()
        viewer = hub.subscribe(2)
        hub.handle(_tick(2, 1, 1))
        assert json.loads(await viewer.next())["type"] == "delta"
        hub.handle(_tick(2, 3, 3))  # tick 2 was lost on the way
        assert await viewer.next() is None
        hub.handle({"kind": "status", "run_id": 2, "status": "succeeded", "error": None})
        assert json.loads(await viewer.next())["type"] == "status"
        assert hub.state(2) is None

    asyncio.run(scenario())


def test_history_is_bounded() -> None:
    hub = LiveHub()
    for k in range(1, 3 * MAX_POINTS):
        hub.handle(_tick(3, k, k))
    state = hub.state(3)
    assert state is not None
    assert len(state.trajectory_time) <= MAX_POINTS
    assert len(state.series["residual"]["values"]) <= MAX_POINTS
