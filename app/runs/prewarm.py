"""Imported by the run workers' fork server before it forks the first worker
(:mod:`app.runs.executor` names it in ``set_forkserver_preload``): the worker's modules and the
map filters' compiled kernels, loaded once, so every worker forked from the server starts warm
(:mod:`app.runs.pool`). The fork server is its own process: the API server never imports this.

Nothing here may start a thread: a process is forked from this one.

``app.cli.main`` is here because each forked worker imports the server's main script again
(multiprocessing's ``prepare``; for ``mapwise serve`` that script imports ``app.cli.main``),
and would otherwise do so from scratch. Naming ``"__main__"`` in the preload list instead
does nothing on Python 3.11, whose fork server is never told the main script's path.
"""

import app.cli.main  # noqa: F401
from app.runs.pool import load_kernels, worker_main
from app.runs.worker import execute_run

__all__ = ["execute_run", "worker_main"]

load_kernels()
