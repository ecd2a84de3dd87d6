"""Process-pool plumbing of the local executor: each pool process remembers its context,
dies with the server and publishes its runs' live messages to a queue."""

from __future__ import annotations

import contextlib
import os
import threading
import time
from typing import Any

import numpy as np

from app.runs.live import Publish
from app.runs.worker import WorkerContext, execute_run
from estimation.registry import EstimatorKind, get_spec, names
from estimation.signals import Signals

_pool_context: WorkerContext | None = None
_pool_publish: Publish | None = None


def init_pool_worker(context: WorkerContext, queue: Any) -> None:
    """Pool initializer: remember the context, die with the server, publish to ``queue``."""
    global _pool_context, _pool_publish
    _pool_context = context
    _set_parent_death_signal()

    def publish(message: dict[str, Any]) -> None:
        with contextlib.suppress(Exception):  # a full queue drops the frame, never blocks
            queue.put_nowait(message)

    _pool_publish = publish
    if context.parent_pid is not None:
        threading.Thread(target=_watch_parent, args=(context.parent_pid,), daemon=True).start()


def _set_parent_death_signal() -> None:
    """Linux: SIGKILL this worker when the server process dies (``kill -9`` included)."""
    try:
        import ctypes
        import signal

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _watch_parent(parent_pid: int) -> None:
    while True:
        if os.getppid() != parent_pid:
            os._exit(70)
        time.sleep(0.1)


def execute_in_pool(run_id: int) -> str:
    assert _pool_context is not None, "pool not initialised"
    assert _pool_publish is not None
    return execute_run(run_id, _pool_context, _pool_publish)


def warm_up() -> int:
    """Makes the pool start its processes now, and loads the compiled kernels of the map
    filters (numba's cache) so the first run does not wait for them."""
    u = np.array([0.0, 0.5, 1.0, 0.25])
    signals = Signals(np.arange(4.0), {"u": u, "y": u})
    config = {"axes": [{"name": "u", "breakpoints": [0.0, 1.0]}], "output": "y"}
    for name in names(EstimatorKind.MAP_FILTER):
        get_spec(name).build(config).fit(signals)
    return os.getpid()
