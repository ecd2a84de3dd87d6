"""Runs on a Dask distributed cluster (``MAPWISE_EXECUTOR=dask``, ``MAPWISE_DASK_ADDRESS``).

Workers read the run and its dataset from the shared PostgreSQL and write versions, metrics
and status there, exactly as a local pool worker does (:class:`app.runs.worker.RunSession`);
nothing travels through Dask but the run id. Live frames go through Dask's own pub/sub
(``Worker.log_event`` → ``Client.subscribe_topic``), so every API process connected to the
scheduler feeds its viewers, whichever process submitted the run.

Tasks are submitted ``fire_and_forget``: a run keeps executing when the API process that
submitted it stops or dies. A worker lost mid-run (killed, out of memory) makes the scheduler
run the task again elsewhere; the new execution records the lost attempt
(:meth:`RunRepo.lose_attempt`) and, unless the run is poisoned, claims it as a new attempt
that resumes from the last persisted version. The old attempt, should it still be alive,
fails its next fenced write, so a run never completes twice.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from datetime import UTC, datetime
from typing import Any

from app.config import Settings
from app.db.engine import Database
from app.db.repositories import RunRepo
from app.domain import RunStatus
from app.runs.frames import StatusFrame
from app.runs.hub import LiveHub
from app.runs.lost_runs import ExecutorBase
from app.runs.worker import WorkerContext, database, execute_run

log = logging.getLogger("mapwise.runs")
LIVE_TOPIC = "mapwise-live"


def dask_owner(address: str) -> str:
    return f"dask:{address}"


def execute_on_dask(run_id: int, context: WorkerContext, max_lost: int) -> str:
    """The task: on a Dask worker, execute the run (or its next attempt after a lost one)."""
    from distributed import get_worker

    worker = get_worker()

    def publish(message: dict[str, Any]) -> None:
        with contextlib.suppress(Exception):  # frames are best effort, never block the run
            worker.log_event(LIVE_TOPIC, message)

    db = database(context.database_url)
    with db.write() as s:
        runs = RunRepo(s)
        if runs.get(run_id).status == RunStatus.RUNNING:  # this task ran before, on a lost worker
            status = runs.lose_attempt(
                run_id,
                reason="its Dask worker was lost (killed or out of memory)",
                requeue=True,
                max_lost=max_lost,
            )
            if status == RunStatus.FAILED:
                publish(StatusFrame(run_id, RunStatus.FAILED).to_message())
                return RunStatus.FAILED
    return execute_run(run_id, context, publish)


class DaskExecutor(ExecutorBase):
    """Submits runs to the scheduler at ``settings.dask_address``; the same interface as
    :class:`app.runs.executor.RunExecutor` (start, submit, deliver_local, shutdown, sweep)."""

    def __init__(self, settings: Settings, db: Database, hub: LiveHub) -> None:
        assert settings.dask_address is not None
        super().__init__(settings, db, hub, owner=dask_owner(settings.dask_address))
        self._client: Any = None

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        from distributed import Client

        self._loop = loop
        self._client = Client(
            self.settings.dask_address, set_as_default=False, timeout=self.settings.dask_timeout_s
        )
        self._client.subscribe_topic(LIVE_TOPIC, self._on_event)
        self.sweep()
        with self.db.read() as s:
            queued = RunRepo(s).ids_with_status(RunStatus.QUEUED)
        for run_id in queued:  # submitted again: a claim lets only one execution through
            self.submit(run_id)
        self._start_sweeper()

    def workers_alive(self) -> int | None:
        """``None``: the cluster's workers are Dask's to count."""
        return None

    def submit(self, run_id: int) -> None:
        from distributed import fire_and_forget

        if self._client is None:
            raise RuntimeError("the Dask executor is not running")
        future = self._client.submit(
            execute_on_dask,
            run_id,
            self.context,
            self.settings.max_lost_attempts,
            key=f"mapwise-run-{run_id}-{datetime.now(UTC).timestamp():.6f}",
            pure=False,
        )
        fire_and_forget(future)

    def _on_event(self, event: tuple[float, Any]) -> None:
        _, message = event
        if isinstance(message, dict) and "run_id" in message:
            self._deliver(message)

    def shutdown(self) -> None:
        """The runs keep executing on the cluster; only this process's client goes."""
        self._stopping.set()
        if self._client is not None:
            with contextlib.suppress(Exception):
                self._client.unsubscribe_topic(LIVE_TOPIC)
            with contextlib.suppress(Exception):
                self._client.close(timeout=5)
        self._client = None
