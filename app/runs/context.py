"""What a run's worker needs besides the run id (:class:`WorkerContext`).

Apart from :mod:`app.runs.worker`, so that the server, which builds contexts and hands them to
worker processes, never imports the numerics a run executes (numba alone is about 120 MiB of
the API process, docs/reliability.md#api-memory).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from app.store import default_store_url


@dataclass(frozen=True, slots=True)
class WorkerContext:
    """What a worker needs besides the run id; picklable except for ``publish``."""

    database_url: str
    store_url: str = field(default_factory=default_store_url)  # the datasets' samples
    live_fps: float = 20.0
    series_points: int = 4000
    cancel_poll_s: float = 0.2
    version_fraction: float = 0.1
    owner: str = "local"  # the executor whose attempt this is (runs.owner)
    heartbeat_s: float = 2.0  # an executing attempt proves it lives this often
    take_over: bool = False  # claim a run left running by a dead attempt (a Dask retry)
    run_max_s: float | None = None  # wall-clock budget of an attempt (MAPWISE_RUN_MAX_S)
    run_memory_mb: float | None = None  # the memory limit a run executes under (its message)
