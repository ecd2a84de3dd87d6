"""The live ticks' map budget: a big map rides on a tick only within ``LIVE_CELLS_PER_S``
cells a second, other ticks still carry the series and progress, the final tick always has
the map, and the hub keeps the last map for a full frame."""

from __future__ import annotations

from typing import Any

import numpy as np

from app.domain import Series, SeriesRole
from app.runs.hub import LiveHub
from app.runs.live import LIVE_CELLS_PER_S, LIVE_POINTS_PER_TICK, LiveTicks
from app.store.log_rows import MemoryRows
from estimation.estimator import Snapshot
from estimation.signals import Signals
from estimation.table import Axis, Table

N = 300  # a 300 × 300 map: 90 000 cells
SAMPLES = 2000
STEP_S = 0.01  # log time between two samples
CHUNK_S = 0.03  # fake wall time between two chunks of 10 samples: a tick every other chunk


class FakeResults:
    """What :meth:`LiveTicks.tick` reads of a run's results, over a fixed log."""

    def __init__(self) -> None:
        t = STEP_S * np.arange(SAMPLES)
        self.signals = Signals(t, {"u1": np.linspace(0, 1, SAMPLES), "u2": np.zeros(SAMPLES)})
        self.log = MemoryRows(self.signals)
        self.n = SAMPLES
        self.visits = np.zeros((N, N))
        self.residual = np.sin(t)

    def lines(self, start: int = 0, stop: int | None = None) -> list[Series]:
        time, residual = self.signals.time[start:stop], self.residual[start:stop]
        return [Series("residual", "", time, residual, SeriesRole.OUTPUT)]

    def live_rmse(self) -> float | None:
        return 0.5

    def active_cell(self, z: int) -> list[int] | None:
        return [0, 0]

    def run_rejected(self) -> dict[str, int]:
        return {}


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _snap(sample: int, table: Table) -> Snapshot:
    return Snapshot(
        estimator="rls",
        sample=sample,
        n_samples=SAMPLES,
        time_s=sample * STEP_S,
        state=None,
        chunk_start=max(sample - 10, 0),
        table=table,
        variance=np.full(table.size, 2.0),
    )


def test_big_map_rides_on_ticks_within_the_cells_per_second_budget() -> None:
    axes = [Axis("u1", "", np.linspace(0, 1, N)), Axis("u2", "", np.linspace(0, 1, N))]
    results = FakeResults()
    clock = Clock()
    sent: list[dict[str, Any]] = []
    live = LiveTicks(7, live_fps=20.0, publish=sent.append, clock=clock)
    hub = LiveHub()
    start = clock.now
    last_table = None
    for k, sample in enumerate(range(10, SAMPLES, 10)):
        clock.now = start + k * CHUNK_S
        last_table = Table(axes, float(sample))  # every cell shows which tick made it
        live.tick(_snap(sample, last_table), results)  # type: ignore[arg-type]
    elapsed = clock.now - start
    assert last_table is not None
    live.tick(_snap(SAMPLES, last_table), results, force=True)  # type: ignore[arg-type]
    for message in sent:
        hub.handle(message)

    ticks = sent[:-1]
    with_map = [m for m in ticks if m["values"] is not None]
    without = [m for m in ticks if m["values"] is None]
    cells = N * N
    # ~6 s of fake wall time, a tick every 0.06 s: ~100 ticks, of which the budget allows a
    # map on at most one every cells / LIVE_CELLS_PER_S seconds (the first at once).
    assert len(ticks) > 80
    assert len(with_map) <= elapsed * LIVE_CELLS_PER_S / cells + 1
    assert len(with_map) >= 2
    assert len(without) > 60
    for m in without:
        assert m["variances"] is None
        assert m["visits"] is None
        assert m["series"]["residual"]["values"]  # the samples still flow
        assert 0 < m["progress"] <= 1
    for m in with_map:
        assert len(m["values"]) == N
        assert m["variances"][0][0] == 2.0
        assert len(m["visits"]) == N
    map_times = [start + (m["sample"] // 10 - 1) * CHUNK_S for m in with_map]
    gaps = np.diff(map_times)
    assert np.all(gaps >= cells / LIVE_CELLS_PER_S - 1e-9)

    final = sent[-1]
    assert final["values"] is not None
    assert final["values"][0][0] == float(last_table.values[0, 0])

    # The hub keeps the latest map across map-less ticks, so a new viewer's full frame has it.
    hub2 = LiveHub()
    for message in sent[:-1]:
        hub2.handle(message)
    state = hub2.state(7)
    assert state is not None
    assert sent[-2]["values"] is None  # the last live tick carried no map ...
    assert state.values is not None  # ... yet the state still holds the last one sent
    assert state.values[0][0] == with_map[-1]["values"][0][0]
    assert state.sample == sent[-2]["sample"]
    final_state = hub.state(7)
    assert final_state is not None
    assert final_state.values[0][0] == final["values"][0][0]


def test_small_map_rides_on_every_tick() -> None:
    axes = [Axis("u1", "", np.linspace(0, 1, 20)), Axis("u2", "", np.linspace(0, 1, 20))]
    results = FakeResults()
    results.visits = np.zeros((20, 20))
    clock = Clock()
    sent: list[dict[str, Any]] = []
    live = LiveTicks(1, live_fps=20.0, publish=sent.append, clock=clock)
    for sample in range(10, 1000, 10):
        clock.now += 0.06  # past one tick period (1/20 s)
        live.tick(_snap(sample, Table(axes, 1.0)), results)  # type: ignore[arg-type]
    assert len(sent) > 90
    assert all(m["values"] is not None for m in sent)


def test_a_tick_keeps_a_one_sample_spike_of_its_window() -> None:
    """A tick covering more samples than it carries keeps each bucket's extremes: a spike
    of one sample shows on the live plot while the run goes, not only once it is stored."""
    axes = [Axis("u1", "", np.linspace(0, 1, 5)), Axis("u2", "", np.linspace(0, 1, 5))]
    results = FakeResults()
    results.visits = np.zeros((5, 5))
    results.residual = np.zeros(SAMPLES)
    results.residual[1234] = 64.7
    sent: list[dict[str, Any]] = []
    live = LiveTicks(3, live_fps=20.0, publish=sent.append, clock=Clock())
    live.tick(_snap(SAMPLES, Table(axes, 1.0)), results, force=True)  # type: ignore[arg-type]
    line = sent[-1]["series"]["residual"]
    assert len(line["values"]) <= LIVE_POINTS_PER_TICK < SAMPLES
    assert max(line["values"]) == 64.7
    assert line["time"] == sorted(line["time"])
