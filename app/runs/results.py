"""What a run accumulates as its chunks come in, and the series and metrics it stores.

Per chunk (:meth:`RunResults.absorb`) the estimator's snapshot is folded into per-sample
output arrays and status codes, the running Σ residual² of accepted samples (the live
``output_rmse``), and, for a map, per-cell visits and rejections:

    visits[c]      = Σ_{k accepted} w_k,c
    rejected_r[c]  = Σ_{k rejected for reason r} w_k,c

with ``w_k,c`` the interpolation weight of sample k on cell c (the table's regressor,
computed once for the whole log). A rejection is the estimator's (innovation gate, sensor
delay: the snapshot's status code) or a sample gate's, attributed to the first gate
rejecting it (:meth:`GateResult.first_gate`).

The result series are namespaced by role (:class:`SeriesRole`): the operating-point
input channels, the measured output, the estimator's outputs (estimates), the simulated
truths, the errors truth − estimate and the rejection mask (``rejected``: 1 where the
sample was rejected, by a gate or the estimator, 0 where accepted, NaN before it was
processed; stored decimated by max per bucket, so no rejection is lost; present when the
run has gates or rejected a sample). Each has a key unique within the run: its name, or
``role:name`` where an earlier role already has that name (an EKF estimates ``p_im_pa``,
which is also one of its input channels).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from app.domain import Dataset, ResumePoint, Run, Series, SeriesRole
from app.io.decimate import MinMaxBuckets, minmax_decimate
from app.io.payload import Truth
from app.runs.gates import GateResult, cell_counts, nearest_cell
from app.store.log_rows import LogRows, MemoryRows
from estimation.errors import EstimationError
from estimation.estimator import Estimator, LogWindows, Snapshot
from estimation.metrics import running_ise, score_run, torque_window
from estimation.registry import EstimatorSpec
from estimation.signals import Signals
from estimation.table import Table

STATUS_ACCEPTED = 0
# Snapshot status codes that count against a cell, by name (see estimation.estimator.Snapshot;
# code 1, the accept mask, is counted by the gate that set it).
CELL_STATUS = {"innovation": 2, "delay": 3}
STATUS_KEY = "__status__"  # the status codes' name in a persisted segment
SERIES_WINDOW = 1 << 18  # rows of a streamed log decimated at a time into the stored series


def channels_read(run: Run, estimator: Estimator, truth: Truth | None) -> list[str]:
    """Every channel of the log a run reads, so its worker loads no other: the estimator's
    (:meth:`~estimation.estimator.Estimator.required_signals` and its signal roles, whose
    ``axis`` names the grid of its snapshots' tables), the operating channels and measured
    output :meth:`RunResults.lines` shows, and the truth's map inputs (scoring points of an
    older truth). The sample gates' channels are the worker's to add."""
    names = list(estimator.required_signals())
    names += [name for role in estimator.signal_roles().values() for name in role]
    names += _run_operating_channels(run)
    output = run.estimator_config.get("output")
    if isinstance(output, str):
        names.append(output)
    if truth is not None:
        names += list(truth.map_inputs)
    return list(dict.fromkeys(names))


def _run_operating_channels(run: Run) -> list[str]:
    """The operating-point channels a run names: its table's axes, else its signal roles."""
    table = run.table
    return [a["name"] for a in table["axes"]] if table else list(run.signals.values())


class RunResults:
    """The per-sample outputs, status codes and cell counts of one run, so far.

    The log is read through ``log`` (:mod:`app.store.log_rows`): held whole
    (:class:`MemoryRows`), or, in a streamed run, a window at a time from the store; only
    the outputs and status codes span the log (17 bytes a sample for a map filter)."""

    def __init__(
        self,
        run: Run,
        spec: EstimatorSpec,
        dataset: Dataset,
        log: LogRows | Signals,
        truth: Truth | None,
        gates: GateResult | None,
    ) -> None:
        self.run, self.spec, self.dataset = run, spec, dataset
        self.log: LogRows = MemoryRows(log) if isinstance(log, Signals) else log
        self.truth, self.gates = truth, gates
        self.n = self.log.n
        self.outputs: dict[str, np.ndarray] = {}
        self.status = np.full(self.n, -1, dtype=np.int8)
        self.grid: Table | None = None  # the map's grid, once a snapshot shows it
        self.visits: np.ndarray | None = None
        self.cell_rejections: dict[str, np.ndarray] = {}
        self.rejected: dict[str, int] = {}
        self.sq_sum = 0.0  # running Σ residual² over accepted samples
        self.sq_n = 0
        self._gate_masks = None if gates is None else gates.first_gate()
        self._first_gate_cache: tuple[int, np.ndarray] | None = None
        self._rejections_seen = False  # a processed sample had status > 0
        self._ise_before = (0, 0.0)  # (k, running ISE of samples [0, k)) of the last slice

    @property
    def streamed(self) -> bool:
        """The log is read a window at a time, never held whole."""
        return not isinstance(self.log, MemoryRows)

    @property
    def signals(self) -> Signals:
        """The whole log, for what only a run holding it does (truth, gates, torque ISE)."""
        if not isinstance(self.log, MemoryRows):
            raise RuntimeError("a streamed run does not hold its log whole")
        return self.log.signals

    # -- accumulation -------------------------------------------------------------------------

    def absorb(self, snap: Snapshot) -> None:
        """Fold the chunk ``[snap.chunk_start, snap.sample)`` in."""
        a, z = snap.chunk_start, snap.sample
        if snap.status is not None and snap.status.size == z - a:
            self.status[a:z] = snap.status
        else:
            self.status[a:z] = STATUS_ACCEPTED
        self._rejections_seen |= bool(np.any(self.status[a:z] > 0))
        for name, values in snap.outputs.items():
            values = np.asarray(values, dtype=np.float64)
            if values.ndim == 1 and values.size == z - a:
                self._output(name)[a:z] = values
        self.rejected = {k: int(v) for k, v in snap.rejected.items()}
        if snap.table is not None:
            self._count_cells(snap.table, a, z)
        residual = snap.outputs.get("residual")
        if residual is not None and residual.size == z - a:
            self._add_squares(np.asarray(residual), self.status[a:z])

    def restore(self, point: ResumePoint) -> None:
        """Continue from a persisted version: its segments, visits and rejections."""
        start = 0
        for segment in point.segments:
            status = segment[STATUS_KEY]
            stop = start + status.size
            self.status[start:stop] = status
            for name, values in segment.items():
                if name != STATUS_KEY:
                    self._output(name)[start:stop] = values
            start = stop
        if start != point.step:
            raise RuntimeError(f"persisted segments cover {start} samples, version {point.step}")
        self._rejections_seen = bool(np.any(self.status[:start] > 0))
        self.visits = point.visits
        self.cell_rejections = dict(point.cell_rejections)
        residual = self.outputs.get("residual")
        if residual is not None:
            self._add_squares(residual[:start], self.status[:start])

    def segment(self, a: int, z: int) -> dict[str, np.ndarray]:
        """Samples ``[a, z)`` of every output and the status codes, as a version stores them."""
        segment = {name: values[a:z] for name, values in self.outputs.items()}
        segment[STATUS_KEY] = self.status[a:z]
        return segment

    def run_rejected(self) -> dict[str, int]:
        """Rejected samples by reason: the estimator's, then ``gate:<label>``.

        The estimator's reasons are disjoint (one status code per sample), so their sum is
        the run's total. Where it counts the accept mask (``mask``), the gates split that
        count: each masked sample so far (status 1) goes to the first gate, in the run's
        list, that rejects it, so ``Σ gate:* == mask`` at every moment (a sample failing
        two gates counts once). With a sensor delay τ a masked step pairs measurement k
        with operating point k − τ, and either being gated masks it. An estimator that
        does not count the mask gets the gates' whole-log counts (first gate wins too).
        """
        out = dict(self.rejected)
        if self.gates is None:
            return out
        labels = list(self.gates.masks)
        if "mask" not in out or not labels:
            return out | {f"gate:{k}": int(v) for k, v in self.gates.rejected.items()}
        first = self._first_gate(int(out.get("delay", 0)))[self.status == 1]
        counts = np.bincount(first[first >= 0], minlength=len(labels))
        return out | {f"gate:{k}": int(c) for k, c in zip(labels, counts, strict=True)}

    def _first_gate(self, tau: int) -> np.ndarray:
        """``(n,)`` index (in the gate list) of the first gate rejecting sample k or k − τ;
        −1 where none does. Cached: it depends only on the log and τ."""
        if self._first_gate_cache is None or self._first_gate_cache[0] != tau:
            assert self.gates is not None
            first = np.full(self.n, -1, dtype=np.int16)
            for i, mask in enumerate(self.gates.masks.values()):
                hit = mask.copy()
                if 0 < tau < self.n:
                    hit[tau:] |= mask[:-tau]
                first[(first < 0) & hit] = i
            self._first_gate_cache = (tau, first)
        return self._first_gate_cache[1]

    def live_rmse(self) -> float | None:
        """RMS residual of the accepted samples so far."""
        return math.sqrt(self.sq_sum / self.sq_n) if self.sq_n else None

    def active_cell(self, z: int) -> list[int] | None:
        """The grid node nearest the operating point of sample ``z − 1``."""
        if self.grid is None or z <= 0:
            return None
        idx, w = self._regressor(z - 1, z)
        flat = int(nearest_cell(idx, w)[0])
        return [int(i) for i in np.unravel_index(flat, self.grid.shape)]

    def _output(self, name: str) -> np.ndarray:
        if name not in self.outputs:
            self.outputs[name] = np.full(self.n, np.nan)
        return self.outputs[name]

    def _add_squares(self, residual: np.ndarray, status: np.ndarray) -> None:
        ok = (status == STATUS_ACCEPTED) & np.isfinite(residual)
        self.sq_sum += float(np.sum(residual[ok] ** 2))
        self.sq_n += int(ok.sum())

    def _count_cells(self, table: Table, a: int, z: int) -> None:
        """Visits (interpolation weight of accepted samples) and rejections per cell, from
        the chunk's regressor rows (made per chunk: a run never holds the whole log's)."""
        if self.grid is None:
            if not all(ax.name in self.log.names for ax in table.axes):
                return
            self.grid = table
            if self.visits is None:
                self.visits = np.zeros(table.shape)
        assert self.visits is not None
        (idx, w), status = self._regressor(a, z), self.status[a:z]
        size, shape = self.grid.size, table.shape
        self.visits += cell_counts(idx, w, status == STATUS_ACCEPTED, size).reshape(shape)
        for label, mask in self._rejection_masks(a, z, status).items():
            if not mask.any():
                self.cell_rejections.setdefault(label, np.zeros(shape))
                continue
            counts = cell_counts(idx, w, mask, size).reshape(shape)
            self.cell_rejections[label] = self.cell_rejections.get(label, 0) + counts

    def _regressor(self, a: int, z: int) -> tuple[np.ndarray, np.ndarray]:
        """The map grid's regressor rows of log samples ``[a, z)``."""
        assert self.grid is not None
        rows = self.log.rows(a, z)
        return self.grid.regressor(np.column_stack([rows[ax.name] for ax in self.grid.axes]))

    def _rejection_masks(self, a: int, z: int, status: np.ndarray) -> dict[str, np.ndarray]:
        masks = {name: status == code for name, code in CELL_STATUS.items()}
        if self._gate_masks is not None:
            masks |= {label: mask[a:z] for label, mask in self._gate_masks.items()}
        return masks

    # -- series -------------------------------------------------------------------------------

    def lines(self, start: int = 0, stop: int | None = None) -> list[Series]:
        """Every result line at full rate, keyed uniquely (see the module docstring), over
        samples ``[start, stop)`` (default the whole log): a live tick takes only its own
        samples, so its cost does not grow with the log."""
        a, z = start, self.n if stop is None else stop
        raw: list[tuple[str, SeriesRole, str, np.ndarray]] = []
        rows = self.log.rows(a, z)
        units = self.log.units
        for channel in self._operating_channels():
            raw.append((channel, SeriesRole.INPUT, units.get(channel, ""), rows[channel]))
        config = self.run.estimator_config
        output, out_unit = config.get("output"), config.get("output_unit", "")
        if isinstance(output, str) and output in self.log.names:
            unit = units.get(output, "")
            raw.append(("measured", SeriesRole.MEASURED, unit, rows[output]))
        for name, values in self.outputs.items():
            raw.append((name, SeriesRole.OUTPUT, self._unit(name, out_unit), values[a:z]))
        if self.truth is not None:
            for name, truth in self.truth.scored_series.items():
                if name in self.outputs:
                    unit = self._unit(name, out_unit)
                    raw.append((f"{name}_true", SeriesRole.TRUTH, unit, truth[a:z]))
                    error = truth[a:z] - self.outputs[name][a:z]
                    raw.append((f"{name}_error", SeriesRole.ERROR, unit, error))
                    if name == "torque_nm":  # the run view's running ISE (TQ (60))
                        ise = self._running_ise(truth, self.outputs[name], a, z)
                        raw.append((f"{name}_ise", SeriesRole.ERROR, "N²·m²·s", ise))
        # With gates from the start (a stable set of lines); else once a sample is rejected.
        rejected = self.rejection_mask(a, z)
        if self.gates is not None or self._rejections_seen:
            raw.append(("rejected", SeriesRole.REJECTED, "", rejected))
        out: list[Series] = []
        taken: set[str] = set()
        time_s = rows.time
        for name, role, unit, values in raw:
            key = name if name not in taken else f"{role}:{name}"
            taken.add(key)
            out.append(Series(key, unit, time_s, values, role))
        return out

    def _running_ise(self, truth: np.ndarray, estimate: np.ndarray, a: int, z: int) -> np.ndarray:
        """:func:`running_ise` of ``truth − estimate`` on samples ``[a, z)``, equal to the
        whole log's. Computed on ``[a − 1, z]`` (sample k's rectangle spans to sample k + 1,
        the last sample's repeats the step before it) less sample a − 1's own term, plus the
        ISE before ``a``: kept from the previous call when it ended at ``a`` (live ticks come
        in order), else summed afresh."""
        t = self.signals.time
        window = torque_window(t)
        lo, end = max(a - 1, 0), min(z + 1, self.n)
        part = running_ise(t[lo:end], truth[lo:end] - estimate[lo:end], window_s=window)
        if a == 0:
            ise = part[:z]
        else:
            if self._ise_before[0] == a:
                offset = self._ise_before[1]
            else:
                head = running_ise(t[: a + 1], truth[: a + 1] - estimate[: a + 1], window_s=window)
                offset = float(head[a - 1])
            ise = offset + (part[1 : 1 + z - a] - part[0])
        if z > a:
            self._ise_before = (z, float(ise[-1]))
        return ise

    def rejection_mask(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """``(stop − start,)`` 1.0 where sample k was rejected (status code > 0: the accept
        mask, the innovation gate, the sensor delay; or a sample gate, also for an estimator
        that does not take the accept mask), 0.0 where accepted, NaN where not yet processed.

        Its sum over the processed samples is the run's number of rejected samples; for an
        estimator that counts the mask that is ``Σ`` of its reasons in :meth:`run_rejected`
        (``gate:*`` split ``mask``). Min/max decimation keeps a 1 in every bucket that has one.
        """
        a, z = start, self.n if stop is None else stop
        status = self.status[a:z]
        mask = (status > 0).astype(np.float64)
        if self.gates is not None:
            mask[~self.gates.accept[a:z]] = 1.0
        mask[status < 0] = np.nan
        return mask

    def series(self, points: int) -> list[Series]:
        """:meth:`lines` at most ``points`` samples long, for storage: min/max per bucket
        (:func:`minmax_decimate`) so a one-sample spike of an error stays in the stored
        series (a stride would keep one sample in ``n / points`` and lose it). A streamed
        run decimates its lines :data:`SERIES_WINDOW` rows at a time (:class:`MinMaxBuckets`,
        the same result)."""
        if not self.streamed:
            lines = self.lines()
            time_s, values = minmax_decimate(
                self.signals.time, {x.name: x.values for x in lines}, points
            )
            return [Series(x.name, x.unit, time_s, values[x.name], x.role) for x in lines]
        shape = self.lines(0, 0)
        buckets = MinMaxBuckets(self.n, points, [x.name for x in shape])
        for a in range(0, self.n, SERIES_WINDOW):
            z = min(a + SERIES_WINDOW, self.n)
            part = self.lines(a, z)
            buckets.add(part[0].time, {x.name: x.values for x in part})
        time_s, values = buckets.result()
        return [Series(x.name, x.unit, time_s, values[x.name], x.role) for x in shape]

    def _unit(self, name: str, out_unit: str) -> str:
        """The spec's unit of an output; ``""`` there means the output channel's unit."""
        return self.spec.output_units.get(name, "") or out_unit

    def _operating_channels(self) -> list[str]:
        names = _run_operating_channels(self.run)
        if not names and self.grid is not None:
            names = [a.name for a in self.grid.axes]
        return [name for name in dict.fromkeys(names) if name in self.log.names]

    # -- metrics ------------------------------------------------------------------------------

    def metrics(self, snap: Snapshot, run_s: float) -> dict[str, float | None]:
        """The run's final metrics: timing, counts, ``output_rmse``, coverage, on a
        simulated dataset the scores against its truth (:func:`score_run`) and the
        truth-free ones (:meth:`holdout_metrics`)."""
        truth = None
        if self.truth is not None:
            truth = self.truth.scenario_data(
                self.dataset.scenario or "", self.dataset.seed or 0, self.signals
            )
        scored = score_run(self.outputs, self.status, table=snap.table, truth=truth)
        metrics: dict[str, float | None] = {
            "run_s": run_s,
            "samples": float(self.n),
            "accepted": float(np.count_nonzero(self.status == STATUS_ACCEPTED)),
        }
        if "output_rmse" in scored:
            metrics["output_rmse"] = scored.pop("output_rmse")
        if snap.table is not None and self.visits is not None:
            metrics["coverage"] = float(np.mean(self.visits >= 1.0))
        metrics |= scored
        metrics |= self.holdout_metrics()
        return {k: finite_or_none(v) for k, v in metrics.items()}

    def holdout_metrics(self) -> dict[str, float | None]:
        """The run's truth-free metrics, by its spec's check
        (:meth:`~estimation.registry.EstimatorSpec.holdout_check`, docs/tuning.md): the
        run's estimator and config refitted on the first 70 % of the log and what it froze
        scored on the rest (``holdout:*``, in the measured output's unit), with the fit's
        innovation statistics (``nis:*``) or, for the LPV observer, its output-error
        statistics (``residual:*``); ``…:not_applicable:<reason>`` (``None``) where a check
        does not exist (the torque estimators). Empty when the log is too short to split.
        """
        accept = None if self.gates is None else self.gates.accept
        config = self.run.estimator_config
        try:
            if self.streamed:  # the check reads the log a window at a time too
                output = config.get("output", "")
                unit = config.get("output_unit") or self.log.units.get(output, "")
                check_windows = self.spec.holdout_check_windows()
                log = LogWindows.over(self.log.rows, self.n, timeline=self.log.time, accept=accept)
                result = check_windows(self.spec.name, config, log, unit=unit)
            else:
                check = self.spec.holdout_check()
                result = check(self.spec.name, config, self.signals, accept=accept)
        except EstimationError:
            return {}
        return dict(result.metrics())


def finite_or_none(value: Any) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None
