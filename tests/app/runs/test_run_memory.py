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

from scripts.run_memory import MIB, workbench, worker_peak

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
