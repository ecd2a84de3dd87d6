"""The live hub: fans worker ticks out to any number of WebSocket viewers per run.

Runs the event loop's side only. A worker never waits for the hub (its ticks arrive through a
queue it writes without blocking) and the hub never waits for a viewer: each viewer has a
small bounded queue; when it is full the viewer's pending deltas are dropped and it is marked
for a fresh ``full`` frame, which it gets as soon as it reads again. The hub keeps the current
state of every executing run (map, variances, visits, trajectory and series so far, bounded
by halving their resolution) so late joiners start from a full frame.
"""

from __future__ import annotations

import asyncio
import json
from dataclasses import dataclass, field
from typing import Any

MAX_POINTS = 4000
VIEWER_QUEUE = 8
TERMINAL = ("succeeded", "failed", "cancelled", "interrupted")


@dataclass
class LiveState:
    run_id: int
    status: str = "running"
    error: str | None = None
    progress: float = 0.0
    sample: int = 0
    n_samples: int = 0
    axes: list[dict[str, Any]] | None = None
    values: Any = None
    variances: Any = None
    visits: Any = None
    active_cell: list[int] | None = None
    metrics: dict[str, Any] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    trajectory_time: list[float | None] = field(default_factory=list)
    trajectory_points: list[list[float]] = field(default_factory=list)
    series: dict[str, dict[str, list[Any]]] = field(default_factory=dict)
    seq: int = 0

    def add_points(self, trajectory: dict[str, Any], series: dict[str, Any]) -> None:
        self.trajectory_time += trajectory.get("time", [])
        self.trajectory_points += trajectory.get("points", [])
        if len(self.trajectory_time) > MAX_POINTS:
            self.trajectory_time = self.trajectory_time[::2]
            self.trajectory_points = self.trajectory_points[::2]
        for name, line in series.items():
            mine = self.series.setdefault(name, {"time": [], "values": []})
            mine["time"] += line["time"]
            mine["values"] += line["values"]
            if len(mine["time"]) > MAX_POINTS:
                mine["time"] = mine["time"][::2]
                mine["values"] = mine["values"][::2]


class Viewer:
    """One WebSocket viewer: a bounded queue and a flag asking for a full frame."""

    def __init__(self, run_id: int) -> None:
        self.run_id = run_id
        self.queue: asyncio.Queue[str] = asyncio.Queue(maxsize=VIEWER_QUEUE)
        self.needs_full = False
        self.wakeup = asyncio.Event()

    def offer(self, message: str) -> None:
        """Queue an encoded message; a full queue drops everything pending for a full frame."""
        if self.needs_full:
            return
        try:
            self.queue.put_nowait(message)
        except asyncio.QueueFull:
            self._drain()
            self.needs_full = True
        self.wakeup.set()

    def resync(self) -> None:
        self._drain()
        self.needs_full = True
        self.wakeup.set()

    def reset(self) -> None:
        """Forget pending messages: the viewer was just sent a full frame."""
        self._drain()
        self.needs_full = False

    def _drain(self) -> None:
        while not self.queue.empty():
            self.queue.get_nowait()

    async def next(self) -> str | None:
        """The next encoded message to send, or ``None`` when a full frame is due."""
        while True:
            if self.needs_full:
                self.needs_full = False
                return None
            if not self.queue.empty():
                return self.queue.get_nowait()
            self.wakeup.clear()
            await self.wakeup.wait()


class LiveHub:
    def __init__(self) -> None:
        self.live: dict[int, LiveState] = {}
        self.viewers: dict[int, set[Viewer]] = {}
        self.frames_in = 0
        self.frames_out = 0

    def subscribe(self, run_id: int) -> Viewer:
        viewer = Viewer(run_id)
        self.viewers.setdefault(run_id, set()).add(viewer)
        return viewer

    def unsubscribe(self, viewer: Viewer) -> None:
        viewers = self.viewers.get(viewer.run_id)
        if viewers is not None:
            viewers.discard(viewer)
            if not viewers:
                del self.viewers[viewer.run_id]

    def state(self, run_id: int) -> LiveState | None:
        return self.live.get(run_id)

    def handle(self, message: dict[str, Any]) -> None:
        """A worker message (``start``, ``tick`` or ``status``); called on the event loop."""
        kind, run_id = message.get("kind"), int(message["run_id"])
        self.frames_in += 1
        if kind == "start":
            self.live[run_id] = LiveState(
                run_id=run_id,
                axes=message.get("axes"),
                n_samples=int(message.get("n_samples", 0)),
                units=dict(message.get("units", {})),
            )
            self._broadcast_resync(run_id)
        elif kind == "tick":
            self._tick(run_id, message)
        elif kind == "status":
            self._status(run_id, message)

    def _tick(self, run_id: int, message: dict[str, Any]) -> None:
        state = self.live.get(run_id)
        if state is None:
            state = self.live[run_id] = LiveState(run_id=run_id)
        gap = state.seq and message["seq"] != state.seq + 1
        state.seq = message["seq"]
        for key in (
            "sample",
            "n_samples",
            "progress",
            "values",
            "variances",
            "visits",
            "active_cell",
            "metrics",
            "rejected",
        ):
            setattr(state, key, message.get(key))
        state.add_points(message.get("trajectory", {}), message.get("series", {}))
        if gap:
            self._broadcast_resync(run_id)
            return
        delta = {
            "type": "delta",
            "sample": message["sample"],
            "progress": message["progress"],
            "time_s": message.get("time_s"),
            "emitted_at": message.get("emitted_at"),
            "values": message.get("values"),
            "variances": message.get("variances"),
            "visits": message.get("visits"),
            "active_cell": message.get("active_cell"),
            "trajectory": message.get("trajectory", {"time": [], "points": []}),
            "series": message.get("series", {}),
            "metrics": message.get("metrics", {}),
            "rejected": message.get("rejected", {}),
        }
        viewers = self.viewers.get(run_id, ())
        if viewers:
            text = json.dumps(delta, separators=(",", ":"))  # encoded once for every viewer
            for viewer in viewers:
                viewer.offer(text)
                self.frames_out += 1

    def _status(self, run_id: int, message: dict[str, Any]) -> None:
        status = message["status"]
        state = self.live.get(run_id)
        if state is not None:
            state.status, state.error = status, message.get("error")
        out = {
            "type": "status",
            "status": status,
            "error": message.get("error"),
            "progress": message.get("progress", 0.0),
        }
        text = json.dumps(out, separators=(",", ":"))
        for viewer in self.viewers.get(run_id, ()):
            viewer.offer(text)
        if status in TERMINAL:
            self.live.pop(run_id, None)

    def _broadcast_resync(self, run_id: int) -> None:
        for viewer in self.viewers.get(run_id, ()):
            viewer.resync()
