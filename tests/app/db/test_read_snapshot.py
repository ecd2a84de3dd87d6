"""A read unit of work sees one snapshot on both backends (app/db/engine.py): a run list's
total and its items, read in two statements, agree even when a run changes status between
them. The isolation storm once saw ``total`` 0 beside one interrupted run on PostgreSQL,
whose default READ COMMITTED takes a snapshot per statement."""

from __future__ import annotations

from sqlalchemy import func, select, update

from app.config import Settings
from app.db.engine import Database
from app.db.migrate import upgrade
from app.db.models import RunRow
from app.db.repositories import DatasetRepo, RunRepo
from app.domain import Channel
from app.services.run_plan import RunRequest
from app.services.runs import RunService
from tests.support.server import run_body


def _dataset_and_run(db: Database) -> int:
    """A dataset row (no samples: a list never reads them) and a queued run on it."""
    with db.write() as s:
        dataset = DatasetRepo(s).add(
            name="log",
            source="csv",
            rows=1000,
            rate_hz=100.0,
            duration_s=9.99,
            time_column="time",
            channels=[Channel("u1", "rpm"), Channel("u2", "mg/stroke"), Channel("y", "ppm")],
        )
    service = RunService(db, Settings(database_url=db.url), executor=None)
    with db.write() as s:
        return service.store_in(s, RunRequest(**run_body(dataset.id))).id


def test_a_read_sees_one_snapshot_across_its_statements(database_url: str) -> None:
    upgrade(database_url)
    db = Database(database_url)
    try:
        run_id = _dataset_and_run(db)
        with db.read() as s:
            interrupted = RunRow.status == "interrupted"
            before = s.scalar(select(func.count()).select_from(RunRow).where(interrupted))
            with db.write() as w:  # another unit of work commits in between
                w.execute(update(RunRow).where(RunRow.id == run_id).values(status="interrupted"))
            page = RunRepo(s).list(status="interrupted", limit=10, offset=0)
            assert (before, page.total, len(page.items)) == (0, 0, 0)
        with db.read() as s:
            page = RunRepo(s).list(status="interrupted", limit=10, offset=0)
            assert (page.total, [r.id for r in page.items]) == (1, [run_id])
    finally:
        db.dispose()
