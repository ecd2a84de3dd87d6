"""A bounded load test of a mapwise server on loopback (figures for the README; a short run of
it is a test, tests/app/service/test_load.py).

``--users`` concurrent users for ``--seconds``, each in a loop: upload a small CSV log, start
a paced SKF run on it, read the lists while watching its live stream to the end, read the
run, pause (0.5–2 s) and begin again. Besides them, ``--streams`` long runs stream the whole
time, each watched by a viewer from start to end (the soak's "8 streaming runs"). Then every
run started is waited for.
Reported: requests and requests/s, p50/p95/p99 latency, live frames/s delivered and their
delay from the worker to the viewer, errors (any non-2xx or transport error), lost runs
(started but not ``succeeded``) and, for a server started here, its memory growth between
the first and the last minute.

    .venv/bin/python scripts/load.py [--url URL | --database-url URL] [--users 10]
        [--streams 0] [--seconds 60] [--workers N] [--json]

A server started here gets ``--workers`` run workers (default: ``--streams`` + 2, so that
the long runs do not hold every worker).

The soak of README: ``--users 20 --streams 8 --seconds 1800 --warmup 60``: latencies and
frame delays are counted after the first minute (workers starting, first compilations), as
locust's ``--reset-stats`` does after its ramp-up; errors and lost runs count throughout.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import random
import re
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import websockets

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the shared server helper, when run as scripts/load.py

from tests.support.server import FINISHED as TERMINAL  # noqa: E402
from tests.support.server import Server, run_body  # noqa: E402

USER_WATCH_S = 60.0  # a user watches its run to the end, or this long
THINK_S = (0.5, 2.0)  # a user's pause between one run and the next


def small_log(seed: int, rows: int = 1000, rate_hz: float = 100.0) -> bytes:
    rng = np.random.default_rng(seed)
    t = np.arange(rows) / rate_hz
    u1, u2 = rng.uniform(400, 3600, rows), rng.uniform(-5, 65, rows)
    y = 1.0 + u1 / 1000.0 + u2 / 40.0 + rng.normal(0, 0.05, rows)
    lines = ["time [s],u1 [rpm],u2 [mg/stroke],y [ppm]"]
    lines += [f"{a:.4f},{b:.3f},{c:.3f},{d:.5f}" for a, b, c, d in zip(t, u1, u2, y, strict=True)]
    return ("\n".join(lines) + "\n").encode()


@dataclass
class Tally:
    latencies: list[float] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    frames: int = 0
    frame_delays: list[float] = field(default_factory=list)
    runs: list[int] = field(default_factory=list)
    cut: set[int] = field(default_factory=set)  # streaming runs cancelled at the end
    by_route: dict[str, list[float]] = field(default_factory=dict)
    measure_from: float = 0.0  # time.monotonic() after which latencies count (the warm-up)

    @property
    def measuring(self) -> bool:
        return time.monotonic() >= self.measure_from

    async def call(self, client: httpx.AsyncClient, method: str, path: str, **kw: Any) -> Any:
        t0 = time.perf_counter()
        try:
            response = await client.request(method, path, **kw)
        except httpx.HTTPError as exc:
            self.errors.append(f"{method} {path}: {exc!r}")
            return None
        if self.measuring:
            self.latencies.append(time.perf_counter() - t0)
            route = re.sub(r"/\d+", "/{id}", path.split("?")[0])
            self.by_route.setdefault(f"{method} {route}", []).append(self.latencies[-1])
        if response.status_code >= 400:
            self.errors.append(f"{method} {path}: {response.status_code} {response.text[:200]}")
            return None
        return response.json() if response.content else {}


async def watch(ws_url: str, seconds: float, tally: Tally, headers: dict[str, str]) -> None:
    end = time.monotonic() + seconds
    try:
        async with websockets.connect(ws_url, max_size=None, additional_headers=headers) as ws:
            while (left := end - time.monotonic()) > 0:
                try:
                    message = json.loads(await asyncio.wait_for(ws.recv(), timeout=left))
                except TimeoutError:
                    return
                if message["type"] in ("full", "delta"):
                    tally.frames += 1
                if message.get("emitted_at") and tally.measuring:
                    tally.frame_delays.append(time.time() - float(message["emitted_at"]))
                if message["type"] == "status" and message["status"] in TERMINAL:
                    return
    except (OSError, websockets.WebSocketException) as exc:
        tally.errors.append(f"WS {ws_url}: {exc!r}")


async def user(base: str, index: int, until: float, tally: Tally, token: str | None) -> None:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    ws_base = base.replace("http", "ws", 1)
    rng = random.Random(index)
    async with httpx.AsyncClient(base_url=base, headers=headers, timeout=60) as client:
        k = 0
        while time.monotonic() < until:
            k += 1
            files = {"file": (f"u{index}-{k}.csv", small_log(index * 1000 + k))}
            dataset = await tally.call(client, "POST", "/api/datasets", files=files)
            if dataset is None:
                continue
            body = run_body(dataset["id"], pace=rng.choice([5, 10, 20]))
            run = await tally.call(client, "POST", "/api/runs", json=body)
            if run is None:
                continue
            tally.runs.append(int(run["id"]))
            ws_url = f"{ws_base}/api/runs/{run['id']}/stream" + (f"?token={token}" if token else "")
            watcher = asyncio.create_task(watch(ws_url, USER_WATCH_S, tally, {}))
            for path in ("/api/runs?limit=20", "/api/datasets?limit=20"):
                await tally.call(client, "GET", path)
            await watcher
            await tally.call(client, "GET", f"/api/runs/{run['id']}")
            await asyncio.sleep(rng.uniform(*THINK_S))


async def streamer(base: str, index: int, until: float, tally: Tally, token: str | None) -> None:
    """A long paced run watched from its start to its end, restarted until ``until``."""
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    ws_base = base.replace("http", "ws", 1)
    async with httpx.AsyncClient(base_url=base, headers=headers, timeout=60) as client:
        files = {"file": (f"stream{index}.csv", small_log(10_000 + index, rows=12_000))}
        dataset = await tally.call(client, "POST", "/api/datasets", files=files)
        if dataset is None:
            return
        while (left := until - time.monotonic()) > 1.0:
            body = run_body(dataset["id"], pace=1)
            run = await tally.call(client, "POST", "/api/runs", json=body)
            if run is None:
                return
            tally.runs.append(int(run["id"]))
            ws_url = f"{ws_base}/api/runs/{run['id']}/stream" + (f"?token={token}" if token else "")
            await watch(ws_url, min(left, 130.0), tally, {})
            status = (await client.get(f"/api/runs/{run['id']}")).json()["status"]
            if status not in TERMINAL:  # the soak is over: cut the run (not a lost one)
                tally.cut.add(int(run["id"]))
                cancel = await client.post(f"/api/runs/{run['id']}/cancel")
                if cancel.status_code not in (200, 202, 409):  # 409: it ended meanwhile
                    tally.errors.append(f"cancel {run['id']}: {cancel.status_code}")


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


async def _sample_memory(pid: int | None, until: float, out: list[tuple[float, float]]) -> None:
    if pid is None:
        return
    t0 = time.monotonic()
    while time.monotonic() < until:
        out.append((time.monotonic() - t0, _rss_mb(pid)))
        await asyncio.sleep(5.0)


async def _settle(base: str, tally: Tally, token: str | None, timeout: float) -> list[int]:
    """Runs not ``succeeded`` once every started run had time to finish."""
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    deadline = time.monotonic() + timeout
    pending = set(tally.runs)
    statuses: dict[int, str] = {}
    async with httpx.AsyncClient(base_url=base, headers=headers, timeout=60) as client:
        while pending and time.monotonic() < deadline:
            for run_id in list(pending):
                doc = (await client.get(f"/api/runs/{run_id}")).json()
                if doc["status"] in TERMINAL:
                    statuses[run_id] = doc["status"]
                    pending.discard(run_id)
            await asyncio.sleep(0.5)
    ok = {
        r for r, s in statuses.items() if s == "succeeded" or (r in tally.cut and s == "cancelled")
    }
    return sorted(pending | (set(statuses) - ok))


def run_load(
    base: str,
    *,
    users: int,
    seconds: float,
    streams: int = 0,
    token: str | None = None,
    settle_s: float = 300.0,
    server_pid: int | None = None,
    warmup_s: float = 0.0,
) -> dict[str, Any]:
    tally = Tally(measure_from=time.monotonic() + warmup_s)
    memory: list[tuple[float, float]] = []

    async def main() -> list[int]:
        until = time.monotonic() + seconds
        await asyncio.gather(
            *(user(base, i, until, tally, token) for i in range(users)),
            *(streamer(base, i, until, tally, token) for i in range(streams)),
            _sample_memory(server_pid, until, memory),
        )
        return await _settle(base, tally, token, settle_s)

    t0 = time.perf_counter()
    lost = asyncio.run(main())
    elapsed = time.perf_counter() - t0
    delays = sorted(tally.frame_delays) or [float("nan")]
    return {
        "users": users,
        "seconds": seconds,
        "warmup_s": warmup_s,
        "requests": len(tally.latencies),
        "requests_per_s": round(len(tally.latencies) / max(seconds - warmup_s, 1e-9), 1),
        **{k: v for k, v in _percentiles(tally.latencies).items() if k != "n"},
        "frames": tally.frames,
        "frames_per_s": round(tally.frames / seconds, 1),
        "frame_delay_p99_s": round(delays[int(0.99 * (len(delays) - 1))], 3),
        "streams": streams,
        "memory_growth_pct": _growth(memory, seconds),
        "runs_started": len(tally.runs),
        "lost_runs": lost,
        "by_route": {
            route: _percentiles(values) for route, values in sorted(tally.by_route.items())
        },
        "errors": tally.errors[:20],
        "error_count": len(tally.errors),
        "wall_s": round(elapsed, 1),
    }


def _percentiles(seconds: list[float]) -> dict[str, float]:
    ms = sorted(1000 * x for x in seconds) or [float("nan")]
    return {
        "n": len(seconds),
        "p50_ms": round(statistics.median(ms), 1),
        "p95_ms": round(ms[int(0.95 * (len(ms) - 1))], 1),
        "p99_ms": round(ms[int(0.99 * (len(ms) - 1))], 1),
    }


def _growth(memory: list[tuple[float, float]], seconds: float) -> float | None:
    """Server memory of the last minute against the first (after a 60 s warm-up), percent."""
    if len(memory) < 4:
        return None
    window = min(60.0, seconds / 4)
    first = [m for t, m in memory if window <= t < 2 * window] or [memory[1][1]]
    last = [m for t, m in memory if t >= memory[-1][0] - window] or [memory[-1][1]]
    return round(100.0 * (statistics.mean(last) / statistics.mean(first) - 1.0), 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", help="a running server (default: start one)")
    parser.add_argument("--database-url", help="for the server started here (default SQLite)")
    parser.add_argument("--token", help="bearer token of --url")
    parser.add_argument("--users", type=int, default=10)
    parser.add_argument("--streams", type=int, default=0, help="long runs watched throughout")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--workers", type=int, help="run workers of the server started here")
    parser.add_argument(
        "--warmup",
        type=float,
        default=0.0,
        help="seconds at the start whose latencies are not counted (errors always are)",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    server = None
    if args.url is None:
        work = Path(tempfile.mkdtemp(prefix="mapwise-load-"))
        server = Server(
            args.database_url or f"sqlite:///{work / 'load.db'}",
            workers=args.workers or max(2, args.streams + 2),
        )
        args.url = server.base
    try:
        result = run_load(
            args.url,
            users=args.users,
            seconds=args.seconds,
            streams=args.streams,
            token=args.token,
            server_pid=None if server is None else server.process.pid,
            warmup_s=args.warmup,
        )
    finally:
        if server is not None:
            server.stop()
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:<20} {value}")
    sys.exit(0 if not result["error_count"] and not result["lost_runs"] else 1)


if __name__ == "__main__":
    main()
