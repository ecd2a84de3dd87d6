"""The demo seeded into an empty database, so the dashboard is never empty: the shipped NOx
drive log (``app/data/example_nox.csv``) and a finished SKF run learning the 12×18 NOx map
with the SKF paper's case-study settings (SKF (34); the same run as ``scripts/start.sh``)."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from app.config import Settings
from app.db.engine import Database
from app.runs.context import WorkerContext
from app.runs.pool import warm_context
from app.services.datasets import DatasetService
from app.services.run_plan import RunRequest
from app.services.runs import RunService
from app.store import open_store

EXAMPLE_LOG = Path(__file__).resolve().parents[1] / "data" / "example_nox.csv"
SPEED_RPM = [750, 780, 1000, 1250, 1500, 1750, 2000, 2500, 3000, 3500, 4000, 4500]
FUEL_MG = [0, 5, 10, 15, 20, 25, 30, 34, 38, 42, 46, 50, 55, 60, 65, 70, 75, 80]
DEMO_CONFIG = {
    "sigma_w": 15.0,
    "sigma_v": 25.0,
    "p0": 1.0e4,
    "sensor": {"lag": 0.96, "delay_s": 0.75, "sigma_f": 50.0},
}
DEMO_RUN_NAME = "Demo: SKF learns the NOx map (SKF (34) settings)"


def _execute(run_id: int, context: WorkerContext) -> None:
    from app.runs.worker import execute_run

    execute_run(run_id, context)


class _RunNow:
    """Executes a submitted run at once, in a child process: the numerics (numba and its
    LLVM, about 120 MiB) stay out of the server that seeds the demo
    (docs/reliability.md#api-memory)."""

    def __init__(self, context: WorkerContext) -> None:
        self.context = context

    def submit(self, run_id: int) -> None:
        # Forked from the run workers' fork server, which the server's executor then reuses.
        with ProcessPoolExecutor(max_workers=1, mp_context=warm_context()) as child:
            child.submit(_execute, run_id, self.context).result()

    def deliver_local(self, message: dict) -> None:
        pass


def seed_demo(settings: Settings) -> int:
    """Store the demo dataset and execute the demo run; returns the run id."""
    db = Database(settings.database_url)
    try:
        with EXAMPLE_LOG.open("rb") as f:
            dataset = DatasetService(db, open_store(settings.store_url)).upload(
                f,
                filename=EXAMPLE_LOG.name,
                name="Demo: NOx drive, 150 s at 50 Hz (example_nox.csv)",
                units=None,
                max_bytes=settings.max_upload_bytes,
                max_whole_bytes=settings.max_whole_bytes,
            )
        context = WorkerContext(database_url=db.url, store_url=settings.store_url)
        runs = RunService(db, settings, _RunNow(context))
        run = runs.create(
            RunRequest(
                dataset_id=dataset.id,
                estimator="skf",
                signals={"y": "nox_ppm"},
                table={
                    "axes": [
                        {"name": "speed_rpm", "breakpoints": SPEED_RPM},
                        {"name": "fuel_mg_per_stroke", "breakpoints": FUEL_MG},
                    ]
                },
                config=DEMO_CONFIG,
                name=DEMO_RUN_NAME,
            )
        )
        return run.id
    finally:
        db.dispose()


def demo_run_id(database_url: str) -> int | None:
    """The id of the seeded demo run, or ``None`` when it was deleted or never seeded."""
    from sqlalchemy import select

    from app.db.models import RunRow

    db = Database(database_url)
    try:
        with db.read() as s:
            return s.scalar(
                select(RunRow.id).where(RunRow.name == DEMO_RUN_NAME).order_by(RunRow.id).limit(1)
            )
    finally:
        db.dispose()
