"""A live tick reads only its own samples of a run's result lines: ``lines(a, z)`` over
consecutive ranges, joined, is ``lines()`` over the whole log, value for value (the running
ISE carried from range to range, the rejection mask, the truth and error lines), in any
order of ranges, and the line set does not change when the first rejection comes late."""

from __future__ import annotations

import itertools
from datetime import UTC, datetime

import numpy as np
import pytest

from app.domain import Channel, Dataset, Run, RunStatus
from app.io.payload import Truth
from app.runs.gates import apply_gates, parse_gates
from app.runs.results import RunResults
from estimation.estimator import Snapshot
from estimation.registry import get_spec
from estimation.signals import Signals

N = 3000
STEP_S = 0.01  # 30 s: the torque scoring window 5–30 s lies inside


def _run(estimator: str, signals: dict[str, str]) -> Run:
    return Run(
        id=1, dataset_id=1, name="r", estimator=estimator, status=RunStatus.RUNNING,
        progress=0.0, sample=0, n_samples=N, error=None, signals=signals, table=None,
        config={}, estimator_config={}, rejected={}, produces_map=False, base_map_id=None,
        stop_request=None, attempt=1, lost_attempts=0, owner=None, heartbeat_at=None,
        created_at=datetime.now(UTC), started_at=None, finished_at=None,
    )  # fmt: skip


def _results(*, gated: bool) -> RunResults:
    rng = np.random.default_rng(3)
    t = STEP_S * np.arange(N) + rng.uniform(0, 1e-3, N)  # uneven steps: Δt matters
    speed = 2000 + 50 * rng.standard_normal(N)
    signals = Signals(t, {"speed_rpm": speed}, units={"speed_rpm": "rpm"})
    dataset = Dataset(
        id=1, name="d", source="simulated", rows=N, rate_hz=1 / STEP_S, duration_s=t[-1],
        time_column="time", channels=[Channel("speed_rpm", "rpm")], scenario=None, seed=None,
        has_truth=True, created_at=datetime.now(UTC),
    )  # fmt: skip
    truth = Truth(
        true_map=None, map_inputs=(), map_output=None, map_points=None,
        scored_series={"torque_nm": 100 + 10 * np.sin(t)},
    )  # fmt: skip
    gates = None
    if gated:
        parsed = parse_gates(
            [{"type": "range", "channel": "speed_rpm", "max": 2060.0}], ["speed_rpm"]
        )
        gates = apply_gates(parsed, signals)
    run = _run("uio", {"speed": "speed_rpm"})
    results = RunResults(run, get_spec("uio"), dataset, signals, truth, gates)
    for a in range(0, N, 250):  # chunks; the estimator rejects one late sample itself
        z = min(a + 250, N)
        status = np.zeros(z - a, dtype=np.int8)
        if a <= 2500 < z:
            status[2500 - a] = 2
        torque = 100 + 10 * np.sin(t[a:z]) + rng.standard_normal(z - a)
        results.absorb(
            Snapshot(
                estimator="uio",
                sample=z,
                n_samples=N,
                time_s=t[z - 1],
                state=None,
                chunk_start=a,
                outputs={"torque_nm": torque},
                status=status,
            )
        )
    return results


@pytest.mark.parametrize("gated", [False, True])
def test_ranges_joined_are_the_whole_log(gated: bool) -> None:
    results = _results(gated=gated)
    whole = {x.name: x for x in results.lines()}
    assert {"torque_nm_ise", "torque_nm_error", "rejected"} <= set(whole)
    cuts = [0, 1, 7, 500, 1234, 2999, N]
    parts = [results.lines(a, z) for a, z in itertools.pairwise(cuts)]
    for key, line in whole.items():
        joined = np.concatenate([next(x for x in part if x.name == key).values for part in parts])
        np.testing.assert_allclose(joined, line.values, rtol=1e-10, atol=1e-9, err_msg=key)
        assert all(next(x for x in p if x.name == key).unit == line.unit for p in parts)
    time_joined = np.concatenate([p[0].time for p in parts])
    np.testing.assert_array_equal(time_joined, results.signals.time)


def test_a_range_out_of_order_sums_the_ise_afresh() -> None:
    results = _results(gated=False)
    whole = next(x for x in results.lines() if x.name == "torque_nm_ise").values
    results.lines(0, 2000)  # leaves the carried ISE at sample 2000
    late = next(x for x in results.lines(1500, 1600) if x.name == "torque_nm_ise").values
    np.testing.assert_allclose(late, whole[1500:1600], rtol=1e-10)


def test_the_rejected_line_is_there_from_the_first_rejection_on() -> None:
    results = _results(gated=False)
    # The only rejection is sample 2500, processed: every range has the line, even one
    # before it, so a live view's set of lines does not change from tick to tick.
    assert "rejected" in {x.name for x in results.lines(0, 10)}
    assert "rejected" in {x.name for x in results.lines(0, 0)}
