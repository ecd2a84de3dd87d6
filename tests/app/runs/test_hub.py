"""The live hub on its own event loop: a viewer that does not read never blocks the others
(its deltas are dropped and it gets a full frame), late state is kept, gaps force a resync."""

from __future__ import annotations

import asyncio
import json

from app.runs.frame_encoding import decode_binary
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


def test_each_frame_is_encoded_once_per_encoding_for_a_hundred_viewers() -> None:
    async def scenario() -> None:
        hub = LiveHub()
        viewers = [
            hub.subscribe(4, encoding="binary" if k % 2 else "json") for k in range(hub.max_per_run)
        ]
        for viewer in viewers:
            viewer.reset()
        for k in range(1, 21):
            hub.handle(_tick(4, k, 10 * k))
            messages = [await viewer.next() for viewer in viewers]
            json_text = messages[0]
            binary = messages[1]
            assert isinstance(json_text, str)
            assert isinstance(binary, bytes)
            # Every viewer of an encoding holds the very same object: no copy, no re-encoding.
            assert all(
                m is (binary if v.encoding == "binary" else json_text)
                for v, m in zip(viewers, messages, strict=True)
            )
            assert json.loads(json_text)["sample"] == decode_binary(binary)["sample"] == 10 * k
        assert hub.encodes == {"json": 20, "binary": 20}

        # Nobody asked for binary: it is never encoded.
        json_only = LiveHub()
        watchers = [json_only.subscribe(5) for _ in range(10)]
        for viewer in watchers:
            viewer.reset()
        for k in range(1, 11):
            json_only.handle(_tick(5, k, k))
            texts = [await viewer.next() for viewer in watchers]
            assert isinstance(texts[0], str)
            assert all(text is texts[0] for text in texts)
        assert json_only.encodes == {"json": 10, "binary": 0}

    asyncio.run(scenario())


def test_a_viewer_stalled_for_10_s_catches_up_with_one_full_frame_and_loses_nothing_else() -> None:
    """20 frames/s for 10 s while one viewer reads nothing: the run never waits for it, the
    frames it cannot queue cost no encoding, it is then due exactly one full frame (the hub's
    state holds every point it missed) and every later frame reaches it in order."""

    async def scenario() -> None:
        hub = LiveHub()
        reader = hub.subscribe(6, encoding="json")
        stalled = hub.subscribe(6, encoding="binary")  # the only binary viewer
        hub.handle({"kind": "start", "run_id": 6, "axes": None, "n_samples": 1000, "units": {}})
        reader.reset()
        stalled.reset()
        stall_ticks = 200  # 10 s at 20 frames/s
        for k in range(1, stall_ticks + 1):
            hub.handle(_tick(6, k, k))
            assert json.loads(await reader.next())["sample"] == k
        # It filled its queue once; after that, nothing was encoded for it.
        assert hub.encodes["binary"] == VIEWER_QUEUE + 1
        assert await stalled.next() is None  # one full frame is due
        state = hub.state(6)
        assert state is not None
        assert len(state.trajectory_time) == stall_ticks  # the full frame misses nothing
        stalled.reset()  # the route sent it the full frame
        after = list(range(stall_ticks + 1, stall_ticks + 21))
        received = []
        for k in after:
            hub.handle(_tick(6, k, k))
            received.append(decode_binary(await stalled.next())["sample"])
            assert json.loads(await reader.next())["sample"] == k
        assert received == after
        hub.handle({"kind": "status", "run_id": 6, "status": "succeeded", "error": None})
        assert decode_binary(await stalled.next())["status"] == "succeeded"
        assert stalled.queue.empty()

    asyncio.run(scenario())
