"""Sweep throughput, local process pool against Dask (figures for the README; not a test).

In one run, on one fresh PostgreSQL database: a 200-run SKF sweep (σw × σv grid, 20 × 10) of
a 60 s, 100 Hz log on a 12×18 NOx grid, submitted with ``POST /api/sweeps``

1. to a ``mapwise serve`` with its local pool of ``--workers`` processes, and
2. to a ``mapwise serve`` with ``MAPWISE_EXECUTOR=dask`` and a local Dask cluster of
   ``--workers`` worker processes (a scheduler and workers under nannies, as deployed);

reporting the wall time from the POST until every run has succeeded, and runs/s.

    .venv/bin/python scripts/bench_scaleout.py [--workers 2] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scripts.bench_service import drive_run_body, make_log  # noqa: E402
from tests.support.cluster import DaskCluster  # noqa: E402
from tests.support.databases import PgDatabases  # noqa: E402
from tests.support.server import Server  # noqa: E402

SIGMA_W = [float(x) for x in np.geomspace(1, 50, 20)]
SIGMA_V = [float(x) for x in np.geomspace(5, 100, 10)]


def sweep(server: Server, dataset_id: int, timeout: float = 1800.0) -> dict[str, Any]:
    body = drive_run_body(dataset_id, p0=1e4) | {
        "parameters": {"sigma_w": SIGMA_W, "sigma_v": SIGMA_V},
        "metric": "output_rmse",
    }
    t0 = time.perf_counter()
    response = server.http.post("/api/sweeps", json=body, timeout=600)
    response.raise_for_status()
    sweep_id = response.json()["id"]
    deadline = time.monotonic() + timeout
    while True:
        doc = server.get(f"/api/sweeps/{sweep_id}")
        if all(r["status"] in ("succeeded", "failed", "cancelled") for r in doc["runs"]):
            break
        if time.monotonic() > deadline:
            raise TimeoutError(f"sweep {sweep_id}: {doc['counts']}")
        time.sleep(0.2)
    wall = time.perf_counter() - t0
    if doc["counts"] != {"succeeded": len(doc["runs"])}:
        raise RuntimeError(f"sweep {sweep_id} did not succeed: {doc['counts']}")
    best = doc["runs"][0]
    return {
        "runs": len(doc["runs"]),
        "wall_s": round(wall, 2),
        "runs_per_s": round(len(doc["runs"]) / wall, 2),
        "best": {"params": best["params"], "output_rmse": best["metric"]},
    }


def upload(server: Server, path: Path) -> int:
    with path.open("rb") as f:
        response = server.http.post("/api/datasets", files={"file": ("sweep.csv", f)})
    response.raise_for_status()
    return int(response.json()["id"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rows", type=int, default=6000)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    import tempfile

    work = Path(tempfile.mkdtemp(prefix="mapwise-scaleout-"))
    log = work / "log.csv"
    make_log(log, args.rows)
    databases = PgDatabases()
    result: dict[str, Any] = {"rows": args.rows, "workers": args.workers}
    try:
        url = databases.create()
        local = Server(url, workers=args.workers)
        try:
            result["local"] = sweep(local, upload(local, log))
        finally:
            local.stop()
        cluster = DaskCluster(workers=args.workers)
        try:
            env = {"MAPWISE_EXECUTOR": "dask", "MAPWISE_DASK_ADDRESS": cluster.address}
            dask = Server(url, env=env)
            try:
                result["dask"] = sweep(dask, upload(dask, log))
            finally:
                dask.stop()
        finally:
            cluster.stop()
    finally:
        databases.drop_all()
    result["dask_over_local"] = round(
        result["dask"]["runs_per_s"] / result["local"]["runs_per_s"], 2
    )
    print(json.dumps(result) if args.json else json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
