"""The interface every estimator implements, and the base class that implements most of it.

An estimator is built from a typed config (a pydantic model whose JSON schema the dashboard
renders as a form), declares the channels it needs, and ``run``s over a :class:`Signals`
block in compiled chunks, yielding a :class:`Snapshot` after each chunk. Its state is
explicit and serialisable: ``run(..., state=snapshot.state)`` resumes to a result identical
to an uninterrupted run. :class:`ChunkedEstimator` holds that loop once; the registry of
estimators by name is :mod:`estimation.registry`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, ClassVar, Generic, Protocol, TypeVar

import numpy as np
from pydantic import BaseModel, ValidationError

from estimation.errors import ConfigError, ShapeError, StateError
from estimation.signals import Signals
from estimation.state import EstimatorState
from estimation.table import Grid, Table


@dataclass(frozen=True, slots=True, eq=False)
class Snapshot:
    """What an estimator reports between chunks.

    ``sample`` counts the log samples consumed so far (of ``n_samples``); ``chunk_start`` is
    the first log sample of the chunk that just ran, and ``outputs`` hold per-sample series
    for that chunk (e.g. ``prediction`` and ``residual`` of the table output, in its unit),
    with ``status`` (0 accepted, 1 rejected by the accept mask, 2 by the innovation gate,
    3 not usable: before the sensor delay is filled).
    """

    estimator: str
    sample: int
    n_samples: int
    time_s: float
    state: Any
    chunk_start: int
    table: Table | None = None
    variance: np.ndarray | None = None
    outputs: dict[str, np.ndarray] = field(default_factory=dict)
    status: np.ndarray | None = None
    rejected: dict[str, int] = field(default_factory=dict)
    metrics: dict[str, float] = field(default_factory=dict)

    @property
    def done(self) -> bool:
        return self.sample >= self.n_samples


class Estimator(Protocol):
    """What the service, the CLI and the benchmarks rely on."""

    name: str
    config: BaseModel

    def required_signals(self) -> list[str]: ...

    def signal_roles(self) -> dict[str, list[str]]: ...

    def run(
        self,
        signals: Signals,
        *,
        every: int | None = None,
        state: Any = None,
        accept: np.ndarray | None = None,
    ) -> Iterator[Snapshot]: ...

    def fit(self, signals: Signals, *, accept: np.ndarray | None = None) -> Snapshot: ...


#: Kernel steps a window of :meth:`ChunkedEstimator.run_windows` holds (rounded to whole
#: chunks): its rows are the most of the log a streamed run has in memory at once.
WINDOW_STEPS = 1 << 18


@dataclass(frozen=True, slots=True)
class LogWindows:
    """A log of ``n`` samples that :meth:`ChunkedEstimator.run_windows` never holds whole:
    ``read(a, z)`` gives its rows ``a … z−1``, ``timeline()`` its time column, ``accept`` the
    ``(n,)`` mask of the samples the estimator may learn from (``None``: all), and ``window``
    the rows a pass over it reads at a time."""

    n: int
    read: Callable[[int, int], Signals]
    timeline: Callable[[], np.ndarray]
    accept: np.ndarray | None
    window: int = WINDOW_STEPS

    @classmethod
    def over(
        cls,
        read: Callable[[int, int], Signals],
        n: int,
        *,
        timeline: Callable[[], np.ndarray] | None = None,
        accept: np.ndarray | None = None,
        window: int = WINDOW_STEPS,
    ) -> LogWindows:
        """The log ``read`` gives; without ``timeline`` its time column is ``read(0, n)``'s
        (the log read whole once, if a plan asks for it)."""
        return cls(n, read, timeline or (lambda: read(0, n).time), accept, window)


@dataclass(frozen=True, slots=True)
class WindowPlan:
    """How :meth:`ChunkedEstimator.run_windows` reads a log: ``steps`` kernel steps in all,
    each window with ``extra_rows`` rows after its last step (a sensor delay's) and
    ``rows_before`` before its first (a backward difference's, where the log has them), and
    the whole-log ``context`` each window is prepared with (resolved settings, sample period,
    a gain design)."""

    steps: int
    extra_rows: int
    context: Any
    rows_before: int = 0


@dataclass(frozen=True, slots=True, eq=False)
class Chunk:
    """Log samples ``first:sample`` just run, and their per-sample ``outputs``."""

    first: int
    sample: int
    outputs: dict[str, np.ndarray]


S = TypeVar("S", bound=EstimatorState)
P = TypeVar("P")


class ChunkedEstimator(ABC, Generic[S, P]):
    """The chunked run loop, ``fit`` and the state check every estimator shares.

    A subclass turns a log into kernel inputs once (:meth:`prepare`), says how many kernel
    steps the log has (:meth:`steps`), makes the first state (:meth:`start`), advances a
    state over one chunk (:meth:`advance`) and adds its part to each snapshot
    (:meth:`report`); it checks whatever else a resumed state must satisfy in
    :meth:`check_fit`.
    """

    name: str
    config: BaseModel
    state_class: type[S]
    grid: Grid | None = None  # the map's grid, when the state's ``theta`` holds its values
    noun: str = "estimator"  # in messages: "state of a 'kf' filter cannot resume 'skf'"
    windowed: ClassVar[bool] = False  # plans and prepares windows: run_windows streams a log

    @abstractmethod
    def required_signals(self) -> list[str]:
        """Every channel the estimator reads."""

    @abstractmethod
    def signal_roles(self) -> dict[str, list[str]]:
        """The channels it reads by role: ``axis``, ``output``, ``input``."""

    @abstractmethod
    def output_names(self) -> tuple[str, ...]:
        """The per-sample series of every snapshot's ``outputs``."""

    @abstractmethod
    def prepare(self, signals: Signals, accept: np.ndarray | None = None) -> P:
        """Validate the log (and accept mask) and turn it into kernel inputs."""

    @abstractmethod
    def steps(self, prepared: P) -> int:
        """Kernel steps in the prepared log (where ``state.step`` ends)."""

    @abstractmethod
    def start(self, signals: Signals, prepared: P) -> S:
        """The state before the first step."""

    @abstractmethod
    def advance(self, state: S, prepared: P, stop: int) -> tuple[S, dict[str, np.ndarray], Any]:
        """Run steps ``state.step:stop``; return the new state, the chunk's outputs and
        per-sample status (as :meth:`snapshot` takes them). ``state`` is not modified."""

    @abstractmethod
    def times(self, prepared: P) -> np.ndarray:
        """The log's sample times [s]."""

    def n_samples(self, prepared: P) -> int:
        """Log samples in the whole log (a prepared window is part of it)."""
        return int(self.times(prepared).size)

    def time_of(self, prepared: P, sample: int) -> float:
        """The time [s] of the last of the first ``sample`` log samples (of the first, at 0)."""
        return float(self.times(prepared)[max(sample - 1, 0)])

    def log_sample(self, step: int, prepared: P) -> int:
        """Log samples accounted for after ``step`` kernel steps (more when a step pairs a
        measurement with an earlier operating point)."""
        return step

    def report(self, state: S, prepared: P, chunk: Chunk) -> dict[str, Any]:
        """The family's part of the snapshot after ``chunk``: ``outputs``, and ``table``,
        ``variance``, ``rejected``, ``metrics`` as it has them."""
        return {"outputs": chunk.outputs}

    def snapshot(
        self, state: S, prepared: P, start: int, outputs: dict[str, np.ndarray], status: Any
    ) -> Snapshot:
        """The report after the chunk that began at step ``start`` and ended at ``state``."""
        first = self.log_sample(start, prepared)
        sample = self.log_sample(state.step, prepared)
        return Snapshot(
            estimator=self.name,
            sample=sample,
            n_samples=self.n_samples(prepared),
            time_s=self.time_of(prepared, sample),
            state=state,
            chunk_start=first,
            status=status,
            **self.report(state, prepared, Chunk(first, sample, outputs)),
        )

    def check_fit(self, state: S) -> None:
        """Raise :class:`StateError` if ``state`` does not fit this estimator's shapes."""

    def check_state(self, state: Any, steps: int) -> None:
        """``state`` must be this estimator's class and kind, fit it, and be within the log."""
        if not isinstance(state, self.state_class):
            raise StateError(f"{self.name} cannot resume from a {type(state).__name__}")
        if state.kind != self.name:
            raise StateError(f"state of a {state.kind!r} {self.noun} cannot resume {self.name!r}")
        theta = getattr(state, "theta", None)
        if self.grid is not None and theta is not None and theta.size != self.grid.size:
            raise StateError(f"state has {theta.size} cells, the table {self.grid.size}")
        self.check_fit(state)
        if not 0 <= state.step <= steps:
            raise StateError(f"state is at step {state.step}, the log has {steps} steps")

    def run(
        self,
        signals: Signals,
        *,
        every: int | None = None,
        state: S | None = None,
        accept: np.ndarray | None = None,
    ) -> Iterator[Snapshot]:
        """Run over the whole log in chunks of ``every`` steps, yielding a snapshot after each.

        ``state`` (from a snapshot, or the state class's ``from_dict``/``load``) resumes where
        it stopped, to a result identical to an uninterrupted run; a finished state yields
        one snapshot without outputs.
        """
        prepared = self.prepare(signals, accept)
        steps = self.steps(prepared)
        if state is None:
            state = self.start(signals, prepared)
        self.check_state(state, steps)
        chunk = steps if every is None else int(every)
        if chunk < 1:
            raise ConfigError(f"every must be >= 1 sample, got {every}")
        if state.step == steps:
            yield self.snapshot(state, prepared, steps, {}, np.empty(0, np.int8))
            return
        while state.step < steps:
            start = state.step
            state, outputs, status = self.advance(state, prepared, min(start + chunk, steps))
            yield self.snapshot(state, prepared, start, outputs, status)

    def plan_windows(self, log: LogWindows) -> WindowPlan:
        """The :class:`WindowPlan` of ``log``: ``log.timeline()`` is read only if the plan
        needs the time column, ``log.read`` for a plan that takes more of the whole log (a
        pass ``log.window`` rows at a time). An estimator that sets ``windowed`` says how."""
        raise NotImplementedError(f"{self.name} reads its log whole")

    def prepare_window(
        self, signals: Signals, accept: np.ndarray | None, offset: int, n: int, context: Any
    ) -> P:
        """:meth:`prepare` for rows ``offset …`` of a log of ``n`` samples, with the plan's
        ``context``: ``signals`` start ``min(rows_before, offset)`` rows earlier, and
        ``accept`` is the mask of its rows."""
        raise NotImplementedError(f"{self.name} reads its log whole")

    def run_windows(
        self,
        read: Callable[[int, int], Signals],
        n: int,
        *,
        every: int,
        state: S | None = None,
        window: int = WINDOW_STEPS,
        timeline: Callable[[], np.ndarray] | None = None,
        accept: np.ndarray | None = None,
    ) -> Iterator[Snapshot]:
        """:meth:`run` over a log of ``n`` samples that is never held whole.

        ``read(a, z)`` gives the log's rows ``a … z−1`` (its time and the channels the
        estimator reads). The estimator reads ``window`` kernel steps at a time, rounded up to
        whole chunks of ``every`` steps counted from where the run starts (a resumed run reads
        from its state's step on), each window with the plan's extra rows after it (a sensor
        delay's). The kernel carries its state across windows as across chunks, so snapshots,
        states and outputs are :meth:`run`'s bit for bit (``tests/estimation/
        test_run_windows.py``). What a window needs of the whole log comes from the plan
        (:meth:`plan_windows`): ``timeline()`` gives the time column (default: ``read(0,
        n).time``, the log read whole once). ``accept`` is :meth:`run`'s ``(n,)`` mask of the
        samples the estimator may learn from (a byte a sample).
        """
        chunk = int(every)
        if chunk < 1:
            raise ConfigError(f"every must be >= 1 sample, got {every}")
        if accept is not None and np.shape(accept) != (n,):
            raise ShapeError(f"accept mask has shape {np.shape(accept)}, the log has {n} samples")
        plan = self.plan_windows(
            LogWindows.over(read, n, timeline=timeline, accept=accept, window=window)
        )
        steps = plan.steps
        span = max(1, -(-window // chunk)) * chunk

        def prepared(a: int, z: int) -> tuple[Signals, P]:
            first, end = max(a - plan.rows_before, 0), min(z + plan.extra_rows, n)
            mask = None if accept is None else accept[first:end]
            rows = read(first, end)
            return rows, self.prepare_window(rows, mask, a, n, plan.context)

        if state is None:
            state = self.start(*prepared(0, min(span, steps)))
        self.check_state(state, steps)
        if state.step == steps:
            last = prepared(max(steps - 1, 0), steps)[1]
            yield self.snapshot(state, last, steps, {}, np.empty(0, np.int8))
            return
        while state.step < steps:
            part = prepared(state.step, min(state.step + span, steps))[1]
            end = self.steps(part)
            if end <= state.step:  # a plan and a window that disagree would loop forever
                raise RuntimeError(f"{self.name}: the window at step {state.step} ends at {end}")
            while state.step < end:
                start = state.step
                state, outputs, status = self.advance(state, part, min(start + chunk, end))
                yield self.snapshot(state, part, start, outputs, status)

    def fit(self, signals: Signals, *, accept: np.ndarray | None = None) -> Snapshot:
        """Run over the whole log in one chunk and return the final snapshot."""
        last = None
        for last in self.run(signals, accept=accept):  # noqa: B007
            pass
        assert last is not None
        return last


def describe_validation_error(exc: ValidationError) -> str:
    """One line per problem: ``field.path: message``."""
    parts = []
    for err in exc.errors():
        message = err["msg"].removeprefix("Value error, ")
        loc = ".".join(str(p) for p in err["loc"])
        parts.append(f"{loc}: {message}" if loc else message)
    return "; ".join(parts)
