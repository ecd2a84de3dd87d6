"""The live hub: fans worker ticks out to any number of WebSocket viewers per run.

Runs the event loop's side only. A worker never waits for the hub (its ticks arrive through a
queue it writes without blocking) and the hub never waits for a viewer: each viewer has a
small bounded queue; when it is full the viewer's pending deltas are dropped and it is marked
for a fresh ``full`` frame, which it gets as soon as it reads again. The hub keeps the current
state of every executing run (map, variances, visits, trajectory and series so far, bounded
by halving their resolution) so late joiners start from a full frame. A tick without the map
(``values`` is ``None``: the worker sends the map only within its cells-per-second budget)
leaves the last map in place.

Viewers are admitted within limits (per run, per client address, in all): past one,
:meth:`LiveHub.subscribe` raises :class:`ViewerLimitError` saying which. A viewer's memory is
its queue of at most ``VIEWER_QUEUE`` messages. Each viewer reads one encoding (``json`` or
``binary``, :mod:`app.runs.frame_encoding`); a frame is encoded once per encoding that a
viewer waiting for it reads, lazily, and every such viewer shares the same ``str`` or
``bytes`` (:attr:`LiveHub.encodes` counts the encodings done). The hub knows which token each
viewer came with, so a revoked token's viewers can be closed (:meth:`LiveHub.close_tokens`).
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any

from app.domain import FINISHED, RunStatus
from app.runs.frame_encoding import ENCODINGS, Encoding, encode
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


Message = str | bytes  # one encoded frame, as a WebSocket text or binary message


@dataclass(slots=True)
class EncodedFull:
    """A run's full frame, built once for every viewer joining at the same point and encoded
    at most once per encoding (:meth:`messages`): ``key`` says which state it shows,
    ``status_doc`` (the status frame) follows it when the run is finished."""

    key: tuple[Any, ...]
    doc: dict[str, Any]
    status_doc: dict[str, Any] | None
    status: str
    encoded: dict[str, tuple[Message, Message | None]] = field(default_factory=dict)

    def messages(self, hub: LiveHub, encoding: Encoding) -> tuple[Message, Message | None]:
        """The full frame and the status frame (or ``None``) in ``encoding``."""
        pair = self.encoded.get(encoding)
        if pair is None:
            status = None if self.status_doc is None else hub.encode(self.status_doc, encoding)
            pair = self.encoded[encoding] = (hub.encode(self.doc, encoding), status)
        return pair


class ViewerLimitError(Exception):
    """A viewer over one of the hub's limits; the message says which."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


class Viewer:
    """One WebSocket viewer: a bounded queue and a flag asking for a full frame; ``closed``
    is set when the hub ends the viewer (its token was revoked), ``close_reason`` says why."""

    def __init__(
        self,
        run_id: int,
        client: str | None = None,
        token_id: int | None = None,
        encoding: Encoding = "json",
    ) -> None:
        self.run_id = run_id
        self.client = client
        self.token_id = token_id
        self.encoding = encoding
        self.queue: asyncio.Queue[Message] = asyncio.Queue(maxsize=VIEWER_QUEUE)
        self.needs_full = False
        self.wakeup = asyncio.Event()
        self.closed = asyncio.Event()
        self.close_reason = ""

    def close(self, reason: str) -> None:
        self.close_reason = reason
        self._drain()
        self.closed.set()
        self.wakeup.set()

    @property
    def waiting(self) -> bool:
        """Whether the next delta would be queued (not dropped for a due full frame)."""
        return not self.needs_full and not self.closed.is_set()

    def offer(self, message: Message) -> None:
        """Queue an encoded message; a full queue drops everything pending for a full frame."""
        if self.needs_full or self.closed.is_set():
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

    async def next(self) -> Message | None:
        """The next encoded message to send, or ``None`` when a full frame is due; waits
        forever once the viewer is closed (whoever serves it watches ``closed``)."""
        while True:
            if self.closed.is_set():
                await asyncio.Future()  # never completes: the caller is cancelled
            if self.needs_full:
                self.needs_full = False
                return None
            if not self.queue.empty():
                return self.queue.get_nowait()
            self.wakeup.clear()
            await self.wakeup.wait()


class LiveHub:
    def __init__(
        self,
        *,
        max_per_run: int = 100,
        max_per_client: int = 200,
        max_total: int = 500,
    ) -> None:
        self.live: dict[int, LiveState] = {}
        self.viewers: dict[int, set[Viewer]] = {}
        self.by_client: dict[str, int] = {}
        self.by_token: dict[int, set[Viewer]] = {}
        self.total = 0
        self.max_per_run = max_per_run
        self.max_per_client = max_per_client
        self.max_total = max_total
        self.frames_in = 0
        self.frames_out = 0
        self.refused = 0
        # Frames encoded, per encoding: one per frame and encoding in use, whatever the number
        # of viewers (the tests count them).
        self.encodes: dict[str, int] = dict.fromkeys(ENCODINGS, 0)
        # One encoded full frame per watched run: a hundred joiners cost one encoding, not a
        # hundred (the JSON of a full frame is the costliest thing the event loop does).
        self.full_frames: dict[int, EncodedFull] = {}
        self._full_locks: dict[int, asyncio.Lock] = {}

    def full_lock(self, run_id: int) -> asyncio.Lock:
        """Held while a run's full frame is built, so concurrent joiners build it once."""
        lock = self._full_locks.get(run_id)
        if lock is None:
            lock = self._full_locks[run_id] = asyncio.Lock()
        return lock

    def encode(self, doc: dict[str, Any], encoding: Encoding) -> Message:
        """``doc`` as a message in ``encoding``, counted in :attr:`encodes`."""
        self.encodes[encoding] += 1
        return encode(doc, encoding)

    def keep_full(self, run_id: int, full: EncodedFull) -> None:
        if run_id in self.viewers:
            self.full_frames[run_id] = full

    def subscribe(
        self,
        run_id: int,
        *,
        client: str | None = None,
        token_id: int | None = None,
        encoding: Encoding = "json",
    ) -> Viewer:
        """A new viewer of ``run_id``; :class:`ViewerLimitError` past a limit.

        Checked and counted without an ``await`` in between, so concurrent handshakes can
        never overshoot a limit."""
        if self.total >= self.max_total:
            self.refused += 1
            raise ViewerLimitError(f"the server has its maximum of {self.max_total} live viewers")
        if len(self.viewers.get(run_id, ())) >= self.max_per_run:
            self.refused += 1
            raise ViewerLimitError(f"run {run_id} has its maximum of {self.max_per_run} viewers")
        if client is not None and self.by_client.get(client, 0) >= self.max_per_client:
            self.refused += 1
            raise ViewerLimitError(
                f"this client has its maximum of {self.max_per_client} live viewers"
            )
        viewer = Viewer(run_id, client, token_id, encoding)
        self.viewers.setdefault(run_id, set()).add(viewer)
        if client is not None:
            self.by_client[client] = self.by_client.get(client, 0) + 1
        if token_id is not None:
            self.by_token.setdefault(token_id, set()).add(viewer)
        self.total += 1
        return viewer

    def unsubscribe(self, viewer: Viewer) -> None:
        viewers = self.viewers.get(viewer.run_id)
        if viewers is None or viewer not in viewers:
            return
        viewers.discard(viewer)
        if not viewers:
            del self.viewers[viewer.run_id]
            self.full_frames.pop(viewer.run_id, None)
            self._full_locks.pop(viewer.run_id, None)
        self.total -= 1
        if viewer.client is not None:
            left = self.by_client[viewer.client] - 1
            if left:
                self.by_client[viewer.client] = left
            else:
                del self.by_client[viewer.client]
        if viewer.token_id is not None:
            mine = self.by_token[viewer.token_id]
            mine.discard(viewer)
            if not mine:
                del self.by_token[viewer.token_id]

    def token_ids(self) -> list[int]:
        """The tokens that viewers are connected with now."""
        return list(self.by_token)

    def close_tokens(self, token_ids: set[int] | list[int], reason: str) -> int:
        """Close every viewer connected with one of ``token_ids``; how many were closed."""
        closed = 0
        for token_id in token_ids:
            for viewer in self.by_token.get(token_id, set()):
                if not viewer.closed.is_set():
                    viewer.close(reason)
                    closed += 1
        return closed

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
        if tick.values is not None:  # a tick without the map (its byte budget) keeps the last
            state.values, state.variances, state.visits = tick.values, tick.variances, tick.visits
        state.active_cell, state.metrics = tick.active_cell, tick.metrics
        state.rejected = tick.rejected
        state.add_points(tick.trajectory, tick.series)
        if gap:
            self._broadcast_resync(run_id)
            return
        self.frames_out += self._fan_out(run_id, tick.delta().to_json())

    def _status(self, frame: StatusFrame) -> None:
        state = self.live.get(frame.run_id)
        if state is not None:
            state.status, state.error = frame.status, frame.error
        self._fan_out(frame.run_id, frame.to_json())
        if frame.status in FINISHED:
            self.live.pop(frame.run_id, None)

    def _fan_out(self, run_id: int, doc: dict[str, Any]) -> int:
        """Offer ``doc`` to the run's viewers, encoded once per encoding that a waiting viewer
        reads (a viewer due for a full frame would drop it: it costs no encoding); returns
        how many viewers it was offered to."""
        encoded: dict[str, Message] = {}
        offered = 0
        for viewer in self.viewers.get(run_id, ()):
            if not viewer.waiting:
                continue
            message = encoded.get(viewer.encoding)
            if message is None:
                message = encoded[viewer.encoding] = self.encode(doc, viewer.encoding)
            viewer.offer(message)
            offered += 1
        return offered

    def _broadcast_resync(self, run_id: int) -> None:
        for viewer in self.viewers.get(run_id, ()):
            viewer.resync()
