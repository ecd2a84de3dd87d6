"""The run executor: a process pool (spawn) fed with run ids, and the pump that carries
worker messages to the live hub on the event loop.

At start-up it sweeps the database: runs left ``running`` by a server that died become
``interrupted`` (resumable), runs still ``queued`` are submitted again. At shutdown it asks
its running runs to stop (they persist a version and end ``interrupted``), so nothing is
lost that a resume cannot recover.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import multiprocessing
import os
import queue as queue_module
import threading
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from functools import partial
from typing import Any

from app.config import Settings
from app.db.engine import Database
from app.db.repositories import RunRepo
from app.runs.hub import LiveHub
from app.runs.worker import WorkerContext, execute_in_pool, init_pool_worker, warm_up

log = logging.getLogger("mapwise.runs")
SHUTDOWN_WAIT_S = 15.0


class RunExecutor:
    def __init__(self, settings: Settings, db: Database, hub: LiveHub) -> None:
        self.settings = settings
        self.db = db
        self.hub = hub
        self.context = WorkerContext(
            database_url=db.url,
            live_fps=settings.live_fps,
            series_points=settings.series_points,
            cancel_poll_s=settings.cancel_poll_s,
            version_fraction=settings.version_fraction,
            parent_pid=os.getpid(),
        )
        self._mp = multiprocessing.get_context("spawn")
        self._queue: Any = None
        self._pool: ProcessPoolExecutor | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pump: threading.Thread | None = None
        self._stopping = threading.Event()
        self._lock = threading.Lock()
        self._futures: dict[int, Future[str]] = {}

    # -- lifecycle ----------------------------------------------------------------------------

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """Start the pool (from the long-lived event-loop thread) and the message pump."""
        self._loop = loop
        self._queue = self._mp.Queue(maxsize=10_000)
        self._pool = self._new_pool()
        self._pump = threading.Thread(target=self._pump_messages, name="mapwise-pump", daemon=True)
        self._pump.start()
        with self.db.write() as s:
            runs = RunRepo(s)
            interrupted = runs.mark_running_interrupted()
            queued = runs.ids_with_status("queued")
        if interrupted:
            log.warning("runs %s were left running by a stopped server: interrupted", interrupted)
        for run_id in queued:
            self.submit(run_id)

    def _new_pool(self) -> ProcessPoolExecutor:
        pool = ProcessPoolExecutor(
            max_workers=self.settings.run_workers,
            mp_context=self._mp,
            initializer=init_pool_worker,
            initargs=(self.context, self._queue),
        )
        for _ in range(self.settings.run_workers):
            pool.submit(warm_up)  # launches every worker now, from this thread
        return pool

    def shutdown(self) -> None:
        """Ask running runs to stop, wait for the pool, then stop the pump."""
        with self._lock:
            active = [run_id for run_id, f in self._futures.items() if not f.done()]
        if active:
            with self.db.write() as s:
                runs = RunRepo(s)
                for run_id in active:
                    runs.request_stop(run_id, "shutdown")
        pool = self._pool
        self._pool = None
        if pool is not None:
            done = threading.Event()

            def _wait() -> None:
                pool.shutdown(wait=True, cancel_futures=True)
                done.set()

            threading.Thread(target=_wait, daemon=True).start()
            if not done.wait(SHUTDOWN_WAIT_S):
                log.warning("run workers did not stop within %s s", SHUTDOWN_WAIT_S)
        with self.db.write() as s:
            RunRepo(s).mark_running_interrupted()
        self._stopping.set()
        if self._pump is not None:
            self._pump.join(timeout=2.0)
        if self._queue is not None:
            self._queue.close()
            self._queue.join_thread()

    # -- runs -----------------------------------------------------------------------------------

    def submit(self, run_id: int) -> None:
        with self._lock:
            if self._pool is None:
                raise RuntimeError("the run executor is not running")
            try:
                future = self._pool.submit(execute_in_pool, run_id)
            except BrokenProcessPool:
                log.error("the run pool broke; starting a new one")
                self._pool = self._new_pool()
                future = self._pool.submit(execute_in_pool, run_id)
            self._futures[run_id] = future
        future.add_done_callback(partial(self._done, run_id))

    def _done(self, run_id: int, future: Future[str]) -> None:
        with self._lock:
            if self._futures.get(run_id) is future:
                del self._futures[run_id]
        if future.cancelled():
            return
        exc = future.exception()
        if exc is None:
            return
        log.error("run %s: its worker failed: %r", run_id, exc)
        broken = isinstance(exc, BrokenProcessPool)
        # A dead worker process (killed, out of memory) takes the whole pool with it: its
        # runs are interrupted like a killed server's and resume from their last version.
        status = "interrupted" if broken else "failed"
        message = f"the worker process failed: {type(exc).__name__}: {exc}"
        if broken:
            message = "a run worker process died (killed or out of memory); resume the run"
        if broken and not self._stopping.is_set():
            with self._lock:
                if self._pool is not None and self._pool._broken:  # type: ignore[attr-defined]
                    self._pool = self._new_pool()
        try:
            with self.db.write() as s:
                runs = RunRepo(s)
                # a run the dead pool never started is simply queued again
                requeue = broken and runs.get(run_id).status == "queued"
                changed = not requeue and runs.set_status(
                    run_id, status, only_if=("running",), error=message, finished=True
                )
        except Exception:  # the database may be gone at shutdown
            return
        if requeue and not self._stopping.is_set():
            self.submit(run_id)
        elif changed:
            self._deliver({"kind": "status", "run_id": run_id, "status": status, "error": message})

    def is_active(self, run_id: int) -> bool:
        with self._lock:
            future = self._futures.get(run_id)
        return future is not None and not future.done()

    # -- messages -------------------------------------------------------------------------------

    def _pump_messages(self) -> None:
        while not self._stopping.is_set():
            try:
                message = self._queue.get(timeout=0.25)
            except queue_module.Empty:
                continue
            except (EOFError, OSError):
                return
            self._deliver(message)

    def _deliver(self, message: dict[str, Any]) -> None:
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
            loop.call_soon_threadsafe(self.hub.handle, message)

    def deliver_local(self, message: dict[str, Any]) -> None:
        """A message from the API process itself (e.g. a queued run cancelled)."""
        self._deliver(message)
