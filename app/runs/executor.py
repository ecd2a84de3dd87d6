"""The run executor: a process pool (spawn) fed with run ids, and the pump that carries
worker messages to the live hub on the event loop.

Each executor has an owner id (host, pid and process start time) that its workers write into
the runs they claim. At start-up it sweeps the database: runs whose owner was a server
process on this host that no longer exists lost their attempt at once; runs still ``queued``
are submitted again. Every ``heartbeat_timeout_s / 2`` the sweeper finds running attempts
that have not heartbeated for ``heartbeat_timeout_s`` (any owner: a server on another host
that died, an attempt that died before its first heartbeat). A lost attempt is handled by
:meth:`RunRepo.lose_attempt` (interrupted or re-queued by policy, failed after
``max_lost_attempts``). At shutdown it asks its own running runs to stop (they persist a
version and end ``interrupted``), so nothing is lost that a resume cannot recover, and
another server's runs on a shared database are left alone.
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
import os
import queue as queue_module
import socket
import threading
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from functools import partial
from pathlib import Path
from typing import Any, Protocol

from app.config import Settings
from app.db.engine import Database
from app.db.repositories import RunRepo
from app.domain import RunStatus
from app.runs.frames import StatusFrame
from app.runs.hub import LiveHub
from app.runs.lost_runs import ExecutorBase
from app.runs.pool import execute_in_pool, init_pool_worker, warm_up

log = logging.getLogger("mapwise.runs")
SHUTDOWN_WAIT_S = 15.0
LOCAL = "local"


def _start_time(pid: int) -> str | None:
    """The process's start time in clock ticks since boot (/proc), or ``None`` if it is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]


def local_owner(pid: int | None = None) -> str:
    """``local:<host>:<pid>:<start time>``: unique even when a pid is reused."""
    pid = os.getpid() if pid is None else pid
    return f"{LOCAL}:{socket.gethostname()}:{pid}:{_start_time(pid) or '?'}"


def dead_local_owner(owner: str) -> bool:
    """An owner that was a process on this host which no longer exists."""
    parts = owner.split(":")
    if len(parts) != 4 or parts[0] != LOCAL or parts[1] != socket.gethostname():
        return False
    try:
        pid = int(parts[2])
    except ValueError:
        return False
    return _start_time(pid) != parts[3]


class RunExecutor(ExecutorBase):
    def __init__(self, settings: Settings, db: Database, hub: LiveHub) -> None:
        super().__init__(settings, db, hub, owner=local_owner(), parent_pid=os.getpid())
        self._mp = multiprocessing.get_context("spawn")
        self._queue: Any = None
        self._pool: ProcessPoolExecutor | None = None
        self._pump: threading.Thread | None = None
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
        with self.db.read() as s:
            runs = RunRepo(s)
            dead = [o for o in runs.running_owners() if dead_local_owner(o)]
            orphans = runs.running_owned_by(dead)
        for run_id in orphans:
            self.lose(run_id, None, "the server stopped while the run was executing")
        self.sweep()
        with self.db.read() as s:
            queued = RunRepo(s).ids_with_status(RunStatus.QUEUED)
        for run_id in queued:
            self.submit(run_id)
        self._start_sweeper()

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
        self._stopping.set()
        with self.db.write() as s:
            runs = RunRepo(s)
            mine = runs.running_owned_by([self.owner])
            runs.interrupt(mine, "the server was stopped while the run was executing; resume it")
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
        if not isinstance(exc, BrokenProcessPool):
            message = f"the worker process failed: {type(exc).__name__}: {exc}"
            try:
                with self.db.write() as s:
                    changed = RunRepo(s).set_status(
                        run_id,
                        RunStatus.FAILED,
                        only_if=(RunStatus.RUNNING,),
                        error=message,
                        finished=True,
                    )
            except Exception:  # the database may be gone at shutdown
                return
            if changed:
                self._deliver(StatusFrame(run_id, RunStatus.FAILED, message).to_message())
            return
        # A dead worker process (killed, out of memory) takes the whole pool with it: its
        # runs lost their attempt; a run the dead pool never started is simply queued again.
        if not self._stopping.is_set():
            with self._lock:
                if self._pool is not None and self._pool._broken:  # type: ignore[attr-defined]
                    self._pool = self._new_pool()
        try:
            with self.db.read() as s:
                never_started = RunRepo(s).get(run_id).status == RunStatus.QUEUED
        except Exception:
            return
        if never_started:
            if not self._stopping.is_set():
                self.submit(run_id)
            return
        self.lose(run_id, None, "a run worker process died (killed or out of memory)")

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


def make_executor(settings: Settings, db: Database, hub: LiveHub) -> Executor:
    """The executor ``settings.executor`` names: the local pool or a Dask cluster."""
    if settings.executor == "dask":
        from app.runs.dask_executor import DaskExecutor

        return DaskExecutor(settings, db, hub)
    return RunExecutor(settings, db, hub)


class Executor(Protocol):
    """What the service needs of an executor."""

    def start(self, loop: asyncio.AbstractEventLoop) -> None: ...
    def submit(self, run_id: int) -> None: ...
    def deliver_local(self, message: dict[str, Any]) -> None: ...
    def sweep(self) -> list[int]: ...
    def shutdown(self) -> None: ...
