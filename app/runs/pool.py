"""The local executor's worker processes: isolated, replaced when they die, memory-limited.

A :class:`WorkerPool` keeps ``size`` long-lived worker processes. Importing the numerics and
loading numba's cached kernels costs about a CPU-second, so it is done once, in a fork
server (:mod:`app.runs.prewarm`, started by the executor with the first worker), and every
worker is forked from it warm: a worker killed mid-run is replaced in milliseconds, and the
workers share the loaded code's pages. The server itself never loads the numerics. Each
worker has its own pipe and its own thread in the server, which hands it one run at a time
and waits for the run's outcome *or the process's death*. A worker exits when the server is
gone, however it ended (:func:`watch_lifeline`). A dead worker therefore affects only
the run it was executing (unlike ``ProcessPoolExecutor``, where one dead process breaks the
pool and every run in it): the thread reports that run's outcome as a death, with the
attempt the worker had claimed, and starts a new worker. Each run executes under the OS
memory limit of :mod:`app.runs.limits`. A worker names itself (``/proc/<pid>/comm``, what
``ps`` shows) ``mw-run-<id>`` while it executes run ``<id>`` and ``mw-idle`` otherwise.
"""

from __future__ import annotations

import contextlib
import io
import logging
import multiprocessing
import os
import queue as queue_module
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing import connection as mp_connection
from multiprocessing.connection import Connection
from multiprocessing.context import BaseContext
from multiprocessing.process import BaseProcess
from typing import Any, NoReturn

import numpy as np

from app.runs.context import WorkerContext
from app.runs.limits import MIB, data_bytes, memory_limit, out_of_memory_message

log = logging.getLogger("mapwise.runs")
IDLE_CHECK_S = 1.0  # how often an idle worker's thread checks that its process lives
STOP_WAIT_S = 5.0  # how long a worker told to exit has to do so before it is killed
RETIRE_FRACTION = 0.25  # a worker holding this much of a run budget more than when warm exits
PREWARM = "app.runs.prewarm"  # what the fork server imports before it forks a process


def warm_context() -> BaseContext:
    """The multiprocessing context of the run workers and the dataset child: processes forked
    from one fork server per server process, started at the first of them, which has
    imported :mod:`app.runs.prewarm` (the numerics and their kernels) once for all."""
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload([PREWARM])
    return context


# -- in the worker process --------------------------------------------------------------------


def set_parent_death_signal() -> None:
    """Linux: SIGKILL this worker when the thread that forked it dies: the fork server's.
    That happens only if the fork server itself is killed (it outlives the server while a
    worker lives), so :func:`watch_lifeline` is what ends a worker with the server."""
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def set_process_name(name: str) -> None:
    """This process's name in ``/proc/<pid>/comm`` (at most 15 bytes): what ``ps`` shows."""
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(15, name.encode()[:15], 0, 0, 0)  # PR_SET_NAME
    except (OSError, AttributeError):
        pass


def watch_lifeline(lifeline: Connection) -> None:
    """Exit (code 70) once ``lifeline`` reads end-of-file: the server, which alone holds its
    other end, is gone (killed with ``kill -9`` too). A forked process's parent is the fork
    server, which outlives the server for as long as such a process does, so it cannot be
    watched instead. Run workers and the dataset child both watch one."""
    with contextlib.suppress(EOFError, OSError):
        while True:
            lifeline.recv()  # the server never writes: this returns only at its end
    os._exit(70)


def load_kernels() -> None:
    """Load the compiled kernels of the map filters (numba's cache), so the first run does
    not wait for them: done once in the fork server (:mod:`app.runs.prewarm`), and again,
    at no cost then, in each worker (a worker spawned afresh loads them there)."""
    from estimation.registry import EstimatorKind, get_spec, names
    from estimation.signals import Signals

    u = np.array([0.0, 0.5, 1.0, 0.25])
    signals = Signals(np.arange(4.0), {"u": u, "y": u})
    config = {"axes": [{"name": "u", "breakpoints": [0.0, 1.0]}], "output": "y"}
    for name in names(EstimatorKind.MAP_FILTER):
        get_spec(name).build(config).fit(signals)


def warm_up() -> int:
    """Make this worker ready for its first run: the kernels and pyarrow's memory pool."""
    load_kernels()
    touch_arrow_memory_pool()
    return os.getpid()


def touch_arrow_memory_pool() -> None:
    """Write and read a tiny Parquet table, as a run reads its dataset. pyarrow's allocator
    reserves about 1 GB of address space (``VmData``) on first use: reserved here, before
    the worker's baseline, it neither counts against a run's ``RLIMIT_DATA`` budget nor makes
    every worker retire after its first run as if it had kept that much memory."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from app.io.arrow_arrays import float64_array

    sink = io.BytesIO()
    pq.write_table(pa.Table.from_arrays([float64_array(np.arange(8.0))], names=["u"]), sink)
    sink.seek(0)
    pq.ParquetFile(sink).read_row_group(0)  # as a run reads (pq.read_table imports pandas)


def worker_main(context: WorkerContext, queue: Any, conn: Connection, lifeline: Connection) -> None:
    """A worker process: warm up, then execute the run ids received on ``conn`` one by one,
    telling the server ``("claimed", attempt)`` and then ``("done", status, retire)`` or
    ``("error", message, retire)``; ``None`` ends it. ``retire``: the worker exits after
    this run, because it kept more memory than a fresh one would (so runs keep their
    budget and the host does not pay for fragmentation)."""
    # The numerics are imported here, in the worker, never in the server that spawns it.
    from app.runs.worker import execute_run

    set_parent_death_signal()
    set_process_name("mw-idle")
    threading.Thread(target=watch_lifeline, args=(lifeline,), daemon=True).start()

    def publish(message: dict[str, Any]) -> None:
        with contextlib.suppress(Exception):  # a full queue drops the frame, never blocks
            queue.put_nowait(message)

    warm_up()
    baseline = data_bytes()
    budget = context.run_memory_mb
    conn.send(("ready", os.getpid()))
    while True:
        try:
            run_id = conn.recv()
        except (EOFError, OSError):
            _leave(queue)
        if run_id is None:
            _leave(queue)
        set_process_name(f"mw-run-{run_id}")
        reply: tuple[str, str]
        try:
            with memory_limit(budget):
                claimed = lambda number: conn.send(("claimed", number))  # noqa: E731
                reply = ("done", execute_run(run_id, context, publish, on_claim=claimed))
        except MemoryError:  # outside the run's own handler (at its start, say)
            reply = ("error", out_of_memory_message(budget))
        except Exception as exc:  # the run could not even record its failure
            reply = ("error", " ".join(f"{type(exc).__name__}: {exc}".split()))
        set_process_name("mw-idle")
        retire = budget is not None and data_bytes() - baseline > RETIRE_FRACTION * budget * MIB
        conn.send((*reply, retire))
        if retire:
            _leave(queue)


def _leave(queue: Any) -> NoReturn:
    """End the worker now: flush the live frames still buffered for the server, then exit
    without the interpreter's teardown, which with numba, llvmlite and pyarrow loaded takes
    about 1 s of a server's or a test module's shutdown (0.3 s instead of 1.4 s for a pool of
    two) and releases nothing the operating system does not."""
    with contextlib.suppress(Exception):
        queue.close()
        queue.join_thread()
    os._exit(0)


# -- in the server ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Outcome:
    """How a run's turn in a worker ended: the status :func:`execute_run` returned, an
    error that escaped it, or the worker's death (``died``: how, e.g. "killed by SIGKILL";
    ``attempt``: the attempt it had claimed, ``None`` if it died before claiming one)."""

    status: str | None = None
    error: str | None = None
    died: str | None = None
    attempt: int | None = None


OnOutcome = Callable[[int, Outcome], None]


def how_it_ended(exitcode: int | None) -> str:
    if exitcode is None:
        return "stopped answering"
    if exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exited with code {exitcode}"


def collect(process: BaseProcess) -> str:
    """Wait up to :data:`STOP_WAIT_S` for ``process`` to end, kill it if it has not; how it
    ended."""
    process.join(timeout=STOP_WAIT_S)
    if process.exitcode is None:
        process.kill()
        process.join(timeout=STOP_WAIT_S)
    return how_it_ended(process.exitcode)


class _Slot:
    """One worker process and the server thread that feeds it."""

    def __init__(self, pool: WorkerPool, index: int) -> None:
        self.pool, self.index = pool, index
        self.process: BaseProcess | None = None
        self.conn: Connection | None = None
        self.run_id: int | None = None  # the run its worker executes now
        self.start_failures = 0  # consecutive start-ups that ended in an error exit
        self.thread = threading.Thread(
            target=self._serve, name=f"mapwise-worker-{index}", daemon=True
        )

    # -- the worker process ---------------------------------------------------------------------

    def _spawn(self) -> None:
        if self.start_failures:  # a worker that cannot start: do not spin
            time.sleep(min(30.0, 0.5 * 2**self.start_failures))
        parent, child = self.pool.mp.Pipe()
        process = self.pool.mp.Process(
            target=worker_main,
            args=(self.pool.context, self.pool.queue, child, self.pool.lifeline),
            name=f"mapwise-run-worker-{self.index}",
            daemon=True,
        )
        try:
            process.start()
        except Exception:  # e.g. the fork server could not start: back off before the next
            parent.close()
            self.start_failures += 1
            raise
        finally:
            child.close()
        self.process, self.conn = process, parent

    def _reap(self) -> str:
        """The worker is gone (or going): collect it; how it ended."""
        assert self.process is not None
        assert self.conn is not None
        how = collect(self.process)
        if self.process.exitcode is not None and self.process.exitcode > 0:
            self.start_failures += 1  # it exited by itself: an error, not a kill
        self.conn.close()
        self.process = self.conn = None
        return how

    def _alive(self) -> bool:
        if self.process is None:
            return False
        assert self.conn is not None
        try:
            while self.conn.poll():  # an idle worker only says "ready"
                if self.conn.recv()[0] == "ready":
                    self.start_failures = 0
        except (EOFError, OSError):
            pass
        if self.process.is_alive():
            return True
        how = self._reap()
        if not self.pool.closing.is_set():
            log.warning("an idle run worker died (%s); starting a new one", how)
        return False

    def _execute(self, run_id: int) -> Outcome:
        """Hand ``run_id`` to the worker; wait for its outcome or the worker's death."""
        assert self.process is not None
        assert self.conn is not None
        attempt: int | None = None
        try:
            self.conn.send(run_id)
            while True:
                ready = mp_connection.wait([self.conn, self.process.sentinel])
                if self.conn not in ready and not self.conn.poll():
                    raise EOFError  # the worker died
                message = self.conn.recv()  # EOFError once the worker is gone
                if message[0] == "ready":
                    self.start_failures = 0
                elif message[0] == "claimed":
                    attempt = int(message[1])
                else:
                    kind, detail, retire = message
                    if retire:
                        self._reap()
                        log.info("a run worker retired after run %s; starting a new one", run_id)
                    if kind == "done":
                        return Outcome(status=detail)
                    return Outcome(error=detail)
        except (EOFError, OSError):
            return Outcome(died=self._reap(), attempt=attempt)

    def _serve(self) -> None:
        pool = self.pool
        wanted = pool.prestart  # keep a worker alive; without prestart, from the first run on
        while True:
            run_id: int | None = None
            try:
                if wanted and not self._alive():
                    if pool.closing.is_set():
                        return
                    self._spawn()
                try:
                    run_id = pool.tasks.get(timeout=IDLE_CHECK_S)
                except queue_module.Empty:
                    continue
                if run_id is None:
                    self._stop()
                    return
                if pool.closing.is_set():
                    continue  # stays queued in the database for the next start-up
                if not wanted:
                    wanted = True
                    self._spawn()
                self.run_id = run_id
                outcome = self._execute(run_id)
                self.run_id = None
                pool.on_outcome(run_id, outcome)
            except Exception:  # this thread must live on: its worker dies with it
                log.exception("run worker %s: run %s", self.index, run_id)
                self.run_id = None

    def _stop(self) -> None:
        if self.process is None or self.conn is None:
            return
        with contextlib.suppress(OSError):
            self.conn.send(None)
        self._reap()

    def pid(self) -> int | None:
        process = self.process
        return None if process is None else process.pid


class WorkerPool:
    """``size`` isolated worker processes; runs queue for the next free one (first come,
    first served). ``on_outcome(run_id, outcome)`` is called from the worker's thread.

    With ``prestart`` every worker starts with the pool; without, a slot starts its worker
    when it takes its first run (which then waits for the warm-up) and keeps one from then on.
    """

    def __init__(
        self,
        size: int,
        context: WorkerContext,
        queue: Any,
        on_outcome: OnOutcome,
        mp: BaseContext,
        *,
        prestart: bool = True,
    ) -> None:
        self.context, self.queue, self.on_outcome, self.mp = context, queue, on_outcome, mp
        self.prestart = prestart
        # Each worker gets the reading end; the server keeps the writing end, never writes,
        # and so closes it only by ending (watch_lifeline).
        self.lifeline, self._lifeline_held = mp.Pipe(duplex=False)
        self.tasks: queue_module.Queue[int | None] = queue_module.Queue()
        self.closing = threading.Event()
        self._slots = [_Slot(self, i) for i in range(size)]

    def start(self) -> None:
        """Start each slot's thread, which lives as long as the pool, and, with ``prestart``,
        its worker."""
        for slot in self._slots:
            slot.thread.start()

    def submit(self, run_id: int) -> None:
        if self.closing.is_set():
            raise RuntimeError("the run workers are stopping")
        self.tasks.put(run_id)

    def alive(self) -> int:
        """How many workers are started and not yet collected. Read from the slots' own
        bookkeeping: only a slot's thread may poll its process (two pollers of a forked
        process race for its exit status, and the loser records 255)."""
        return sum(1 for s in self._slots if s.process is not None)

    def executing(self) -> dict[int, int | None]:
        """The runs the workers execute now, with each worker's process id."""
        return {s.run_id: s.pid() for s in self._slots if s.run_id is not None}

    def close(self) -> None:
        """Take no more runs; drop those still waiting (they stay queued in the database)."""
        self.closing.set()
        with contextlib.suppress(queue_module.Empty):
            while True:
                self.tasks.get_nowait()

    def shutdown(self, timeout: float) -> bool:
        """:meth:`close`, let the executing runs end, stop the workers; kill those still
        busy after ``timeout``. ``True`` if all ended in time."""
        self.close()
        for _ in self._slots:
            self.tasks.put(None)
        deadline = time.monotonic() + timeout
        for slot in self._slots:
            slot.thread.join(max(0.0, deadline - time.monotonic()))
        late = [s for s in self._slots if s.thread.is_alive()]
        for slot in late:
            process = slot.process
            if process is not None:
                with contextlib.suppress(OSError, ValueError):
                    process.kill()
        for slot in late:
            slot.thread.join(STOP_WAIT_S)
        self._lifeline_held.close()  # any worker still there ends (watch_lifeline)
        return not late
