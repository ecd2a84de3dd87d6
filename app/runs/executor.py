"""The run executor: isolated worker processes (:class:`app.runs.pool.WorkerPool`) fed with
run ids, and the pump that carries worker messages to the live hub on the event loop. A
worker that dies loses only the attempt of the run it executed (by the lost-run policy); it
is replaced, and every other run carries on.

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
import os
import queue as queue_module
import socket
import threading
from pathlib import Path
from typing import Any, Protocol

from app.config import Settings
from app.db.engine import Database
from app.db.repositories import RunRepo
from app.domain import RunStatus
from app.runs.frames import StatusFrame
from app.runs.hub import LiveHub
from app.runs.lost_runs import ExecutorBase
from app.runs.pool import Outcome, WorkerPool, warm_context

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
        super().__init__(
            settings,
            db,
            hub,
            owner=local_owner(),
            run_memory_mb=settings.run_memory_mb,
        )
        self._mp = warm_context()
        self._queue: Any = None
        self._pool: WorkerPool | None = None
        self._pump: threading.Thread | None = None
        self._closing = threading.Event()

    # -- lifecycle ----------------------------------------------------------------------------

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """Start the workers (from the long-lived event-loop thread) and the message pump."""
        self._loop = loop
        self._queue = self._mp.Queue(maxsize=10_000)
        self._pool = WorkerPool(
            self.settings.run_workers,
            self.context,
            self._queue,
            self._outcome,
            self._mp,
            prestart=self.settings.run_workers_prestart,
        )
        self._pool.start()
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

    def shutdown(self) -> None:
        """Ask running runs to stop, wait for the workers, then stop the pump."""
        pool = self._pool
        self._closing.set()
        if pool is not None:
            pool.close()
            active = list(pool.executing())
            if active:
                with self.db.write() as s:
                    runs = RunRepo(s)
                    for run_id in active:
                        runs.request_stop(run_id, "shutdown")
            if not pool.shutdown(SHUTDOWN_WAIT_S):
                log.warning("run workers did not stop within %s s: killed", SHUTDOWN_WAIT_S)
        self._pool = None
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

    def workers_alive(self) -> int | None:
        """Run worker processes alive now (fewer than ``run_workers`` before the first runs
        without prestart; a dead one counts until its slot notices, within about a second)."""
        pool = self._pool
        return 0 if pool is None else pool.alive()

    def submit(self, run_id: int) -> None:
        pool = self._pool
        if pool is None:
            raise RuntimeError("the run executor is not running")
        if self._closing.is_set():
            return  # it stays queued in the database: the next start-up submits it
        pool.submit(run_id)

    def _outcome(self, run_id: int, outcome: Outcome) -> None:
        """A run's turn in a worker ended (called from that worker's thread)."""
        if outcome.error is not None:
            self._fail(run_id, f"the worker process failed: {outcome.error}")
        elif outcome.died is not None and not self._closing.is_set():
            self._died(run_id, outcome)

    def _fail(self, run_id: int, message: str) -> None:
        log.error("run %s: %s", run_id, message)
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
            log.exception("run %s: could not record its failure", run_id)
            return
        if changed:
            self._deliver(StatusFrame(run_id, RunStatus.FAILED, message).to_message())

    def _died(self, run_id: int, outcome: Outcome) -> None:
        """The worker executing ``run_id`` died: the run is at fault (a kill, the kernel's OOM
        killer, a crash), so its attempt is lost (interrupted, re-queued or, poisoned,
        failed by policy). The other workers and their runs are untouched. A run the worker
        died before claiming is simply submitted again."""
        reason = f"the run's worker process died ({outcome.died})"
        log.error("run %s: %s", run_id, reason)
        if outcome.attempt is not None:
            self.lose(run_id, outcome.attempt, reason)
            return
        try:
            with self.db.read() as s:
                run = RunRepo(s).get(run_id)
        except Exception:
            log.exception("run %s: could not read it after its worker died", run_id)
            return
        if run.status == RunStatus.QUEUED:
            self.submit(run_id)
        elif run.status == RunStatus.RUNNING and run.owner == self.owner:
            self.lose(run_id, None, reason)  # claimed, but the news died with the worker

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
    def workers_alive(self) -> int | None: ...
    def submit(self, run_id: int) -> None: ...
    def deliver_local(self, message: dict[str, Any]) -> None: ...
    def sweep(self) -> list[int]: ...
    def shutdown(self) -> None: ...
