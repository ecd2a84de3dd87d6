"""How late the event loop runs its callbacks: the measure of "the event loop only moves
bytes". A task sleeps ``interval_s`` again and again; each wake-up later than asked is lag
(a handler computing on the loop, a blocking call). Health reports the worst lag of the last
30 s, so a check (or a test) sees whether anything stalls the server.

Each wake-up also reads the CPU time of the loop's own thread (``time.thread_time``): what
the loop spends running callbacks, not waiting in ``epoll`` for the network. Its growth over
a wall-clock interval is the share of that interval the loop was busy
(``scripts/bench_service.py`` reports it for the live phase, docs/benchmarks.md#service).

The samples are written on the event loop and read by ``/api/health``, a sync route that
runs in the thread pool: a lock keeps the reader from iterating a deque being trimmed
("deque mutated during iteration" was a 500 from health)."""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections import deque


class LoopLag:
    def __init__(self, *, interval_s: float = 0.02, window_s: float = 30.0) -> None:
        self.interval_s = interval_s
        self.window_s = window_s
        self._samples: deque[tuple[float, float]] = deque()
        self._task: asyncio.Task[None] | None = None
        self._lock = threading.Lock()
        self._cpu_s = 0.0

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._run(), name="mapwise-loop-lag")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task

    async def _run(self) -> None:
        while True:
            t0 = time.monotonic()
            await asyncio.sleep(self.interval_s)
            now = time.monotonic()
            self._cpu_s = time.thread_time()  # on the loop's thread: what the loop computed
            with self._lock:
                self._samples.append((now, max(0.0, now - t0 - self.interval_s)))
                while self._samples and self._samples[0][0] < now - self.window_s:
                    self._samples.popleft()

    def max_ms(self) -> float:
        """The worst lag of the window, in milliseconds (0 before the first sample)."""
        with self._lock:
            worst = max((lag for _, lag in self._samples), default=0.0)
        return round(1000.0 * worst, 1)

    def cpu_s(self) -> float:
        """CPU seconds the event loop's thread has used since the process started, as of the
        last wake-up (at most ``interval_s`` ago)."""
        return round(self._cpu_s, 4)
