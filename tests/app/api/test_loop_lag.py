"""The event-loop lag monitor behind ``/api/health``: written on the loop, read from the
thread pool."""

from __future__ import annotations

import asyncio
import threading
import time

from app.api.loop_lag import LoopLag


def test_reading_from_another_thread_while_the_loop_trims_never_fails() -> None:
    """Health reads the samples from a worker thread while the loop appends and trims them;
    unguarded, the reader met "deque mutated during iteration" (a 500 from health)."""
    lag = LoopLag(interval_s=0.0, window_s=0.0005)
    errors: list[BaseException] = []
    readings: list[float] = []
    stop = threading.Event()

    def read() -> None:
        try:
            while not stop.is_set():
                readings.append(lag.max_ms())
        except BaseException as exc:
            errors.append(exc)

    async def main() -> None:
        lag.start()
        reader = threading.Thread(target=read)
        reader.start()
        await asyncio.sleep(1.5)
        stop.set()
        await asyncio.to_thread(reader.join)
        await lag.stop()

    asyncio.run(main())
    assert errors == []
    assert len(readings) > 1000
    assert all(r >= 0.0 for r in readings)


def test_reports_the_worst_lateness_of_the_window_in_milliseconds() -> None:
    lag = LoopLag(interval_s=0.01, window_s=30.0)

    async def main() -> float:
        lag.start()
        await asyncio.sleep(0.05)
        time.sleep(0.2)  # a handler blocking the loop for 200 ms
        await asyncio.sleep(0.05)
        await lag.stop()
        return lag.max_ms()

    assert lag.max_ms() == 0.0
    worst = asyncio.run(main())
    assert worst >= 150.0


def _burn(cpu_s: float) -> None:
    """Computes until this thread has used ``cpu_s`` of CPU time."""
    start = time.thread_time()
    while time.thread_time() - start < cpu_s:
        pass


def test_counts_the_cpu_time_of_the_loops_thread_only() -> None:
    lag = LoopLag(interval_s=0.01, window_s=30.0)

    async def main() -> tuple[float, float]:
        lag.start()
        await asyncio.sleep(0.05)
        before = lag.cpu_s()
        await asyncio.to_thread(_burn, 0.3)  # another thread computes: the loop waits
        await asyncio.sleep(0.05)
        waited = lag.cpu_s()
        _burn(0.3)  # a handler computing on the loop
        await asyncio.sleep(0.05)
        computed = lag.cpu_s()
        await lag.stop()
        return waited - before, computed - waited

    waiting, computing = asyncio.run(main())
    assert waiting < 0.1, waiting
    assert computing >= 0.29, computing
