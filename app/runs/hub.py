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

from app.domain import FINISHED, RunStatus
from app.runs.frames import StartMessage, StatusFrame, TickMessage, parse_message

MAX_POINTS = 4000
VIEWER_QUEUE = 8


@dataclass
class LiveState:
    run_id: int
    status: str = RunStatus.RUNNING
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
    roles: dict[str, str] = field(default_factory=dict)
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
        self.frames_in += 1
        parsed = parse_message(message)
        if isinstance(parsed, StartMessage):
            self.live[parsed.run_id] = LiveState(
                run_id=parsed.run_id,
                axes=parsed.axes,
                n_samples=parsed.n_samples,
                units=dict(parsed.units),
                roles=dict(parsed.roles),
            )
            self._broadcast_resync(parsed.run_id)
        elif isinstance(parsed, TickMessage):
            self._tick(parsed)
        elif isinstance(parsed, StatusFrame):
            self._status(parsed)

    def _tick(self, tick: TickMessage) -> None:
        run_id = tick.run_id
        state = self.live.get(run_id)
        if state is None:
            state = self.live[run_id] = LiveState(run_id=run_id)
        gap = state.seq and tick.seq != state.seq + 1
        state.seq = tick.seq
        state.sample, state.n_samples, state.progress = tick.sample, tick.n_samples, tick.progress
        state.values, state.variances, state.visits = tick.values, tick.variances, tick.visits
        state.active_cell, state.metrics = tick.active_cell, tick.metrics
        state.rejected = tick.rejected
        state.add_points(tick.trajectory, tick.series)
        if gap:
            self._broadcast_resync(run_id)
            return
        viewers = self.viewers.get(run_id, ())
        if viewers:
            text = _encode(tick.delta().to_json())  # encoded once for every viewer
            for viewer in viewers:
                viewer.offer(text)
                self.frames_out += 1

    def _status(self, frame: StatusFrame) -> None:
        state = self.live.get(frame.run_id)
        if state is not None:
            state.status, state.error = frame.status, frame.error
        text = _encode(frame.to_json())
        for viewer in self.viewers.get(frame.run_id, ()):
            viewer.offer(text)
        if frame.status in FINISHED:
            self.live.pop(frame.run_id, None)

    def _broadcast_resync(self, run_id: int) -> None:
        for viewer in self.viewers.get(run_id, ()):
            viewer.resync()


def _encode(frame: dict[str, Any]) -> str:
    return json.dumps(frame, separators=(",", ":"))
