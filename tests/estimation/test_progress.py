"""estimation.progress: the air-path plant counts its integrator steps into the progress of
the build that asked for it, readable from another thread while the kernel runs without the
GIL; a build without one, or in another context, pays and sees nothing; the numbers do not
change."""

from __future__ import annotations

import threading
import time

import numpy as np

from estimation.plants import airpath
from estimation.progress import Progress, current, reporting
from estimation.scenarios import get_scenario


def test_progress_is_read_live_and_changes_no_number() -> None:
    scenario = get_scenario("maf-whtc")
    airpath._PLANT_RUNS.clear()  # a cached plant run has no steps to count
    plain = scenario.build(seed=3, duration_s=900.0)
    airpath._PLANT_RUNS.clear()
    progress = Progress()
    seen: list[tuple[int, float]] = []
    done = threading.Event()

    def poll() -> None:
        while not done.is_set():
            seen.append((progress.stage, progress.fraction))
            time.sleep(0.002)

    poller = threading.Thread(target=poll)
    poller.start()
    try:
        with reporting(progress):
            assert current() is progress
            counted = scenario.build(seed=3, duration_s=900.0)
    finally:
        done.set()
        poller.join()
    assert current() is None
    assert progress.stage == 2  # the cycle, then the identification segment
    assert progress.fraction == 1.0
    assert any(stage == 1 and 0.0 < f < 1.0 for stage, f in seen), seen[-5:]
    for stage in (1, 2):
        shares = [f for s, f in seen if s == stage]
        assert shares == sorted(shares)
    for name in plain.signals.names:
        np.testing.assert_array_equal(counted.signals[name], plain.signals[name])


def test_each_thread_sees_its_own_progress() -> None:
    mine = Progress()
    other: list[Progress | None] = []
    with reporting(mine):
        thread = threading.Thread(target=lambda: other.append(current()))
        thread.start()
        thread.join()
        assert current() is mine
    assert other == [None]
    cached = Progress()
    cached.next_stage()
    cached.finish()
    assert (cached.stage, cached.fraction) == (1, 1.0)
    assert Progress().fraction == 0.0
