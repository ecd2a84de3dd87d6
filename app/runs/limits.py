"""The OS memory limit a run executes under, in its worker process.

The limit is ``RLIMIT_DATA``: since Linux 4.7 it counts the process's private writable
memory (heap, anonymous mappings, thread stacks), which is what a run allocates, and not
the code, shared libraries and reserved-but-unused address space that ``RLIMIT_AS`` counts
(a warmed-up worker maps about 500 MiB of address space for 250 MiB of data and 200 MiB
resident: numba/llvmlite, OpenBLAS and the thread stacks reserve a lot). Each run may
allocate ``run_memory_mb`` on top of what its worker holds when the run starts; beyond it an
allocation fails with :class:`MemoryError` in the run instead of waking the host's OOM
killer, and the run fails with :func:`out_of_memory_message`.
"""

from __future__ import annotations

import contextlib
import resource
from collections.abc import Iterator
from pathlib import Path

MIB = 1024 * 1024


def out_of_memory_message(limit_mb: float | None) -> str:
    """The error of a run that ran out of memory (under its limit, or the machine's)."""
    if limit_mb is None:
        return "out of memory: the run needed more memory than the machine could give"
    return f"out of memory: the run exceeded its {limit_mb:g} MiB limit (MAPWISE_RUN_MEMORY_MB)"


def data_bytes() -> int:
    """This process's private writable memory (``VmData`` of /proc/self/status), in bytes."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmData:"):
            return int(line.split()[1]) * 1024
    raise OSError("VmData not found in /proc/self/status")


@contextlib.contextmanager
def memory_limit(budget_mb: float | None) -> Iterator[None]:
    """Within the block, this process may allocate ``budget_mb`` MiB more than it holds now
    (``None``: no limit). The soft limit is raised back afterwards (the hard one is never
    lowered, so the next run can be given its own budget)."""
    if budget_mb is None:
        yield
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
    limit = data_bytes() + int(budget_mb * MIB)
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_DATA, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_DATA, (soft, hard))
