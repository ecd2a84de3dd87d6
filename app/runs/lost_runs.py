"""What both executors (the local pool and Dask) share: the worker context they hand out,
delivering worker messages to the live hub on the event loop, and the handling of lost
attempts — the sweep for silent ones every ``heartbeat_timeout_s / 2``, and the policy for a
lost attempt (interrupted, re-queued and submitted again, or failed when poisoned)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from datetime import UTC, datetime, timedelta
from typing import Any

from app.config import Settings
from app.db.engine import Database
from app.db.repositories import RunRepo
from app.domain import RunStatus
from app.runs.context import WorkerContext
from app.runs.frames import StatusFrame
from app.runs.hub import LiveHub

log = logging.getLogger("mapwise.runs")


class ExecutorBase:
    """Subclasses implement ``submit(run_id)``, ``start(loop)`` and ``shutdown()``."""

    def __init__(
        self, settings: Settings, db: Database, hub: LiveHub, *, owner: str, **context: Any
    ) -> None:
        self.settings = settings
        self.db = db
        self.hub = hub
        self.owner = owner
        self.context = WorkerContext(
            database_url=db.url,
            store_url=settings.store_url,
            live_fps=settings.live_fps,
            series_points=settings.series_points,
            cancel_poll_s=settings.cancel_poll_s,
            version_fraction=settings.version_fraction,
            owner=owner,
            heartbeat_s=settings.heartbeat_s,
            run_max_s=settings.run_max_s,
            **context,
        )
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping = threading.Event()
        self._sweeper: threading.Thread | None = None

    def submit(self, run_id: int) -> None:
        raise NotImplementedError

    # -- lost attempts ----------------------------------------------------------------------

    def lose(self, run_id: int, attempt: int | None, reason: str) -> None:
        """The run's live attempt died: interrupted, re-queued (and submitted) or failed."""
        try:
            with self.db.write() as s:
                status = RunRepo(s).lose_attempt(
                    run_id,
                    reason=reason,
                    requeue=self.settings.lost_run_policy == "requeue",
                    max_lost=self.settings.max_lost_attempts,
                    attempt=attempt,
                )
                error = RunRepo(s).get(run_id).error if status else None
        except Exception:  # the database may be gone at shutdown
            log.exception("run %s: could not record its lost attempt", run_id)
            return
        if status is None:
            return
        log.warning("run %s lost its attempt (%s): now %s", run_id, reason, status)
        self._deliver(StatusFrame(run_id, status, error).to_message())
        if status == RunStatus.QUEUED and not self._stopping.is_set():
            self.submit(run_id)

    def sweep(self) -> list[int]:
        """Running attempts silent for ``heartbeat_timeout_s`` lost their worker."""
        stale_before = datetime.now(UTC) - timedelta(seconds=self.settings.heartbeat_timeout_s)
        with self.db.read() as s:
            stale = RunRepo(s).stale_running(stale_before=stale_before)
        for run in stale:
            self.lose(run.id, run.attempt, "the run's worker stopped heartbeating")
        return [r.id for r in stale]

    def _start_sweeper(self) -> None:
        self._sweeper = threading.Thread(target=self._sweep_loop, name="mapwise-sweep", daemon=True)
        self._sweeper.start()

    def _sweep_loop(self) -> None:
        while not self._stopping.wait(self.settings.heartbeat_timeout_s / 2):
            try:
                self.sweep()
            except Exception:  # the database may be down for a while: sweep again later
                log.exception("the lost-run sweep failed")

    # -- messages -----------------------------------------------------------------------------

    def _deliver(self, message: dict[str, Any]) -> None:
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
            loop.call_soon_threadsafe(self.hub.handle, message)

    def deliver_local(self, message: dict[str, Any]) -> None:
        """A message from the API process itself (e.g. a queued run cancelled)."""
        self._deliver(message)
