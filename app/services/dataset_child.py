"""Datasets simulated, or uploads read whole, by a child process, so the server never loads
the numerics or holds a whole log (docs/reliability.md#api-memory).

Simulating a scenario integrates a plant in numba kernels: executed in the API process, it
would load numba and LLVM there (about 120 MiB, never given back) and hold a whole simulated
log. An upload that cannot stream (an MCAP, MDF or non-dense CSV log, or one with a raster)
is parsed whole: asammdf alone loads pandas (about 55 MiB), and the parse holds several
times the file. A :class:`DatasetChild` keeps one child for both, started at the
first such request and kept for the next ones (so the plant runs it caches,
:mod:`estimation.plants.airpath`, serve them too). The child simulates or parses, stores
the dataset exactly as the in-process path does (:meth:`DatasetService.simulate_here
<app.services.datasets.DatasetService.simulate_here>`, :meth:`DatasetService.upload_whole
<app.services.datasets.DatasetService.upload_whole>`) and answers with its id. Requests take
turns in it, one at a time.

- Each executes under the run memory budget (:func:`app.runs.limits.memory_limit`); an
  upload that needs more is a 413.
- An upload reaches the child as the server's open file (its descriptor passed over the
  pipe, :func:`multiprocessing.reduction.send_handle`), as a path, or as bytes.
- The child is forked from the run workers' fork server (:func:`app.runs.pool.warm_context`),
  which has imported the numerics once: it is ready in milliseconds, where a spawned one
  took about 2 CPU-seconds to import them.
- The child ends with the server: it watches a lifeline pipe whose other end only the
  server holds (:func:`app.runs.pool.watch_lifeline`) and reads the end of its request pipe;
  a server that stops mid-request kills it.
- A simulation's progress crosses through three shared integers (``done``, ``total``,
  ``stage``), copied into the caller's :class:`~estimation.progress.Progress` while the
  server waits.
- A service error raised in the child is raised again in the server with its class (or its
  status and code), message and field. Any other failure (a defect, or memory short) is a
  500 with its message, after which the child leaves; a child that dies is a 500 saying
  how. Either way the next request starts a new one.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
from dataclasses import dataclass
from multiprocessing import reduction
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from app import errors
from app.errors import AppError, InvalidRequestError, PayloadTooLargeError
from app.runs.limits import out_of_memory_message
from app.runs.pool import warm_context
from estimation.errors import EstimationError
from estimation.mismatch import MismatchLevel
from estimation.progress import Progress

log = logging.getLogger("mapwise")
_LEAVES = "leaves"  # ends an answer after which the child leaves
POLL_S = 0.05  # how often the server copies the child's progress while it waits
PROCESS_NAME = "mw-datasets"  # what ps shows, beside the run workers' mw-idle


@dataclass(frozen=True, slots=True)
class SimulationRequest:
    """What :meth:`DatasetService.simulate` was asked, as the child needs it."""

    scenario: str
    seed: int
    name: str | None
    duration_s: float | None
    mismatch: MismatchLevel


@dataclass(frozen=True, slots=True)
class WholeUpload:
    """An upload to parse whole (:meth:`DatasetService.upload_whole`): everything but the
    file itself."""

    name: str
    units: dict[str, str] | None
    channels: list[str] | None
    raster: str | None
    rate_hz: float | None
    max_bytes: int
    max_decompressed_bytes: int


@dataclass(frozen=True, slots=True)
class _Upload:
    """A :class:`WholeUpload` as sent to the child, with where its file is: ``path``, or
    ``content``, or neither (its descriptor follows on the pipe)."""

    upload: WholeUpload
    path: str | None = None
    content: bytes | None = None


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
    lifeline: Connection,
) -> None:
    """The child: for each request received, execute it, then send ``("ok", id)`` or
    ``("error", class name, message, field, status, code)``; ends at ``None`` or when the
    server is gone."""
    from app.db.engine import Database
    from app.runs.limits import memory_limit
    from app.runs.pool import (
        set_parent_death_signal,
        set_process_name,
        touch_arrow_memory_pool,
        watch_lifeline,
    )
    from app.services.datasets import DatasetService
    from app.store import open_store

    set_parent_death_signal()
    set_process_name(PROCESS_NAME)
    threading.Thread(target=watch_lifeline, args=(lifeline,), daemon=True).start()
    touch_arrow_memory_pool()  # pyarrow's reservation is not a request's memory
    db = Database(database_url)
    service = DatasetService(db, open_store(store_url))
    progress = _SharedProgress(shared)
    while True:
        file = None
        try:
            request = conn.recv()
            file = _received_file(conn, request)
        except (EOFError, OSError):
            request = None
        if request is None:
            db.dispose()
            os._exit(0)  # as a run worker leaves: numba's teardown releases nothing
        try:  # the server zeroed the shared progress before sending the request
            with memory_limit(memory_mb):
                answer: tuple[Any, ...] = ("ok", _execute(service, request, file, progress))
        except AppError as exc:
            answer = ("error", type(exc).__name__, exc.message, exc.field, exc.status, exc.code)
        except EstimationError as exc:
            message = " ".join(str(exc).split())
            answer = ("error", InvalidRequestError.__name__, message, None, 422, "validation_error")
        except MemoryError:
            answer = _out_of_memory(request, memory_mb)
        except Exception as exc:  # a defect, or memory short where no MemoryError is raised
            log.exception("dataset request failed")
            message = " ".join(f"{type(exc).__name__}: {exc}".split())
            answer = ("error", "AppError", message, None, 500, "error", _LEAVES)
        finally:
            if file is not None:
                file.close()
        conn.send(answer)
        if answer[0] == "error" and answer[-1] == _LEAVES:
            # A MemoryError (or another failure) can strike inside any import or cache: leave,
            # and let the next request start a clean child rather than trust this one's state.
            db.dispose()
            os._exit(0)


def _received_file(conn: Connection, request: Any) -> BinaryIO | None:
    """The file of an upload whose descriptor follows the request on the pipe."""
    if not isinstance(request, _Upload) or request.path is not None or request.content is not None:
        return None
    file = os.fdopen(reduction.recv_handle(conn), "rb")
    file.seek(0)
    return file


def _execute(service: Any, request: Any, file: BinaryIO | None, progress: Progress) -> int:
    if isinstance(request, SimulationRequest):
        return int(service.simulate_here(request, progress).id)
    assert isinstance(request, _Upload)
    source: Any = file or (request.path and Path(request.path)) or request.content
    return int(service.upload_whole(source, request.upload).id)


def _out_of_memory(request: Any, memory_mb: float | None) -> tuple[Any, ...]:
    """A simulation out of memory is a 500; an upload, a 413: the file is too large to read
    whole under the budget."""
    if not isinstance(request, _Upload):
        message = out_of_memory_message(memory_mb)
        return ("error", "AppError", message, None, 500, "error", _LEAVES)
    budget = "the machine's memory" if memory_mb is None else f"{memory_mb:g} MiB"
    message = (
        f"the file needs more than {budget} (MAPWISE_RUN_MEMORY_MB) to read whole; "
        "upload a dense CSV, which streams, or fewer channels"
    )
    too_large = PayloadTooLargeError(message, field="file")
    code = too_large.code
    return ("error", type(too_large).__name__, message, "file", 413, code, _LEAVES)


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


class DatasetChild:
    """The server's dataset child, started at the first :meth:`simulate` or :meth:`upload`."""

    def __init__(self, database_url: str, store_url: str, memory_mb: float | None) -> None:
        self.database_url, self.store_url, self.memory_mb = database_url, store_url, memory_mb
        self._mp = warm_context()
        self._shared = self._mp.RawArray("q", 3)
        self._view = np.frombuffer(self._shared, dtype=np.int64)
        self._turn = threading.Lock()  # one request at a time in the child
        self._process: BaseProcess | None = None
        self._conn: Connection | None = None
        # The child gets the reading end; the server never writes to the other, which closes
        # only when the server ends, however it ends (watch_lifeline).
        self._lifeline, self._lifeline_held = self._mp.Pipe(duplex=False)

    def simulate(self, request: SimulationRequest, progress: Progress | None) -> int:
        """Simulate and store ``request`` in the child; the new dataset's id."""
        return self._ask(request, None, progress, "simulate again")

    def upload(self, source: BinaryIO | bytes | os.PathLike[str], upload: WholeUpload) -> int:
        """Parse ``source`` whole and store it in the child; the new dataset's id. An open
        file with a descriptor is passed as it (the child reads it from the start)."""
        if isinstance(source, bytes | bytearray | memoryview):
            return self._ask(_Upload(upload, content=bytes(source)), None, None, "upload again")
        if isinstance(source, os.PathLike):
            return self._ask(_Upload(upload, path=str(Path(source))), None, None, "upload again")
        try:
            fd = source.fileno()  # a spooled upload still in memory is written out first
        except (AttributeError, OSError, ValueError):
            source.seek(0)
            return self._ask(_Upload(upload, content=source.read()), None, None, "upload again")
        return self._ask(_Upload(upload), fd, None, "upload again")

    def _ask(self, request: Any, fd: int | None, progress: Progress | None, retry: str) -> int:
        with self._turn:
            process, conn = self._started()
            self._view[:] = 0
            try:
                conn.send(request)
                if fd is not None:
                    reduction.send_handle(conn, fd, process.pid)
                while not wait([conn, process.sentinel], timeout=POLL_S):
                    self._copy(progress)
                self._copy(progress)
                answer = conn.recv()
                if answer[-1] == _LEAVES:
                    self._reap()  # it leaves after such an answer (_child_main)
            except (EOFError, OSError):
                how = self._reap()
                raise AppError(f"the dataset process {how} before it answered; {retry}") from None
        if answer[0] == "ok":
            return int(answer[1])
        raise _raised(*answer[1:6])

    def close(self) -> None:
        """End the child: at once when idle; killed mid-request (the server is stopping, and
        the request ends in the 500 of a dead child, storing nothing)."""
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

    def _started(self) -> tuple[BaseProcess, Connection]:
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
                    self._lifeline,
                ),
                name="mapwise-datasets",
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
