"""A run's live messages: its start, at most ``live_fps`` ticks a second, its status.

Publishing never waits: a tick that is not due yet is skipped (its samples go into the next
one), and ``publish`` itself drops a message rather than block (a full queue).

The map (values, variances, visits) is what makes a tick big: it rides on a tick only while
``cells × map-bearing ticks a second ≤ LIVE_CELLS_PER_S``; other ticks carry ``None`` there
(the hub and the dashboard keep the last map). The final tick always carries it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from app.io.decimate import finite_or_none, minmax_decimate, nested_or_none, stride_decimate
from app.runs.frames import StartMessage, StatusFrame, TickMessage
from app.runs.results import RunResults
from app.runs.results import finite_or_none as finite_scalar
from estimation.estimator import Snapshot

Publish = Callable[[dict[str, Any]], None]
LIVE_POINTS_PER_TICK = 100
# Map cells sent per second per run, at most (each of values, variances and visits): a
# 250 000-cell map goes out every 1.25 s, a 20 × 20 map on every tick.
LIVE_CELLS_PER_S = 200_000
# Samples a tick shows at most: its last ones. A tick spans more only when the run goes
# faster than LIVE_SPAN × live_fps samples a second (5 M/s at 20 fps), or at the final tick
# of a run whose ticks were skipped; reading and decimating all of them would make the
# tick's memory grow with the log (the stored series keep every sample's extremes).
LIVE_SPAN = 1 << 18


class LiveTicks:
    """The live side of one run: what was shown (``sample``) and when the next tick is due."""

    def __init__(
        self,
        run_id: int,
        live_fps: float,
        publish: Publish,
        *,
        cells_per_s: float = LIVE_CELLS_PER_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.run_id, self.live_fps, self.publish = run_id, live_fps, publish
        self.cells_per_s, self.clock = cells_per_s, clock
        self.next_tick = 0.0  # monotonic time the next tick is allowed at
        self.next_map = 0.0  # monotonic time the next tick may carry the map at
        self.sample = 0  # first sample not yet shown
        self.seq = 0

    def start(self, snap: Snapshot, results: RunResults) -> None:
        table = snap.table
        lines = results.lines(0, 0)  # names, units and roles only
        self.publish(
            StartMessage(
                run_id=self.run_id,
                axes=None if table is None else [a.to_dict() for a in table.axes],
                n_samples=results.n,
                trajectory_channels=[] if table is None else [a.name for a in table.axes],
                units={x.name: x.unit for x in lines},
                roles={x.name: str(x.role) for x in lines},
            ).to_json()
        )

    def status(self, status: str, error: str | None, progress: float) -> None:
        frame = StatusFrame(run_id=self.run_id, status=status, error=error, progress=progress)
        self.publish(frame.to_message())

    def tick(
        self,
        snap: Snapshot,
        results: RunResults,
        *,
        force: bool = False,
        metrics: dict[str, Any] | None = None,
    ) -> None:
        """The samples since the last tick, the metrics and, when its budget allows (or on
        ``force``), the map: if due (or ``force``)."""
        now = self.clock()
        if not force and (now < self.next_tick or snap.sample <= self.sample):
            return
        a, z = self.sample, snap.sample
        self.sample = z
        self.seq += 1
        a = max(a, z - LIVE_SPAN)
        index = stride_decimate(max(z - a, 0), LIVE_POINTS_PER_TICK)
        rows = results.log.rows(a, z)  # a streamed run: the window just run, still cached
        time_s = rows.time[index]
        table = snap.table
        trajectory: dict[str, Any] = {"time": [], "points": []}
        active = None
        if table is not None and all(ax.name in results.log.names for ax in table.axes):
            points = np.column_stack([rows[ax.name][index] for ax in table.axes])
            trajectory = {"time": finite_or_none(time_s), "points": points.tolist()}
            active = results.active_cell(z)
        # The series keep each bucket's extremes (a one-sample spike shows while the run
        # goes); the trail needs no more than evenly spread points.
        lines = results.lines(a, z)
        series_time, series_values = minmax_decimate(
            rows.time, {x.name: x.values for x in lines}, LIVE_POINTS_PER_TICK
        )
        series = {
            x.name: {
                "time": finite_or_none(series_time),
                "values": finite_or_none(series_values[x.name]),
            }
            for x in lines
        }
        live_metrics = dict(metrics or {})
        rmse = results.live_rmse()
        if rmse is not None:
            live_metrics.setdefault("output_rmse", rmse)
        with_map = table is not None and (force or now >= self.next_map)
        values = variances = visits = None
        if with_map:
            assert table is not None
            self.next_map = now + table.size / self.cells_per_s
            values, visits = nested_or_none(table.values), nested_or_none(results.visits)
            if snap.variance is not None:
                variances = nested_or_none(np.asarray(snap.variance).reshape(table.shape))
        # The limit counts from the emission, not from the call: a tick slow to build must not
        # leave the next one less than 1/live_fps behind it (never more than live_fps a second).
        self.next_tick = self.clock() + 1.0 / self.live_fps
        message = TickMessage(
            run_id=self.run_id,
            seq=self.seq,
            sample=z,
            n_samples=results.n,
            progress=z / results.n,
            time_s=snap.time_s,
            emitted_at=time.time(),  # wall clock (s since epoch), for frame-delay figures
            values=values,
            variances=variances,
            visits=visits,
            active_cell=active,
            trajectory=trajectory,
            series=series,
            metrics={k: finite_scalar(v) for k, v in live_metrics.items()},
            rejected=results.run_rejected(),
        )
        self.publish(message.to_json())
