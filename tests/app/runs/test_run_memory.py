"""A run's memory grows with the channels it reads, not with the dataset's width.

The same ``skf`` run (3 channels: two axes and the output) executes in fresh worker
processes on a 40-channel log and on the 4-channel log of just its time and channels
(scripts/run_memory.py: the worker warms up on a short run, resets its peak resident set,
then executes the measured run). The 36 channels it never reads cost it next to nothing,
and its peak growth stays under the whole log's size; before column projection the worker
held the file's bytes and every decoded column (about twice the whole log, 172 MiB here).
RSS, not time, so a loaded machine changes nothing.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from estimation.estimator import WINDOW_STEPS
from scripts.run_memory import MIB, RANGE_GATE, workbench, worker_peak

ROWS = 1 << 18  # four of the store's 64k-row groups; 82 MiB of float64 at 40 channels
WIDE, NARROW = 40, 4


@pytest.mark.slow
def test_unread_channels_cost_a_run_no_memory(tmp_path: Path) -> None:
    growth = {}
    log_bytes = {}
    for channels in (WIDE, NARROW):
        directory = tmp_path / f"c{channels}"
        directory.mkdir()
        bench = workbench(directory, ROWS, channels)
        peak = worker_peak(bench, timeout_s=120)
        assert peak.status == "succeeded"
        growth[channels], log_bytes[channels] = peak.growth_bytes, bench.log_bytes
    unread = log_bytes[WIDE] - log_bytes[NARROW]
    report = {
        c: f"+{g / MIB:.0f} MiB of a {log_bytes[c] / MIB:.0f} MiB log" for c, g in growth.items()
    }
    assert growth[NARROW] > 0, report
    assert growth[WIDE] - growth[NARROW] < 0.1 * unread, report
    assert growth[WIDE] < log_bytes[WIDE], report


@pytest.mark.slow
@pytest.mark.parametrize(
    ("estimator", "gates", "keeps", "bound", "recorded"),
    [
        ("skf", [], 17, 48, False),
        ("skf", [RANGE_GATE], 17, 48, False),
        ("uio", [], 9, 24, False),
        ("lpv", [], 49, 130, False),
        ("skf", [], 25, 56, True),
    ],
    ids=["skf", "skf-gated", "uio", "lpv", "skf-recorded"],
)
def test_a_streamed_run_holds_a_window_of_its_log_not_the_log(
    tmp_path: Path, estimator: str, gates: list[dict], keeps: int, bound: int, recorded: bool
) -> None:
    """A run on an uploaded log reads it a window at a time (WINDOW_STEPS rows,
    docs/data-formats.md#streamed-runs). From a log of 2 windows to one of 10, the worker's
    peak grows by what it keeps per sample, ``keeps`` at least — a map filter's prediction,
    residual and status code (17 bytes) and the final RMSE's copy of the accepted residuals
    (8), with a sample gate its masks (5); a ``uio`` run's torque and status code (9), and
    while it checks the sample period its time column and steps (16); the LPV observer's six
    outputs and status code (49) and its check's fit output error (25); on a dataset stored
    as recorded, ``u1`` at twice the rate on its own timestamps, the raster's time column (8)
    besides — not by the log's channels. A run holding its log whole grows by about 75 bytes
    a sample (``skf``; 123 gated, 50 for ``uio``, 554 for ``lpv`` on its 19-channel log, 173
    for ``skf`` on the recorded one). Measured: ``skf`` 23.5 and 26 bytes a sample on a quiet
    machine, the gated run 33 under the whole suite's load (more live ticks, each
    allocating), hence its bound of 48; ``uio`` 11; ``lpv`` 83; ``skf`` as recorded 28."""
    growth, rows = {}, {}
    for windows in (2, 10):
        directory = tmp_path / f"w{windows}"
        directory.mkdir()
        rows[windows] = windows * WINDOW_STEPS
        bench = workbench(directory, rows[windows], NARROW, {"gates": gates}, estimator, recorded)
        peak = worker_peak(bench, timeout_s=300)
        assert peak.status == "succeeded"
        growth[windows] = peak.growth_bytes
    per_sample = (growth[10] - growth[2]) / (rows[10] - rows[2])
    report = {w: f"+{g / MIB:.0f} MiB on {rows[w]} rows" for w, g in growth.items()}
    assert keeps <= per_sample < bound, (per_sample, report)
