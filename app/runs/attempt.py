"""One attempt at a run: its claim, its fence, its heartbeat and its durable writes.

A worker claims a queued run (the claim numbers the attempt); every later write of the
attempt is fenced by that number (:meth:`RunRepo.fence`), so an attempt declared lost can
no longer write once a newer one owns the run (:class:`SupersededError`). A thread
heartbeats the attempt while it executes. A write that meets an unavailable database (a
PostgreSQL restart) is retried for up to :data:`DB_RETRY_S`, and a commit whose
acknowledgement was lost is recognised, so nothing is written twice.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

from sqlalchemy.orm import Session

from app.db.engine import Database
from app.db.repositories import DatasetRepo, MetricRepo, RunRepo, VersionRepo
from app.domain import Dataset, ResumePoint, Run, RunStatus, Series, StoredSamples
from app.errors import DatabaseUnavailableError, SupersededError

T = TypeVar("T")
DB_RETRY_S = 60.0  # how long a run waits for its database to come back before failing

_databases: dict[str, Database] = {}


def database(url: str) -> Database:
    """One :class:`Database` per URL and process (its engine pools the connections)."""
    if url not in _databases:
        _databases[url] = Database(url)
    return _databases[url]


class Heartbeat:
    """A thread that fences (and so heartbeats) the attempt every ``interval_s`` while it
    executes, independent of how long a chunk or a paced sleep takes. It stops on its own
    once the attempt is superseded (the run's next write then raises)."""

    def __init__(self, db: Database, run_id: int, attempt: int, interval_s: float) -> None:
        self.db, self.run_id, self.attempt, self.interval_s = db, run_id, attempt, interval_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._beat, name="mapwise-heartbeat", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)

    def _beat(self) -> None:
        while not self._stop.wait(self.interval_s):
            try:
                with self.db.write() as s:
                    RunRepo(s).fence(self.run_id, self.attempt)
            except SupersededError:
                return
            except Exception:  # a database hiccup: the next beat tries again
                continue


@dataclass(frozen=True, slots=True)
class LoadedRun:
    """What an attempt reads before it starts: the run, its dataset, where the dataset's
    samples are in the artifact store, its truth (an npz blob) and the version to resume
    from (``None``: from the start)."""

    run: Run
    dataset: Dataset
    samples: StoredSamples
    truth: bytes | None
    resume: ResumePoint | None


class Attempt:
    """A claimed attempt at run ``run_id``: every write goes through :meth:`write`."""

    def __init__(self, db: Database, run_id: int, number: int) -> None:
        self.db, self.run_id, self.number = db, run_id, number

    @classmethod
    def claim(cls, db: Database, run_id: int, *, owner: str, take_over: bool) -> Attempt | None:
        """The next attempt at a queued run (or a running one, ``take_over``: a Dask retry);
        ``None`` when the run finished, was cancelled or was taken meanwhile."""
        statuses = (RunStatus.QUEUED, RunStatus.RUNNING) if take_over else (RunStatus.QUEUED,)
        with db.write() as s:
            number = RunRepo(s).claim(run_id, owner=owner, statuses=statuses)
        return None if number is None else cls(db, run_id, number)

    def heartbeat(self, interval_s: float) -> Heartbeat:
        return Heartbeat(self.db, self.run_id, self.number, interval_s)

    @contextlib.contextmanager
    def write(self) -> Iterator[Session]:
        """A write transaction of this attempt: fenced by its number (see RunRepo.fence)."""
        with self.db.write() as s:
            RunRepo(s).fence(self.run_id, self.number)
            yield s

    def durably(self, write: Callable[[], T], stored: Callable[[], bool] | None = None) -> T | None:
        """``write()``, retried while the database is unavailable (a PostgreSQL restart) for
        up to DB_RETRY_S. A commit whose acknowledgement was lost with the connection may
        have landed: ``stored()`` tells, so nothing is written twice (then ``None``)."""
        deadline = time.monotonic() + DB_RETRY_S
        delay = 0.2
        while True:
            try:
                return write()
            except DatabaseUnavailableError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(delay)
                delay = min(2.0, 2 * delay)
                if stored is not None:
                    with contextlib.suppress(DatabaseUnavailableError):
                        if stored():
                            return None

    # -- reads --------------------------------------------------------------------------------

    def load(self) -> LoadedRun:
        """The run, its dataset's samples' key and its truth, and where to resume from."""

        def read() -> LoadedRun:
            with self.db.read() as s:
                run = RunRepo(s).get(self.run_id)
                datasets = DatasetRepo(s)
                return LoadedRun(
                    run=run,
                    dataset=datasets.get(run.dataset_id),
                    samples=datasets.samples(run.dataset_id),
                    truth=datasets.truth(run.dataset_id),
                    resume=VersionRepo(s).resume_point(self.run_id),
                )

        loaded = self.durably(read)
        assert loaded is not None
        return loaded

    def stop_request(self) -> str | None:
        """``"cancel"``, ``"interrupt"`` or ``None`` (also while the database is away: the
        next check asks again)."""
        try:
            with self.db.read() as s:
                return RunRepo(s).stop_request(self.run_id)
        except DatabaseUnavailableError:
            return None

    def _has_version(self, step: int) -> bool:
        with self.db.read() as s:
            return VersionRepo(s).has_step(self.run_id, step)

    # -- writes -------------------------------------------------------------------------------

    def forget_versions_after(self, sample: int) -> None:
        """Versions a previous attempt persisted after the resume point (none normally)."""

        def write() -> None:
            with self.write() as s:
                VersionRepo(s).delete_after(self.run_id, sample)

        self.durably(write)

    def progress(self, *, sample: int, progress: float, rejected: Mapping[str, int]) -> None:
        """Best effort: a progress write that meets an unavailable database is skipped."""
        with contextlib.suppress(DatabaseUnavailableError), self.write() as s:
            RunRepo(s).progress(
                self.run_id, sample=sample, progress=progress, rejected=dict(rejected)
            )

    def add_version(
        self, fields: dict[str, Any], *, progress: float, rejected: Mapping[str, int]
    ) -> None:
        """A map version (``fields`` of :meth:`VersionRepo.add`) and the run's progress."""

        def write() -> None:
            with self.write() as s:
                VersionRepo(s).add(**fields)
                RunRepo(s).progress(
                    self.run_id, sample=fields["step"], progress=progress, rejected=dict(rejected)
                )

        self.durably(write, stored=lambda: self._has_version(fields["step"]))

    def complete(
        self,
        fields: dict[str, Any],
        *,
        metrics: Mapping[str, float | None],
        series: list[Series],
        rejected: Mapping[str, int],
    ) -> None:
        """The final version, the metrics and series, and ``succeeded``: one transaction."""

        def write() -> None:
            with self.write() as s:
                VersionRepo(s).add(**fields)
                MetricRepo(s).replace(self.run_id, metrics, series)
                runs = RunRepo(s)
                runs.progress(
                    self.run_id, sample=fields["step"], progress=1.0, rejected=dict(rejected)
                )
                runs.set_status(
                    self.run_id,
                    RunStatus.SUCCEEDED,
                    only_if=(RunStatus.RUNNING,),
                    finished=True,
                )

        self.durably(write, stored=lambda: self._has_version(fields["step"]))

    def finish(self, status: RunStatus, error: str | None) -> None:
        """A final status other than success (failed, cancelled, interrupted)."""

        def write() -> None:
            with self.write() as s:
                RunRepo(s).set_status(
                    self.run_id, status, only_if=(RunStatus.RUNNING,), error=error, finished=True
                )

        self.durably(write)
