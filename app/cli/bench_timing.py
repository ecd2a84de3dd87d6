"""How ``mapwise bench`` times, and the machine it reports (:mod:`app.cli.bench`).

Map-filter throughput is the median and the worst of :data:`REPEATS` runs after a warm-up
(numba compiled), in CPU time (``time.process_time``) and wall time, one core
(:func:`rates`). The observer, estimator and simulator sections report the best of 3
wall-time runs (:func:`best_rate`, :func:`best_time`).
"""

from __future__ import annotations

import math
import os
import platform
import time
from collections.abc import Callable
from typing import Any

import numpy as np

REPEATS = 5  # timed runs per map-filter measurement (median and worst reported)


def machine() -> dict[str, Any]:
    """The machine the figures come from: CPU model (``/proc/cpuinfo``), logical cores, the
    1/5/15-minute load average (on a shared machine the figures are only as quiet as that) and
    the BLAS threads FilterPy and the numpy references may use (``OPENBLAS_NUM_THREADS=1`` keeps
    every peer on one core, like the kernels)."""
    model = platform.processor() or ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            names = [
                line.split(":", 1)[1].strip() for line in cpuinfo if line.startswith("model name")
            ]
        model = names[0] if names else model
    except OSError:
        pass
    return {
        "python": platform.python_version(),
        "cpu_model": model,
        "cores": os.cpu_count(),
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"),
    }


def rates(run: Callable[[], object], samples: int, repeats: int = REPEATS) -> dict[str, float]:
    """Samples/s of ``run`` after one warm-up call: median and worst of ``repeats`` runs, in
    CPU time of this process and in wall time."""
    run()  # warm-up: compile and fault in memory
    cpu, wall = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        run()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    return {
        "cpu_median": samples / float(np.median(cpu)),
        "cpu_worst": samples / max(cpu),
        "wall_median": samples / float(np.median(wall)),
        "wall_worst": samples / max(wall),
    }


def best_rate(run: Callable[[], object], samples: int, repeats: int = 3) -> float:
    run()  # warm-up: compile and fault in memory
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - t0)
    return samples / best


def best_time(run: Callable[[], object], repeats: int = 3) -> float:
    run()  # warm-up
    return min(timed(run) for _ in range(repeats))


def timed(run: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    run()
    return time.perf_counter() - t0
