"""One run, executed in a worker process (or in-process): estimator chunks, versions, live ticks.

The worker reads everything it needs from the database (the run, its dataset's payload, the
last persisted version when resuming) and writes its results there, so it can run in any
process sharing the database. Per chunk it folds the estimator's snapshot into per-sample
output arrays and per-cell visit counts, persists a map version at the run's cadence (with
the estimator state, so a resumed run continues bit-for-bit), publishes a live tick at most
``live_fps`` times a second (never waiting for anyone), and checks for a stop request.

Live messages (``publish``): ``{"kind": "start" | "tick" | "status", "run_id", ...}``.
"""

from __future__ import annotations

import contextlib
import math
import os
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np
from sqlalchemy.orm import Session

from app.db.engine import Database
from app.db.repositories import DatasetRepo, MetricRepo, RunRepo, VersionRepo
from app.domain import Dataset, ResumePoint, Run, Series
from app.errors import DatabaseUnavailableError, SupersededError
from app.runs.states import dump_state, load_state
from app.services.datasets import Truth, unpack_signals, unpack_truth
from app.services.decimate import finite_or_none, nested_or_none, stride_decimate
from app.services.run_plan import run_options
from estimation.errors import EstimationError
from estimation.estimator import Snapshot, get_spec
from estimation.metrics import map_metrics, output_metrics
from estimation.signals import Signals
from estimation.table import Table

Publish = Callable[[dict[str, Any]], None]
T = TypeVar("T")
LIVE_POINTS_PER_TICK = 100
PROGRESS_EVERY_S = 1.0
DB_RETRY_S = 60.0  # how long a run waits for its database to come back before failing
STATUS_ACCEPTED = 0
# Snapshot status codes that count against a cell, by name (see estimation.estimator.Snapshot;
# code 1, the accept mask, is counted by the gate that set it).
CELL_STATUS = {"innovation": 2, "delay": 3}


@dataclass(frozen=True, slots=True)
class WorkerContext:
    """What a worker needs besides the run id; picklable except for ``publish``."""

    database_url: str
    live_fps: float = 20.0
    series_points: int = 4000
    cancel_poll_s: float = 0.2
    version_fraction: float = 0.1
    parent_pid: int | None = None  # exit when this process is gone (orphaned by kill -9)
    owner: str = "local"  # the executor whose attempt this is (runs.owner)
    heartbeat_s: float = 2.0  # an executing attempt proves it lives this often
    take_over: bool = False  # claim a run left running by a dead attempt (a Dask retry)


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


class StopRun(Exception):  # noqa: N818 - control flow, not an error
    def __init__(self, status: str, error: str | None) -> None:
        super().__init__(status)
        self.status = status
        self.error = error


_databases: dict[str, Database] = {}


def database(url: str) -> Database:
    if url not in _databases:
        _databases[url] = Database(url)
    return _databases[url]


# --- process-pool plumbing -------------------------------------------------------------------

_pool_context: WorkerContext | None = None
_pool_publish: Publish | None = None


def init_pool_worker(context: WorkerContext, queue: Any) -> None:
    """Pool initializer: remember the context, die with the server, publish to ``queue``."""
    global _pool_context, _pool_publish
    _pool_context = context
    _set_parent_death_signal()

    def publish(message: dict[str, Any]) -> None:
        with contextlib.suppress(Exception):  # a full queue drops the frame, never blocks
            queue.put_nowait(message)

    _pool_publish = publish
    if context.parent_pid is not None:
        threading.Thread(target=_watch_parent, args=(context.parent_pid,), daemon=True).start()


def _set_parent_death_signal() -> None:
    """Linux: SIGKILL this worker when the server process dies (``kill -9`` included)."""
    try:
        import ctypes
        import signal

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _watch_parent(parent_pid: int) -> None:
    while True:
        if os.getppid() != parent_pid:
            os._exit(70)
        time.sleep(0.1)


def execute_in_pool(run_id: int) -> str:
    assert _pool_context is not None, "pool not initialised"
    assert _pool_publish is not None
    return execute_run(run_id, _pool_context, _pool_publish)


def warm_up() -> int:
    """Makes the pool start its processes now, and loads the compiled kernels of the table
    filters (numba's cache) so the first run does not wait for them."""
    from estimation.estimator import get_spec

    u = np.array([0.0, 0.5, 1.0, 0.25])
    signals = Signals(np.arange(4.0), {"u": u, "y": u})
    config = {"axes": [{"name": "u", "breakpoints": [0.0, 1.0]}], "output": "y"}
    for name in ("kf", "skf", "sskf", "rls", "nlms"):
        get_spec(name).build(config).fit(signals)  # type: ignore[attr-defined]
    return os.getpid()


# --- the run ---------------------------------------------------------------------------------


def execute_run(run_id: int, context: WorkerContext, publish: Publish | None = None) -> str:
    """Execute one queued run to a final status; returns that status (or ``"skipped"``)."""
    return RunSession(run_id, context, publish or (lambda _m: None)).execute()


@dataclass
class _Progress:
    last_db_write: float = 0.0
    last_stop_check: float = 0.0
    next_tick: float = 0.0
    tick_sample: int = 0
    seq: int = 0
    version_sample: int = 0  # first sample not yet in a persisted segment
    sq_sum: float = 0.0  # running Σ residual² over accepted samples
    sq_n: int = 0
    rejected: dict[str, int] = field(default_factory=dict)


class RunSession:
    def __init__(self, run_id: int, context: WorkerContext, publish: Publish) -> None:
        self.run_id = run_id
        self.ctx = context
        self.publish = publish
        self.db = database(context.database_url)
        self.p = _Progress()

    # -- lifecycle ----------------------------------------------------------------------------

    def execute(self) -> str:
        statuses = ("queued", "running") if self.ctx.take_over else ("queued",)
        with self.db.write() as s:
            attempt = RunRepo(s).claim(self.run_id, owner=self.ctx.owner, statuses=statuses)
        if attempt is None:
            return "skipped"  # finished, cancelled or taken by another attempt meanwhile
        self.attempt = attempt
        heartbeat = Heartbeat(self.db, self.run_id, attempt, self.ctx.heartbeat_s)
        heartbeat.start()
        try:
            self._status("running", None)
            return self._execute()
        except SupersededError:
            return "superseded"  # a newer attempt owns the run: write nothing more
        finally:
            heartbeat.stop()

    def _execute(self) -> str:
        try:
            self._prepare()
            self._loop()
            return "succeeded"
        except StopRun as stop:
            self._finish(stop.status, stop.error)
            return stop.status
        except SupersededError:
            raise
        except Exception as exc:  # any failure is the run's, stored with it
            message = " ".join(f"{type(exc).__name__}: {exc}".split())
            if hasattr(exc, "message"):
                message = " ".join(str(exc).split())
            self._finish("failed", message)
            return "failed"

    @contextlib.contextmanager
    def _write(self) -> Iterator[Session]:
        """A write transaction of this attempt: fenced by its number (see RunRepo.fence)."""
        with self.db.write() as s:
            RunRepo(s).fence(self.run_id, self.attempt)
            yield s

    def _finish(self, status: str, error: str | None) -> None:
        def write() -> None:
            with self._write() as s:
                RunRepo(s).set_status(
                    self.run_id, status, only_if=("running",), error=error, finished=True
                )

        self._durably(write)
        self._status(status, error)

    def _durably(
        self, write: Callable[[], T], stored: Callable[[], bool] | None = None
    ) -> T | None:
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

    def _has_version(self, step: int) -> bool:
        with self.db.read() as s:
            return VersionRepo(s).has_step(self.run_id, step)

    def _status(self, status: str, error: str | None) -> None:
        progress = self.p.version_sample / self.n if getattr(self, "n", 0) else 0.0
        self.publish(
            {
                "kind": "status",
                "run_id": self.run_id,
                "status": status,
                "error": error,
                "progress": progress,
            }
        )

    # -- preparation ----------------------------------------------------------------------------

    def _prepare(self) -> None:
        loaded = self._durably(self._load)
        assert loaded is not None
        self._set_up(*loaded)

    def _load(self) -> tuple[bytes, bytes | None]:
        """The run, its dataset's payload and truth, and where to resume from."""
        with self.db.read() as s:
            self.run: Run = RunRepo(s).get(self.run_id)
            datasets = DatasetRepo(s)
            self.dataset: Dataset = datasets.get(self.run.dataset_id)
            payload = datasets.payload(self.run.dataset_id)
            truth_blob = datasets.truth(self.run.dataset_id)
            self.resume: ResumePoint | None = VersionRepo(s).resume_point(self.run_id)
        return payload, truth_blob

    def _set_up(self, payload: bytes, truth_blob: bytes | None) -> None:
        self.signals: Signals = unpack_signals(payload, self.dataset.channels)
        self.truth: Truth | None = None if truth_blob is None else unpack_truth(truth_blob)
        self.n = len(self.signals)
        self.options = run_options(
            self.run.config, self.n, self.dataset.rate_hz, self.ctx.version_fraction
        )
        self.estimator = get_spec(self.run.estimator).build(self.run.estimator_config)
        self._prepare_gates()
        self.outputs: dict[str, np.ndarray] = {}
        self.status = np.full(self.n, -1, dtype=np.int8)
        self.grid: Table | None = None
        self.visits: np.ndarray | None = None
        self.cell_rejections: dict[str, np.ndarray] = {}
        self.state: Any = None
        if self.resume is not None:
            self._restore(self.resume)

        def forget_later_versions() -> None:
            with self._write() as s:
                VersionRepo(s).delete_after(self.run_id, self.p.version_sample)

        self._durably(forget_later_versions)

    def _prepare_gates(self) -> None:
        self.accept: np.ndarray | None = None
        self.gate_result: Any = None
        if not self.options.gates:
            return
        from app.services.gates import apply_gates, parse_gates

        gates = parse_gates(self.options.gates, self.signals.names, field="config.gates")
        self.gate_result = apply_gates(gates, self.signals)
        self.accept = self.gate_result.accept

    def _restore(self, point: ResumePoint) -> None:
        self.state = load_state(point.state)
        self.p.version_sample = point.step
        self.p.tick_sample = point.step
        start = 0
        for segment in point.segments:
            status = segment["__status__"]
            stop = start + status.size
            self.status[start:stop] = status
            for name, values in segment.items():
                if name != "__status__":
                    self._output(name)[start:stop] = values
            start = stop
        if start != point.step:
            raise RuntimeError(f"persisted segments cover {start} samples, version {point.step}")
        self.visits = point.visits
        self.cell_rejections = dict(point.cell_rejections)
        residual = self.outputs.get("residual")
        if residual is not None:
            ok = (self.status[:start] == STATUS_ACCEPTED) & np.isfinite(residual[:start])
            self.p.sq_sum = float(np.sum(residual[:start][ok] ** 2))
            self.p.sq_n = int(ok.sum())

    def _output(self, name: str) -> np.ndarray:
        if name not in self.outputs:
            self.outputs[name] = np.full(self.n, np.nan)
        return self.outputs[name]

    def _chunk_size(self) -> int:
        """Samples per estimator chunk: one live frame's worth when paced, else ~1 % of the
        log; a divisor of the version cadence when one is near, so versions land on it."""
        if self.options.pace is not None:
            # Half a frame interval of log per chunk: every frame interval then has new
            # samples, so the tick limiter (not the chunking) sets the rate: live_fps.
            per_frame = self.dataset.rate_hz * self.options.pace / (2.0 * self.ctx.live_fps)
            desired = max(1, int(per_frame))
        else:
            desired = min(20_000, max(256, self.n // 100))
        every = self.options.version_every
        if desired >= every:
            return every
        k_max = every // desired  # chunks per version, each at least `desired` long
        for k in range(k_max, max(1, k_max // 2) - 1, -1):
            if every % k == 0:
                return every // k
        return math.ceil(every / k_max)

    # -- the loop -------------------------------------------------------------------------------

    def _loop(self) -> None:
        every = self.options.version_every
        start_sample = self.p.version_sample
        next_version = (start_sample // every + 1) * every
        wall0, t0 = 0.0, 0.0  # the pace clock starts after the first chunk (JIT loading)
        started = False
        t_run = time.perf_counter()
        last: Snapshot | None = None
        for snap in self.estimator.run(
            self.signals, every=self._chunk_size(), state=self.state, accept=self.accept
        ):
            last = snap
            self._absorb(snap)
            if not started:
                self._publish_start(snap)
                started = True
                wall0, t0 = time.monotonic(), snap.time_s
            if snap.done:
                break
            if snap.sample >= next_version:
                self._persist(snap, final=False)
                next_version = (snap.sample // every + 1) * every
            self._tick(snap)
            self._check_stop(snap)
            if self.options.pace is not None:
                target = wall0 + (snap.time_s - t0) / self.options.pace
                self._sleep_until(target, snap)
        assert last is not None
        run_s = time.perf_counter() - t_run
        self._complete(last, run_s)

    def _absorb(self, snap: Snapshot) -> None:
        a, z = snap.chunk_start, snap.sample
        if snap.status is not None and snap.status.size == z - a:
            self.status[a:z] = snap.status
        else:
            self.status[a:z] = STATUS_ACCEPTED
        for name, values in snap.outputs.items():
            values = np.asarray(values, dtype=np.float64)
            if values.ndim == 1 and values.size == z - a:
                self._output(name)[a:z] = values
        self.p.rejected = {k: int(v) for k, v in snap.rejected.items()}
        if snap.table is not None:
            self._count_cells(snap.table, a, z)
        residual = snap.outputs.get("residual")
        if residual is not None and residual.size == z - a:
            ok = (self.status[a:z] == STATUS_ACCEPTED) & np.isfinite(residual)
            self.p.sq_sum += float(np.sum(np.asarray(residual)[ok] ** 2))
            self.p.sq_n += int(ok.sum())

    def _count_cells(self, table: Table, a: int, z: int) -> None:
        """Visits (interpolation weight of accepted samples) and rejections per cell."""
        if self.grid is None:
            names = [ax.name for ax in table.axes]
            if not all(name in self.signals for name in names):
                return
            self.grid = table
            self.idx, self.w = table.regressor(self.signals.stack(names))
            if self.visits is None:
                self.visits = np.zeros(table.shape)
        assert self.visits is not None
        idx, w, status = self.idx[a:z], self.w[a:z], self.status[a:z]
        size = self.grid.size
        ok = status == STATUS_ACCEPTED
        self.visits += np.bincount(idx[ok].ravel(), w[ok].ravel(), size).reshape(table.shape)
        masks = self._rejection_masks(a, z, status)
        for label, mask in masks.items():
            if not mask.any():
                self.cell_rejections.setdefault(label, np.zeros(table.shape))
                continue
            counts = np.bincount(idx[mask].ravel(), w[mask].ravel(), size).reshape(table.shape)
            self.cell_rejections[label] = self.cell_rejections.get(label, 0) + counts

    def _rejection_masks(self, a: int, z: int, status: np.ndarray) -> dict[str, np.ndarray]:
        masks = {name: status == code for name, code in CELL_STATUS.items()}
        if self.gate_result is not None:
            taken = np.zeros(z - a, dtype=bool)
            for label, gate_mask in self.gate_result.masks.items():
                mine = gate_mask[a:z] & ~taken  # attributed to the first gate rejecting it
                taken |= mine
                masks[label] = mine
        return masks

    def _check_stop(self, snap: Snapshot) -> None:
        now = time.monotonic()
        if now - self.p.last_db_write >= PROGRESS_EVERY_S:
            with contextlib.suppress(DatabaseUnavailableError), self._write() as s:
                RunRepo(s).progress(
                    self.run_id,
                    sample=snap.sample,
                    progress=snap.sample / self.n,
                    rejected=self._run_rejected(),
                )
            self.p.last_db_write = now  # also after a failure: the next try is a second on
        if now - self.p.last_stop_check < self.ctx.cancel_poll_s:
            return
        self.p.last_stop_check = now
        try:
            with self.db.read() as s:
                request = RunRepo(s).stop_request(self.run_id)
        except DatabaseUnavailableError:
            return  # asked again at the next check
        if request is None:
            return
        if snap.sample > self.p.version_sample:
            self._persist(snap, final=False)
        if request == "cancel":
            raise StopRun("cancelled", None)
        raise StopRun("interrupted", "the server was stopped while the run was executing")

    def _sleep_until(self, target: float, snap: Snapshot) -> None:
        """Wait for the pace clock, waking for the stop check and, while samples wait to be
        shown, at the moment the next live frame is allowed (so frames come at live_fps)."""
        while True:
            now = time.monotonic()
            remaining = target - now
            if remaining <= 0:
                return
            wake = min(remaining, self.ctx.cancel_poll_s)
            if snap.sample > self.p.tick_sample:
                wake = min(wake, max(self.p.next_tick - now, 0.0))
            time.sleep(wake)
            self._tick(snap)
            self._check_stop(snap)

    def _run_rejected(self) -> dict[str, int]:
        out = dict(self.p.rejected)
        if self.gate_result is not None:
            out |= {f"gate:{k}": int(v) for k, v in self.gate_result.rejected.items()}
        return out

    # -- persistence ----------------------------------------------------------------------------

    def _persist(self, snap: Snapshot, *, final: bool) -> None:
        a, z = self.p.version_sample, snap.sample
        segment = {name: values[a:z] for name, values in self.outputs.items()}
        segment["__status__"] = self.status[a:z]
        fields = self._version_fields(snap, final=final, segment=segment)

        def write() -> None:
            with self._write() as s:
                VersionRepo(s).add(**fields)
                RunRepo(s).progress(
                    self.run_id,
                    sample=snap.sample,
                    progress=snap.sample / self.n,
                    rejected=self._run_rejected(),
                )

        self._durably(write, stored=lambda: self._has_version(snap.sample))
        self.p.version_sample = z
        self.p.last_db_write = time.monotonic()

    def _version_fields(
        self, snap: Snapshot, *, final: bool, segment: dict[str, np.ndarray]
    ) -> dict[str, Any]:
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
            "visits": self.visits,
            "cell_rejections": self.cell_rejections,
            "state": dump_state(snap.state),
            "segment": segment,
            "rejected": snap.rejected,
        }

    def _complete(self, snap: Snapshot, run_s: float) -> None:
        metrics, series = self._results(snap, run_s)
        a, z = self.p.version_sample, snap.sample
        segment = {name: values[a:z] for name, values in self.outputs.items()}
        segment["__status__"] = self.status[a:z]
        fields = self._version_fields(snap, final=True, segment=segment)

        def write() -> None:
            with self._write() as s:
                VersionRepo(s).add(**fields)
                MetricRepo(s).replace(self.run_id, metrics, series)
                runs = RunRepo(s)
                runs.progress(
                    self.run_id, sample=snap.sample, progress=1.0, rejected=self._run_rejected()
                )
                runs.set_status(self.run_id, "succeeded", only_if=("running",), finished=True)

        self._durably(write, stored=lambda: self._has_version(snap.sample))
        self.p.version_sample = z
        time.sleep(max(0.0, self.p.next_tick - time.monotonic()))  # the final frame too
        self._tick(snap, force=True, metrics=metrics)  # keeps to live_fps
        self._status("succeeded", None)

    # -- results --------------------------------------------------------------------------------

    def _results(
        self, snap: Snapshot, run_s: float
    ) -> tuple[dict[str, float | None], list[Series]]:
        metrics: dict[str, float] = {"run_s": run_s}
        accepted = int(np.count_nonzero(self.status == STATUS_ACCEPTED))
        metrics["samples"] = float(self.n)
        metrics["accepted"] = float(accepted)
        residual = self.outputs.get("residual")
        if residual is not None:
            ok = (self.status == STATUS_ACCEPTED) & np.isfinite(residual)
            if ok.any():
                metrics["output_rmse"] = output_metrics(residual[ok])["rmse"]
        if snap.table is not None and self.visits is not None:
            metrics["coverage"] = float(np.mean(self.visits >= 1.0))
        if self.truth is not None:
            metrics |= self._truth_metrics(snap)
        return {k: _finite(v) for k, v in metrics.items()}, self._series()

    def _truth_metrics(self, snap: Snapshot) -> dict[str, float]:
        from app.scenario_run import series_metrics

        assert self.truth is not None
        data = self.truth.scenario_data(
            self.dataset.scenario or "", self.dataset.seed or 0, self.signals
        )
        out: dict[str, float] = {}
        table, true_map = snap.table, self.truth.true_map
        if table is not None and true_map is not None and table.shape == true_map.shape:
            same_grid = all(
                np.array_equal(a.breakpoints, b.breakpoints)
                for a, b in zip(table.axes, true_map.axes, strict=True)
            )
            if same_grid:
                out |= map_metrics(table, true_map, data.scoring_points())
                if data.scored_series:
                    out["map_rmse"] = out.pop("rmse")
        finite = {k: v for k, v in self.outputs.items() if np.all(np.isfinite(v))}
        # e.g. a log shorter than the torque scoring window: then there is no such metric
        with contextlib.suppress(EstimationError):
            out |= series_metrics(data, finite)
        return out

    def _series(self) -> list[Series]:
        index = stride_decimate(self.n, self.ctx.series_points)
        time_s = self.signals.time[index]
        out = [Series(name, unit, time_s, values[index]) for name, unit, values in self._lines()]
        return out

    def _lines(self) -> list[tuple[str, str, np.ndarray]]:
        """Every result line: operating-point channels, measured, outputs, truths, errors."""
        lines: list[tuple[str, str, np.ndarray]] = []
        units = self.signals.units
        for channel in self._operating_channels():
            lines.append((channel, units.get(channel, ""), self.signals[channel]))
        output = self.run.estimator_config.get("output")
        out_unit = self.run.estimator_config.get("output_unit", "")
        if isinstance(output, str) and output in self.signals:
            lines.append(("measured", units.get(output, ""), self.signals[output]))
        for name, values in self.outputs.items():
            unit = out_unit if name in ("prediction", "residual") else _unit_of_output(name)
            lines.append((name, unit, values))
        if self.truth is not None:
            for name, truth in self.truth.scored_series.items():
                if name in self.outputs:
                    unit = _unit_of_output(name)
                    lines.append((f"{name}_true", unit, truth))
                    lines.append((f"{name}_error", unit, truth - self.outputs[name]))
        return lines

    def _operating_channels(self) -> list[str]:
        table = self.run.table
        names = [a["name"] for a in table["axes"]] if table else list(self.run.signals.values())
        if not names and self.grid is not None:
            names = [a.name for a in self.grid.axes]
        seen: list[str] = []
        for name in names:
            if name in self.signals and name not in seen:
                seen.append(name)
        return seen

    # -- live -----------------------------------------------------------------------------------

    def _publish_start(self, snap: Snapshot) -> None:
        table = snap.table
        self.publish(
            {
                "kind": "start",
                "run_id": self.run_id,
                "axes": None if table is None else [a.to_dict() for a in table.axes],
                "n_samples": self.n,
                "trajectory_channels": [a.name for a in table.axes] if table is not None else [],
                "units": {name: unit for name, unit, _ in self._lines_units()},
            }
        )

    def _lines_units(self) -> list[tuple[str, str, None]]:
        return [(name, unit, None) for name, unit, _ in self._lines()]

    def _tick(
        self, snap: Snapshot, *, force: bool = False, metrics: dict[str, Any] | None = None
    ) -> None:
        now = time.monotonic()
        if not force and (now < self.p.next_tick or snap.sample <= self.p.tick_sample):
            return
        self.p.next_tick = now + 1.0 / self.ctx.live_fps  # never more than live_fps a second
        a, z = self.p.tick_sample, snap.sample
        self.p.tick_sample = z
        self.p.seq += 1
        index = a + stride_decimate(max(z - a, 0), LIVE_POINTS_PER_TICK)
        time_s = self.signals.time[index]
        table = snap.table
        trajectory: dict[str, Any] = {"time": [], "points": []}
        active = None
        if table is not None and all(ax.name in self.signals for ax in table.axes):
            points = self.signals.stack([ax.name for ax in table.axes])[index]
            trajectory = {"time": finite_or_none(time_s), "points": points.tolist()}
            if self.grid is not None and z > 0:
                k = z - 1
                flat = int(self.idx[k][int(np.argmax(self.w[k]))])
                active = [int(i) for i in np.unravel_index(flat, self.grid.shape)]
        series = {
            name: {"time": finite_or_none(time_s), "values": finite_or_none(values[index])}
            for name, _unit, values in self._lines()
        }
        live_metrics = dict(metrics or {})
        if self.p.sq_n:
            live_metrics.setdefault("output_rmse", math.sqrt(self.p.sq_sum / self.p.sq_n))
        variances = None
        if table is not None and snap.variance is not None:
            variances = np.asarray(snap.variance).reshape(table.shape)
        self.publish(
            {
                "kind": "tick",
                "run_id": self.run_id,
                "seq": self.p.seq,
                "sample": z,
                "n_samples": self.n,
                "progress": z / self.n,
                "time_s": snap.time_s,
                "emitted_at": time.time(),  # wall clock (s since epoch), for frame-delay figures
                "values": None if table is None else nested_or_none(table.values),
                "variances": nested_or_none(variances),
                "visits": nested_or_none(self.visits),
                "active_cell": active,
                "trajectory": trajectory,
                "series": series,
                "metrics": {k: _finite(v) for k, v in live_metrics.items()},
                "rejected": self._run_rejected(),
            }
        )


_OUTPUT_UNITS = {
    "torque_nm": "N·m",
    "w_c_kg_s": "kg/s",
    "maf_error_kg_s": "kg/s",
    "maf_bias_kg_s": "kg/s",
    "p_im_pa": "Pa",
    "p_em_pa": "Pa",
    "omega_t_rad_s": "rad/s",
}


def _unit_of_output(name: str) -> str:
    return _OUTPUT_UNITS.get(name, "")


def _finite(value: Any) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None
