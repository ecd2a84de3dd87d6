"""One run, executed in a worker process (or in-process): estimator chunks, versions, live ticks.

The worker reads everything it needs from the database (the run, its dataset's row, the
last persisted version when resuming) and the artifact store (the dataset's samples, their
hash checked, only the channels the run reads: :func:`~app.runs.results.channels_read` and
the gates'; a dataset stored as recorded is read on the slowest raster among those channels,
whose step the run's metrics keep as ``raster_s``, `docs/data-formats.md#multi-rate`) and
writes its results to the database, so it can run in any process sharing
both. :class:`RunSession` only orchestrates, per chunk: fold the
estimator's snapshot into the results (:mod:`app.runs.results`), persist a map version at
the run's cadence with the estimator state, so a resumed run continues bit-for-bit
(:mod:`app.runs.attempt`), publish a live tick at most ``live_fps`` times a second without
ever waiting (:mod:`app.runs.live`, frames in :mod:`app.runs.frames`), and check for a stop
request.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from app.db import blobs
from app.domain import RunStatus
from app.errors import SupersededError
from app.io.payload import unpack_truth
from app.runs.attempt import Attempt, database
from app.runs.context import WorkerContext
from app.runs.gates import apply_gates, gate_channels, parse_gates, scan_gates
from app.runs.limits import out_of_memory_message
from app.runs.live import LiveTicks, Publish
from app.runs.options import run_options, run_raster, streams_input
from app.runs.results import RunResults, channels_read
from app.store import load_on_raster, open_store
from app.store.log_rows import open_rows
from app.store.raster_rows import RasterRows
from estimation.estimator import ChunkedEstimator, Snapshot
from estimation.registry import get_spec, load_state

__all__ = ["RunSession", "WorkerContext", "database", "execute_run"]

PROGRESS_EVERY_S = 1.0


class StopRun(Exception):  # noqa: N818 - control flow, not an error
    def __init__(self, status: RunStatus, error: str | None) -> None:
        super().__init__(status)
        self.status = status
        self.error = error


def execute_run(
    run_id: int,
    context: WorkerContext,
    publish: Publish | None = None,
    on_claim: Callable[[int], None] | None = None,
) -> str:
    """Execute one queued run to a final status; returns that status (or ``"skipped"``).
    ``on_claim(attempt)`` is told the attempt's number as soon as it is claimed."""
    session = RunSession(run_id, context, publish or (lambda _m: None), on_claim)
    return session.execute()


class RunSession:
    """One execution of a run: claim an attempt, prepare, loop over the estimator's chunks,
    complete or stop. Results, live messages and writes are delegated (module docstring)."""

    def __init__(
        self,
        run_id: int,
        context: WorkerContext,
        publish: Publish,
        on_claim: Callable[[int], None] | None = None,
    ) -> None:
        self.run_id = run_id
        self.on_claim = on_claim
        self.ctx = context
        self.db = database(context.database_url)
        self.live = LiveTicks(run_id, context.live_fps, publish)
        self.results: RunResults | None = None
        self.raster_s: float | None = None  # the step of a raster made when reading
        self.version_sample = 0  # first sample not yet in a persisted version
        self.last_progress = 0.0  # monotonic time of the last progress write
        self.last_stop_check = 0.0
        self.started = time.monotonic()

    # -- lifecycle ----------------------------------------------------------------------------

    def execute(self) -> str:
        attempt = Attempt.claim(
            self.db, self.run_id, owner=self.ctx.owner, take_over=self.ctx.take_over
        )
        if attempt is None:
            return "skipped"  # finished, cancelled or taken by another attempt meanwhile
        self.attempt = attempt
        if self.on_claim is not None:
            self.on_claim(attempt.number)
        heartbeat = attempt.heartbeat(self.ctx.heartbeat_s)
        heartbeat.start()
        try:
            self._status(RunStatus.RUNNING, None)
            with contextlib.ExitStack() as self.closing:  # a streamed run's open dataset
                return self._execute()
        except SupersededError:
            return "superseded"  # a newer attempt owns the run: write nothing more
        finally:
            heartbeat.stop()

    def _execute(self) -> str:
        try:
            self._prepare()
            self._loop()
            return RunStatus.SUCCEEDED
        except StopRun as stop:
            self._finish(stop.status, stop.error)
            return stop.status
        except SupersededError:
            raise
        except MemoryError:  # finished below, once the traceback (and what it holds) is freed
            pass
        except Exception as exc:  # any failure is the run's, stored with it
            message = " ".join(f"{type(exc).__name__}: {exc}".split())
            if hasattr(exc, "message"):
                message = " ".join(str(exc).split())
            self._finish(RunStatus.FAILED, message)
            return RunStatus.FAILED
        self._finish(RunStatus.FAILED, out_of_memory_message(self.ctx.run_memory_mb))
        return RunStatus.FAILED

    def _finish(self, status: RunStatus, error: str | None) -> None:
        self.attempt.finish(status, error)
        self._status(status, error)

    def _status(self, status: RunStatus, error: str | None) -> None:
        n = self.results.n if self.results is not None else 0
        self.live.status(status, error, self.version_sample / n if n else 0.0)

    # -- preparation --------------------------------------------------------------------------

    def _prepare(self) -> None:
        loaded = self.attempt.load()
        self.run, dataset = loaded.run, loaded.dataset
        truth = None if loaded.truth is None else unpack_truth(loaded.truth)
        spec = get_spec(self.run.estimator)
        self.estimator = spec.build(self.run.estimator_config)
        names = channels_read(self.run, self.estimator, truth) + gate_channels(self.run.config)
        raster = run_raster(self.run.config)
        if raster is not None and raster.channel is not None:
            names.append(raster.channel)
        store = open_store(self.ctx.store_url)
        known = [c.name for c in dataset.channels]
        if streams_input(spec, dataset, self.estimator):
            rows = open_rows(store, loaded.samples, dataset.channels, names, raster=raster)
            log = self.closing.enter_context(rows)
            # stored as recorded: the rate of the raster this run's channels set
            self.raster_s = log.step_s if isinstance(log, RasterRows) else None
            self.rate_hz = dataset.rate_hz if self.raster_s is None else 1.0 / self.raster_s
            self.options = run_options(
                self.run.config, log.n, self.rate_hz, self.ctx.version_fraction
            )
            gates = None
            if self.options.gates:
                parsed = parse_gates(self.options.gates, known, field="config.gates")
                gates = scan_gates(parsed, log.rows, log.n)
            self.results = RunResults(self.run, spec, dataset, log, truth, gates)
        else:
            read = load_on_raster(store, loaded.samples, dataset.channels, names, raster=raster)
            signals = read.signals
            # a dataset stored as recorded: the rate of the raster this run's channels set
            self.raster_s = read.step_s
            self.rate_hz = dataset.rate_hz if read.step_s is None else 1.0 / read.step_s
            self.options = run_options(
                self.run.config, len(signals), self.rate_hz, self.ctx.version_fraction
            )
            gates = None
            if self.options.gates:
                parsed = parse_gates(self.options.gates, known, field="config.gates")
                gates = apply_gates(parsed, signals)
            self.results = RunResults(self.run, spec, dataset, signals, truth, gates)
        self.accept = None if self.results.gates is None else self.results.gates.accept
        self.state: Any = None
        if loaded.resume is not None:
            self.state = load_state(loaded.resume.state)
            self.results.restore(loaded.resume)
            self.version_sample = self.live.sample = loaded.resume.step
        self.attempt.forget_versions_after(self.version_sample)

    def _chunk_size(self) -> int:
        """Samples per estimator chunk: one live frame's worth when paced, else ~1 % of the
        log; a divisor of the version cadence when one is near, so versions land on it."""
        assert self.results is not None
        if self.options.pace is not None:
            # Half a frame interval of log per chunk: every frame interval then has new
            # samples, so the tick limiter (not the chunking) sets the rate: live_fps.
            per_frame = self.rate_hz * self.options.pace / (2.0 * self.ctx.live_fps)
            desired = max(1, int(per_frame))
        else:
            desired = min(20_000, max(256, self.results.n // 100))
        every = self.options.version_every
        if desired >= every:
            return every
        k_max = every // desired  # chunks per version, each at least `desired` long
        for k in range(k_max, max(1, k_max // 2) - 1, -1):
            if every % k == 0:
                return every // k
        return math.ceil(every / k_max)

    # -- the loop -----------------------------------------------------------------------------

    def _loop(self) -> None:
        results = self.results
        assert results is not None
        every = self.options.version_every
        next_version = (self.version_sample // every + 1) * every
        wall0, t0 = 0.0, 0.0  # the pace clock starts after the first chunk (JIT loading)
        started = False
        t_run = time.perf_counter()
        last: Snapshot | None = None
        for snap in self._snapshots(results):
            last = snap
            results.absorb(snap)
            if not started:
                self.live.start(snap, results)
                started = True
                wall0, t0 = time.monotonic(), snap.time_s
            if snap.done:
                break
            if snap.sample >= next_version:
                self._persist(snap)
                next_version = (snap.sample // every + 1) * every
            self.live.tick(snap, results)
            self._check_stop(snap)
            if self.options.pace is not None:
                self._sleep_until(wall0 + (snap.time_s - t0) / self.options.pace, snap)
        assert last is not None
        self._complete(last, time.perf_counter() - t_run)

    def _snapshots(self, results: RunResults) -> Iterator[Snapshot]:
        """The estimator's run: over the log held whole, or a window at a time from the
        store (:meth:`ChunkedEstimator.run_windows`, the same snapshots)."""
        every = self._chunk_size()
        if not results.streamed:
            return self.estimator.run(
                results.signals, every=every, state=self.state, accept=self.accept
            )
        assert isinstance(self.estimator, ChunkedEstimator)
        assert self.estimator.windowed
        log = results.log
        return self.estimator.run_windows(
            log.rows,
            results.n,
            every=every,
            state=self.state,
            timeline=log.time,
            accept=self.accept,
        )

    def _check_stop(self, snap: Snapshot) -> None:
        assert self.results is not None
        now = time.monotonic()
        if now - self.last_progress >= PROGRESS_EVERY_S:
            self.attempt.progress(
                sample=snap.sample,
                progress=snap.sample / self.results.n,
                rejected=self.results.run_rejected(),
            )
            self.last_progress = now  # also after a failure: the next try is a second on
        budget = self.ctx.run_max_s
        if budget is not None and now - self.started > budget:
            if snap.sample > self.version_sample:
                self._persist(snap)  # what it learnt is kept; a resume continues from it
            raise StopRun(
                RunStatus.FAILED,
                f"the run exceeded its wall-clock budget of {budget:g} s (MAPWISE_RUN_MAX_S) "
                f"at sample {snap.sample} of {self.results.n}",
            )
        if now - self.last_stop_check < self.ctx.cancel_poll_s:
            return
        self.last_stop_check = now
        request = self.attempt.stop_request()
        if request is None:
            return
        if snap.sample > self.version_sample:
            self._persist(snap)
        if request == "cancel":
            raise StopRun(RunStatus.CANCELLED, None)
        raise StopRun(RunStatus.INTERRUPTED, "the server was stopped while the run was executing")

    def _sleep_until(self, target: float, snap: Snapshot) -> None:
        """Wait for the pace clock, waking for the stop check and, while samples wait to be
        shown, at the moment the next live frame is allowed (so frames come at live_fps)."""
        assert self.results is not None
        while True:
            now = time.monotonic()
            remaining = target - now
            if remaining <= 0:
                return
            wake = min(remaining, self.ctx.cancel_poll_s)
            if snap.sample > self.live.sample:
                wake = min(wake, max(self.live.next_tick - now, 0.0))
            time.sleep(wake)
            self.live.tick(snap, self.results)
            self._check_stop(snap)

    # -- persistence --------------------------------------------------------------------------

    def _version_fields(self, snap: Snapshot, *, final: bool) -> dict[str, Any]:
        results = self.results
        assert results is not None
        table = snap.table
        variances = None
        if table is not None and snap.variance is not None:
            variances = np.asarray(snap.variance, dtype=np.float64).reshape(table.shape)
        return {
            "run_id": self.run_id,
            "step": snap.sample,
            "time_s": snap.time_s,
            "final": final,
            "axes": None if table is None else [a.to_dict() for a in table.axes],
            "values": None if table is None else np.asarray(table.values, dtype=np.float64),
            "variances": variances,
            "visits": results.visits,
            "cell_rejections": results.cell_rejections,
            "state": blobs.pack_state(snap.state.to_dict()),
            "segment": results.segment(self.version_sample, snap.sample),
            "rejected": snap.rejected,
        }

    def _persist(self, snap: Snapshot) -> None:
        assert self.results is not None
        fields = self._version_fields(snap, final=False)
        self.attempt.add_version(
            fields,
            progress=snap.sample / self.results.n,
            rejected=self.results.run_rejected(),
        )
        self.version_sample = snap.sample
        self.last_progress = time.monotonic()

    def _complete(self, snap: Snapshot, run_s: float) -> None:
        results = self.results
        assert results is not None
        metrics = results.metrics(snap, run_s)
        if self.raster_s is not None:
            metrics["raster_s"] = self.raster_s
        self.attempt.complete(
            self._version_fields(snap, final=True),
            metrics=metrics,
            series=results.series(self.ctx.series_points),
            rejected=results.run_rejected(),
        )
        self.version_sample = snap.sample
        time.sleep(max(0.0, self.live.next_tick - time.monotonic()))  # the final frame too
        self.live.tick(snap, results, force=True, metrics=metrics)  # keeps to live_fps
        self._status(RunStatus.SUCCEEDED, None)
