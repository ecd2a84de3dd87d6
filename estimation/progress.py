"""Progress of a long simulation, readable from another thread while it runs.

A caller that wants progress (the dashboard's *Simulate*, through
``POST /api/datasets/simulate/stream``) builds a scenario inside :func:`reporting`. The slow
parts of a build look up :func:`current` and, when there is one, count their work into its
``counts`` array: ``counts[0]`` steps done of ``counts[1]``. The air-path plant's numba kernel
(:func:`estimation.kernels.airpath_plant.airpath_simulate_kernel`) writes them as it
integrates and runs without the GIL, so a poller in another thread reads a live fraction.
Nothing is timed or estimated: the fraction is the integrator's own step count.

The lookup goes through a :class:`contextvars.ContextVar`, so concurrent builds in other
threads each see their own (or none), and a build without a caller pays nothing.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

import numpy as np

__all__ = ["Progress", "current", "reporting"]


class Progress:
    """Steps done of steps to do in the current stage, as the slow parts of a build write them.

    A build may integrate more than one plant run (an air-path scenario runs the cycle, then
    the segment its observer-side model is identified on), and how many is the scenario's
    business: each run is a *stage* (``stage`` counts them from 1), and ``fraction`` is the
    share of the current stage's steps done, so it rises within a stage and restarts with the
    next one.
    """

    def __init__(self) -> None:
        self.counts = np.zeros(2, dtype=np.int64)
        self.stage = 0

    def next_stage(self) -> np.ndarray:
        """Begin the next stage; returns the ``[done, total]`` array its kernel writes."""
        self.counts[:] = 0
        self.stage += 1
        return self.counts

    def finish(self) -> None:
        """The current stage is done (a cached stage finishes at once)."""
        self.counts[0] = self.counts[1] = max(int(self.counts[1]), 1)

    @property
    def fraction(self) -> float:
        """Share of the current stage done, 0 … 1 (0 before its kernel has started)."""
        done, total = int(self.counts[0]), int(self.counts[1])
        return 0.0 if total <= 0 else min(max(done / total, 0.0), 1.0)


_CURRENT: ContextVar[Progress | None] = ContextVar("mapwise_progress", default=None)


def current() -> Progress | None:
    """The progress the running build reports into, or ``None``."""
    return _CURRENT.get()


@contextmanager
def reporting(progress: Progress) -> Iterator[Progress]:
    """Run the enclosed build with ``progress`` as :func:`current`."""
    token = _CURRENT.set(progress)
    try:
        yield progress
    finally:
        _CURRENT.reset(token)
