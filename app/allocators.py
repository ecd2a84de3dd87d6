"""The API process's allocators, set so that what an upload allocates goes back when it ends.

An upload is parsed by pyarrow's threads in blocks (:mod:`app.io.csv_stream`). Two allocators
would keep what those threads freed, and the process would grow upload after upload:

- pyarrow's default pool (mimalloc in the wheels) keeps freed pages per thread; the system
  pool (``malloc``) is as fast on the reader's blocks and returns them.
- glibc gives each thread that allocates its own arena, up to eight per core, and an arena
  rarely returns its free pages; ``M_ARENA_MAX`` caps them at two.
- glibc maps a block over ``M_MMAP_THRESHOLD`` on its own and unmaps it when freed, but
  raises the threshold each time such a block is freed (up to 32 MiB), after which the
  reader's 2 MiB blocks come from the heap and fragment it. A fixed 1 MiB threshold keeps
  them mapped; a lower one costs the upload time (mapping and faulting each block).

And after each upload the API gives the heap's free pages back (:func:`give_back_free_memory`):
without it, the live frames and requests served between uploads settle on a heap the upload
left in pieces, and the process creeps up round after round of ``scripts/bench_service.py``.
Figures: docs/reliability.md#api-memory. Run workers keep the defaults: each run is bounded by its
own limit and a worker that kept too much is replaced (:mod:`app.runs.pool`).
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable

M_MMAP_THRESHOLD, M_ARENA_MAX = -3, -8  # glibc's <malloc.h>
API_ARENAS = 2
API_MMAP_THRESHOLD = 1 << 20


def use_lean_allocators() -> None:
    """pyarrow allocates with ``malloc``; glibc keeps at most :data:`API_ARENAS` arenas and
    maps every block of :data:`API_MMAP_THRESHOLD` or more (both no-ops on a C library
    without ``mallopt``). Call before the server starts threads."""
    import pyarrow as pa

    pa.set_memory_pool(pa.system_memory_pool())
    if (mallopt := _libc("mallopt")) is not None:
        mallopt(M_ARENA_MAX, API_ARENAS)
        mallopt(M_MMAP_THRESHOLD, API_MMAP_THRESHOLD)


def give_back_free_memory() -> None:
    """Return the heap's free pages to the system (glibc's ``malloc_trim``; a no-op
    elsewhere): after an upload, what its threads freed between live objects."""
    if (malloc_trim := _libc("malloc_trim")) is not None:
        malloc_trim(0)


def _libc(name: str) -> Callable[..., int] | None:
    """The C library's function ``name``, ``None`` where it has none (not glibc)."""
    try:
        return getattr(ctypes.CDLL(None), name)  # type: ignore[no-any-return]
    except (OSError, AttributeError):
        return None
