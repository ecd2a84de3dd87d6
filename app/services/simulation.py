"""Scenarios simulated and stored by a child process, so the server never loads the numerics
(docs/reliability.md#api-memory).

Simulating a scenario integrates a plant in numba kernels: executed in the API process, it
would load numba and LLVM there (about 120 MiB, never given back) and hold a whole simulated
log. A :class:`Simulator` keeps one spawned child instead, started at the first simulation and
kept for the next ones (so the plant runs it caches, :mod:`estimation.plants.airpath`, serve
them too). The child simulates, stores the dataset exactly as the in-process path does
(:meth:`DatasetService.simulate_here <app.services.datasets.DatasetService.simulate_here>`)
and answers with its id. Simulations take turns in it, one at a time.

- Each executes under the run memory budget (:func:`app.runs.limits.memory_limit`).
- The child ends with the server: it watches its parent and reads the end of its pipe; a
  server that stops mid-simulation kills it.
- Progress crosses through three shared integers (``done``, ``total``, ``stage``), copied
  into the caller's :class:`~estimation.progress.Progress` while the server waits.
- A service error raised in the child is raised again in the server with its class, message
  and field. A child that dies is a 500 saying how; the next simulation starts a new one.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import threading
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from multiprocessing.context import SpawnProcess
from typing import Any

import numpy as np

from app import errors
from app.errors import AppError
from app.runs.limits import out_of_memory_message
from estimation.mismatch import MismatchLevel
from estimation.progress import Progress

POLL_S = 0.05  # how often the server copies the child's progress while it waits


@dataclass(frozen=True, slots=True)
class SimulationRequest:
    """What :meth:`DatasetService.simulate` was asked, as the child needs it."""

    scenario: str
    seed: int
    name: str | None
    duration_s: float | None
    mismatch: MismatchLevel


class _SharedProgress(Progress):
    """A :class:`Progress` whose counts and stage live in memory shared with the server."""

    def __init__(self, shared: Any) -> None:
        self._view = np.frombuffer(shared, dtype=np.int64)
        self.counts = self._view[:2]

    @property  # type: ignore[override]
    def stage(self) -> int:
        return int(self._view[2])

    @stage.setter
    def stage(self, value: int) -> None:
        self._view[2] = value


# -- in the child -----------------------------------------------------------------------------


def _child_main(
    database_url: str,
    store_url: str,
    memory_mb: float | None,
    shared: Any,
    conn: Connection,
    parent_pid: int,
) -> None:
    """The child: for each request received, simulate and store it, then send ``("ok", id)``
    or ``("error", class name, message, field, status, code)``; ends at ``None`` or when the
    server is gone."""
    from app.db.engine import Database
    from app.runs.limits import memory_limit
    from app.runs.pool import set_process_name, touch_arrow_memory_pool, watch_parent
    from app.services.datasets import DatasetService
    from app.store import open_store

    set_process_name("mw-simulate")  # what ps shows, beside the run workers' mw-idle
    threading.Thread(target=watch_parent, args=(parent_pid,), daemon=True).start()
    touch_arrow_memory_pool()  # pyarrow's reservation is not a simulation's memory
    db = Database(database_url)
    service = DatasetService(db, open_store(store_url))
    progress = _SharedProgress(shared)
    while True:
        try:
            request = conn.recv()
        except (EOFError, OSError):
            request = None
        if request is None:
            db.dispose()
            os._exit(0)  # as a run worker leaves: numba's teardown releases nothing
        try:  # the server zeroed the shared progress before sending the request
            with memory_limit(memory_mb):
                answer: tuple[Any, ...] = ("ok", service.simulate_here(request, progress).id)
        except AppError as exc:
            answer = ("error", type(exc).__name__, exc.message, exc.field, exc.status, exc.code)
        except MemoryError:
            answer = ("error", "AppError", out_of_memory_message(memory_mb), None, 500, "error")
        conn.send(answer)


# -- in the server ----------------------------------------------------------------------------


def _raised(name: str, message: str, field: str | None, status: int, code: str) -> AppError:
    """The child's service error as the server raises it: the same class where it is one of
    :mod:`app.errors`, else an :class:`AppError` with the child's status and code."""
    cls = getattr(errors, name, None)
    if isinstance(cls, type) and issubclass(cls, AppError) and cls is not AppError:
        return cls(message, field=field)
    error = AppError(message, field=field)
    error.status, error.code = status, code
    return error


class Simulator:
    """The server's simulating child, started at the first :meth:`simulate`."""

    def __init__(self, database_url: str, store_url: str, memory_mb: float | None) -> None:
        self.database_url, self.store_url, self.memory_mb = database_url, store_url, memory_mb
        self._mp = multiprocessing.get_context("spawn")
        self._shared = self._mp.RawArray("q", 3)
        self._view = np.frombuffer(self._shared, dtype=np.int64)
        self._turn = threading.Lock()  # one simulation at a time in the child
        self._process: SpawnProcess | None = None
        self._conn: Connection | None = None

    def simulate(self, request: SimulationRequest, progress: Progress | None) -> int:
        """Simulate and store ``request`` in the child; the new dataset's id."""
        with self._turn:
            process, conn = self._started()
            self._view[:] = 0
            conn.send(request)
            try:
                while not wait([conn, process.sentinel], timeout=POLL_S):
                    self._copy(progress)
                self._copy(progress)
                answer = conn.recv()
            except (EOFError, OSError):
                how = self._reap()
                raise AppError(
                    f"the simulation's process {how} before it answered; simulate again"
                ) from None
        if answer[0] == "ok":
            return int(answer[1])
        raise _raised(*answer[1:])

    def close(self) -> None:
        """End the child: at once when idle; killed mid-simulation (the server is stopping,
        and the simulation's request ends in the 500 of a dead child, storing nothing)."""
        if not self._turn.acquire(blocking=False):
            process = self._process
            if process is not None:
                with contextlib.suppress(OSError, ValueError):
                    process.kill()
            return
        try:
            if self._conn is not None:
                with contextlib.suppress(OSError):
                    self._conn.send(None)
                self._reap()
        finally:
            self._turn.release()

    def pid(self) -> int | None:
        return None if self._process is None else self._process.pid

    def _started(self) -> tuple[SpawnProcess, Connection]:
        if self._process is not None and not self._process.is_alive():
            self._reap()
        if self._process is None or self._conn is None:
            parent, child = self._mp.Pipe()
            process = self._mp.Process(
                target=_child_main,
                args=(
                    self.database_url,
                    self.store_url,
                    self.memory_mb,
                    self._shared,
                    child,
                    os.getpid(),
                ),
                name="mapwise-simulate",
                daemon=True,
            )
            process.start()
            child.close()
            self._process, self._conn = process, parent
        return self._process, self._conn

    def _reap(self) -> str:
        """Collect the child; how it ended."""
        from app.runs.pool import collect

        assert self._process is not None
        assert self._conn is not None
        how = collect(self._process)
        self._conn.close()
        self._process = self._conn = None
        return how

    def _copy(self, progress: Progress | None) -> None:
        if progress is not None:
            progress.counts[:] = self._view[:2]
            progress.stage = int(self._view[2])
