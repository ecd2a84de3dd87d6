"""How long a new run worker takes to be ready for its first run, forked or spawned.

    .venv/bin/python scripts/worker_start.py --repeat 5

starts the fork server the local executor uses (``forkserver`` with ``app.runs.prewarm``
preloaded, as :class:`app.runs.executor.RunExecutor` does) and times
it, then times ``--repeat`` child processes that each do what a worker does before it takes a run
(:func:`app.runs.pool.warm_up`), first forked from that server and then spawned as fresh
interpreters (the start method the pool used before). Prints wall seconds as JSON: the fork
server's start, and the median and worst of each kind of worker.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _time_children(method: str, repeat: int) -> list[float]:
    # Imported here, not at the top: each child imports this script again as its main
    # module, and a server's main module (`mapwise`) is preloaded in the fork server.
    from app.runs.pool import warm_up

    context = multiprocessing.get_context(method)
    seconds = []
    for _ in range(repeat):
        start = time.monotonic()
        child = context.Process(target=warm_up)
        child.start()
        child.join()
        if child.exitcode != 0:
            raise SystemExit(f"a {method} worker exited with code {child.exitcode}")
        seconds.append(time.monotonic() - start)
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="workers of each kind (1-50)")
    args = parser.parse_args()
    if not 1 <= args.repeat <= 50:
        parser.error("--repeat must be 1 to 50")
    from app.runs.pool import warm_context

    forkserver = warm_context()
    start = time.monotonic()
    first = forkserver.Process(target=time.sleep, args=(0,))
    first.start()  # starts the fork server, which imports app.runs.prewarm first
    first.join()
    server_s = time.monotonic() - start
    report: dict[str, object] = {"fork_server_start_s": round(server_s, 3)}
    for method in ("forkserver", "spawn"):
        seconds = _time_children(method, args.repeat)
        report[method] = {
            "median_s": round(statistics.median(seconds), 4),
            "worst_s": round(max(seconds), 4),
        }
    print(json.dumps(report))


if __name__ == "__main__":
    main()
