"""Service benchmark (figures for the README; not a test).

Against a real ``mapwise serve`` process:

1. upload a 1-hour 100 Hz log (360 000 rows, 12 channels) as CSV, run the SKF on a 12×18
   grid at full speed, and wait until its versions, metrics and series are persisted:
   seconds per phase and rows/s;
2. a paced run watched by ``--viewers`` WebSocket viewers (20 by default, at most the 100 a
   run admits) in each ``--encoding`` (``json``, ``binary`` or ``both``: one paced run per
   encoding): frames/s and MB/s each viewer receives (and decodes), the API process's CPU
   (its event loop and thread pool; % of one core) and the event loop's worst lag
   (``/api/health``: the last 30 s, so ``--live-seconds 30`` covers the viewers' phase
   exactly);
3. API latency (p50/p99) of ``GET /api/runs?limit=5`` and ``GET /api/datasets`` polled by
   ``--pollers`` concurrent clients (4), back to back or every ``--poll-every`` seconds,
   measured apart during phase 1 (the bulk upload and full-speed run) and during phase 2
   (the viewers).

A run that does not finish in ``--timeout`` seconds, or a viewer or poller that fails, ends
the benchmark with an error instead of a figure.

    .venv/bin/python scripts/bench_service.py [--database-url URL] [--rows N] [--viewers N]
        [--encoding json|binary|both] [--live-seconds S] [--live-only] [--repeat 5]
        [--pollers N] [--poll-every S] [--deflate] [--json]

Each figure is the median and the worst of ``--repeat`` rounds on one server (the machines
are shared and noisy); ``--live-only`` skips phase 1 (the log is uploaded once);
``--deflate`` turns on permessage-deflate (``MAPWISE_WS_DEFLATE``) to show what compressing
once per viewer costs the live fan-out.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import psutil

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the shared server helper, when run as scripts/bench_service.py

from app.runs.frame_encoding import decode_binary  # noqa: E402
from tests.support.server import Server, run_body  # noqa: E402

SPEED = [750, 780, 1000, 1250, 1500, 1750, 2000, 2500, 3000, 3500, 4000, 4500]
FUEL = [0, 5, 10, 15, 20, 25, 30, 34, 38, 42, 46, 50, 55, 60, 65, 70, 75, 80]


def make_log(path: Path, rows: int, rate_hz: float = 100.0) -> None:
    """A drive-like log: speed, fuel, NOx from a smooth map, plus nine other channels."""
    rng = np.random.default_rng(0)
    t = np.arange(rows) / rate_hz
    speed = 2600 + 1500 * np.sin(t / 37.0) + 300 * np.sin(t / 5.3)
    fuel = 40 + 35 * np.sin(t / 23.0 + 1.0) + 5 * rng.standard_normal(rows)
    nox = 200 + 0.15 * speed + 8.0 * fuel + 25 * rng.standard_normal(rows)
    extra = {f"ch{i}": 10 * np.sin(t / (3.0 + i)) + rng.standard_normal(rows) for i in range(9)}
    names = ["speed_rpm [rpm]", "fuel_mg_per_stroke [mg/stroke]", "nox_ppm [ppm]"]
    header = ["time [s]", *names, *(f"{k} [-]" for k in extra)]
    data = np.column_stack([t, speed, fuel, nox, *extra.values()])
    with path.open("w") as f:
        f.write(",".join(header) + "\n")
        np.savetxt(f, data, delimiter=",", fmt="%.6f")


class Worker(threading.Thread):
    """A thread whose exception is kept and re-raised by :meth:`result`."""

    def __init__(self, target: Any, *args: Any) -> None:
        super().__init__(daemon=True)
        self._call = (target, args)
        self.error: BaseException | None = None

    def run(self) -> None:
        target, args = self._call
        try:
            target(*args)
        except BaseException as exc:
            self.error = exc

    def result(self) -> None:
        self.join()
        if self.error is not None:
            raise RuntimeError(f"benchmark thread failed: {self.error!r}") from self.error


def drive_run_body(dataset_id: int, **config: Any) -> dict[str, Any]:
    """The SKF on NOx over the 12×18 speed × fuel grid of :func:`make_log`'s log."""
    table = {
        "axes": [
            {"name": "speed_rpm", "breakpoints": SPEED},
            {"name": "fuel_mg_per_stroke", "breakpoints": FUEL},
        ]
    }
    noise = {"sigma_w": 15, "sigma_v": 25, "p0": 1e4}
    return run_body(dataset_id, signals={"y": "nox_ppm"}, table=table, **(noise | config))


def viewer(url: str, seconds: float, counts: list[tuple[int, int]], index: int) -> None:
    """Read and decode the stream for ``seconds``: (frames, bytes) into ``counts[index]``."""
    from websockets.sync.client import connect

    end = time.monotonic() + seconds
    n = size = 0
    with connect(url, max_size=None, open_timeout=60) as ws:
        while time.monotonic() < end:
            try:
                data = ws.recv(timeout=max(0.01, end - time.monotonic()))
            except TimeoutError:
                break
            size += len(data)
            message = json.loads(data) if isinstance(data, str) else decode_binary(data)
            if message["type"] in ("delta", "full"):
                n += 1
    counts[index] = (n, size)


def poller(
    base: str, paths: list[str], stop: threading.Event, out: list[float], every_s: float = 0.0
) -> None:
    """Request ``paths`` in turn until ``stop``: back to back (``every_s`` 0, a closed loop
    that takes whatever CPU the server leaves), or each round ``every_s`` after the last."""
    with httpx.Client(base_url=base, timeout=30) as client:
        while not stop.is_set():
            for path in paths:
                t0 = time.perf_counter()
                client.get(path).raise_for_status()
                out.append(time.perf_counter() - t0)
            if every_s > 0:
                stop.wait(every_s)


def peak_rss_mb(pid: int) -> float:
    """The API process's peak resident memory (VmHWM), MiB: the upload is parsed there."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return round(int(line.split()[1]) / 1024, 1)
    return float("nan")


def latency_figures(phase: str, latencies: list[float]) -> dict[str, float]:
    lat_ms = sorted(1000 * x for x in latencies)
    if not lat_ms:
        raise RuntimeError(f"no API request completed during the {phase} phase")
    return {
        f"api_requests_{phase}": len(lat_ms),
        f"api_p50_ms_{phase}": round(lat_ms[len(lat_ms) // 2], 1),
        f"api_p99_ms_{phase}": round(lat_ms[int(0.99 * (len(lat_ms) - 1))], 1),
    }


# Figures where a larger value is better; for every other figure the worst is the largest.
HIGHER_IS_BETTER = ("rows_per_s", "frames_per_s", "mb_per_s", "api_requests")


def warm_up(client: httpx.Client, server: Server, timeout: float) -> None:
    """Warm the run workers (imports, compiled kernels) as a server in use would be."""
    small = "time,speed_rpm,fuel_mg_per_stroke,nox_ppm\n" + "".join(
        f"{k * 0.01},{1000 + k},{10 + k % 50},{100 + k % 7}\n" for k in range(500)
    )
    tiny = client.post("/api/datasets", files={"file": ("w.csv", small.encode())}).json()
    for _ in range(2):
        warm = client.post("/api/runs", json=drive_run_body(tiny["id"])).json()
        server.wait_run(warm["id"], ("succeeded", "failed"), timeout)


def bulk_round(
    client: httpx.Client, server: Server, log_path: Path, args: argparse.Namespace
) -> tuple[dict[str, Any], int]:
    """Phase 1: upload the log, run the SKF at full speed, wait until it is persisted."""
    bulk_latencies: list[float] = []
    stop = threading.Event()
    paths = ["/api/runs?limit=5", "/api/datasets"]
    pollers = [
        Worker(poller, server.base, paths, stop, bulk_latencies, args.poll_every)
        for _ in range(args.pollers)
    ]
    for th in pollers:
        th.start()
    t0 = time.perf_counter()
    with log_path.open("rb") as f:
        response = client.post("/api/datasets", files={"file": ("drive.csv", f)})
    response.raise_for_status()
    dataset = response.json()
    t1 = time.perf_counter()
    run = client.post("/api/runs", json=drive_run_body(dataset["id"])).json()
    done = server.wait_run(run["id"], ("succeeded", "failed"), args.timeout)
    t2 = time.perf_counter()
    stop.set()
    for th in pollers:
        th.result()
    if done["status"] != "succeeded":
        raise RuntimeError(f"the bulk run failed: {done['error']}")
    figures = {
        "upload_s": round(t1 - t0, 2),
        "run_and_persist_s": round(t2 - t1, 2),
        "estimator_s": round(done["metrics"]["run_s"], 3),
        "total_s": round(t2 - t0, 2),
        "rows_per_s": round(args.rows / (t2 - t0)),
        **(latency_figures("bulk", bulk_latencies) if args.pollers else {}),
    }
    return figures, int(dataset["id"])


def upload_once(client: httpx.Client, log_path: Path) -> int:
    """The log as a dataset for ``--live-only`` (no figures: phase 1 measures the upload)."""
    with log_path.open("rb") as f:
        response = client.post("/api/datasets", files={"file": ("drive.csv", f)})
    response.raise_for_status()
    return int(response.json()["id"])


def live_round(
    client: httpx.Client, server: Server, dataset_id: int, args: argparse.Namespace, encoding: str
) -> dict[str, Any]:
    """Phase 2: a paced run watched by ``args.viewers`` viewers reading ``encoding`` while 4
    clients poll; the figures' names end with the encoding."""
    duration_s = args.rows / 100.0
    pace = duration_s / (args.live_seconds * 1.5)
    live = client.post("/api/runs", json=drive_run_body(dataset_id, pace=pace)).json()
    server.wait_run(live["id"], ("running",), args.timeout)
    counts = [(0, 0)] * args.viewers
    ws_url = f"{server.ws_base}/api/runs/{live['id']}/stream?encoding={encoding}"
    threads = [Worker(viewer, ws_url, args.live_seconds, counts, i) for i in range(args.viewers)]
    latencies: list[float] = []
    stop = threading.Event()
    paths = [f"/api/runs/{live['id']}", "/api/datasets"]
    pollers = [
        Worker(poller, server.base, paths, stop, latencies, args.poll_every)
        for _ in range(args.pollers)
    ]
    api = psutil.Process(server.process.pid)
    loop0 = client.get("/api/health").json()["loop_cpu_s"]
    cpu0, t0 = sum(api.cpu_times()[:2]), time.monotonic()
    for th in threads + pollers:
        th.start()
    for th in threads:
        th.result()
    cpu1, t1 = sum(api.cpu_times()[:2]), time.monotonic()
    health = client.get("/api/health").json()
    loop_lag_ms, loop1 = health["loop_lag_ms"], health["loop_cpu_s"]
    stop.set()
    for th in pollers:
        th.result()
    client.post(f"/api/runs/{live['id']}/cancel")
    rates = [n / args.live_seconds for n, _ in counts]
    figures = {
        "frames_per_s_per_viewer_min": round(min(rates), 1),
        "frames_per_s_per_viewer_mean": round(statistics.mean(rates), 1),
        "frames_per_s_total": round(sum(rates), 1),
        "mb_per_s_total": round(sum(b for _, b in counts) / args.live_seconds / 2**20, 2),
        "api_cpu_pct": round(100 * (cpu1 - cpu0) / (t1 - t0), 1),
        "loop_busy_pct": round(100 * (loop1 - loop0) / (t1 - t0), 1),
        "loop_lag_ms": loop_lag_ms,
        **(latency_figures("live", latencies) if args.pollers else {}),
    }
    return {f"{key}_{encoding}": value for key, value in figures.items()}


def summarise(rounds: list[dict[str, Any]]) -> dict[str, Any]:
    """Median and worst of each figure over the rounds (worst: the slowest time, the
    lowest rate)."""
    out: dict[str, Any] = {}
    for key in rounds[0]:
        values = [r[key] for r in rounds]
        worst = min(values) if key.startswith(HIGHER_IS_BETTER) else max(values)
        out[key] = {"median": round(statistics.median(values), 3), "worst": worst}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--database-url", help="default: a fresh SQLite file")
    parser.add_argument("--rows", type=int, default=360_000)
    parser.add_argument("--viewers", type=int, default=20, help="per paced run, at most 100")
    parser.add_argument("--encoding", choices=["json", "binary", "both"], default="json")
    parser.add_argument("--live-seconds", type=float, default=20.0)
    parser.add_argument("--live-only", action="store_true", help="skip the bulk phase")
    parser.add_argument("--repeat", type=int, default=5, help="rounds; median and worst")
    parser.add_argument("--deflate", action="store_true", help="MAPWISE_WS_DEFLATE=true")
    parser.add_argument("--timeout", type=float, default=600.0, help="per run, seconds")
    parser.add_argument(
        "--pollers", type=int, default=4, help="clients polling the API meanwhile (latency)"
    )
    parser.add_argument(
        "--poll-every",
        type=float,
        default=0.0,
        help="seconds between a poller's rounds; 0 (default): back to back, a closed loop "
        "(the dashboard polls a run group once a second)",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.repeat < 1:
        parser.error("--repeat must be at least 1")
    if not 1 <= args.viewers <= 100:
        parser.error("--viewers must be 1 to 100 (a run admits 100 viewers)")
    encodings = ["json", "binary"] if args.encoding == "both" else [args.encoding]
    work = Path(tempfile.mkdtemp(prefix="mapwise-bench-"))
    url = args.database_url or f"sqlite:///{work / 'bench.db'}"
    log_path = work / "log.csv"
    make_log(log_path, args.rows)
    env = {
        "MAPWISE_WS_DEFLATE": "true" if args.deflate else "false",
        "MAPWISE_STORE_URL": (work / "store").as_uri(),  # removed with the rest at the end
    }
    server = Server(url, workers=None, env=env)
    result: dict[str, Any] = {
        "rows": args.rows,
        "channels": 12,
        "csv_mb": round(log_path.stat().st_size / 2**20, 1),
        "database": url.split(":")[0],
        "cpus": os.cpu_count(),
        "viewers": args.viewers,
        "encodings": ",".join(encodings),
        "live_seconds": args.live_seconds,
        "ws_deflate": args.deflate,
        "rounds": args.repeat,
        "pollers": args.pollers,
        "poll_every_s": args.poll_every,
    }
    rounds: list[dict[str, Any]] = []
    try:
        with httpx.Client(base_url=server.base, timeout=600) as client:
            warm_up(client, server, args.timeout)
            kept = upload_once(client, log_path) if args.live_only else None
            for _ in range(args.repeat):
                figures: dict[str, Any] = {}
                if kept is None:
                    figures, dataset_id = bulk_round(client, server, log_path, args)
                else:
                    dataset_id = kept
                for encoding in encodings:
                    figures |= live_round(client, server, dataset_id, args, encoding)
                rounds.append(figures)
                if kept is None:
                    client.delete(f"/api/datasets/{dataset_id}", params={"force": "true"})
        result["server_peak_rss_mb"] = peak_rss_mb(server.process.pid)
    finally:
        server.stop()
        shutil.rmtree(work, ignore_errors=True)
    result |= summarise(rounds)
    if args.json:
        print(json.dumps(result))
        return
    for key, value in result.items():
        if isinstance(value, dict):
            print(f"{key:<32} median {value['median']:<12} worst {value['worst']}")
        else:
            print(f"{key:<32} {value}")


if __name__ == "__main__":
    main()
