"""Big-log benchmark (figures for the data path; not a test): a dense CSV of ``--rows`` rows
at 100 Hz (10 million by default: 27.8 hours, 1.2 GB) uploaded to and run on a real
``mapwise serve`` process, end to end.

1. Write the log into a temporary directory a block of ``--block-rows`` rows at a time
   (:func:`scripts.run_memory.wide_log`'s ``u1 [rpm]``, ``u2 [mg/stroke]``, ``y [ppm]`` and
   nine noise channels ``x03`` … ``x11``, plus ``time [s]``; every cell a finite number with
   at most six decimals, as :func:`scripts.bench_service.make_log` writes them), so this
   script holds one block whatever the size.
2. Start a server on a SQLite database and an artifact store in that directory, warm its run
   workers (:func:`scripts.bench_service.warm_up`), then upload the file with
   ``POST /api/datasets`` (multipart, streamed from disk: the server streams a dense CSV into
   the store, `docs/data-formats.md#streamed-uploads`) and run the SKF on ``y`` over the
   12×18 ``u1`` × ``u2`` grid of bench_service.py's breakpoints (a map filter on an uploaded
   log reads it from the store a window at a time, :func:`app.runs.options.streams_input`),
   polling ``GET /api/runs/{id}`` until it finishes: wall time and rows/s of each phase, and
   the run's own metrics.
3. Throughout, every 50 ms, the resident memory (``VmRSS``) of the API process and of each of
   its children (the run workers: spawned pool processes), the peak per phase; and their
   ``VmHWM`` at the end (reset after the warm-up where ``/proc/PID/clear_refs`` allows, so it
   covers the upload and the run).

    .venv/bin/python scripts/bench_big_log.py [--rows 10000000] [--block-rows 1000000]
        [--timeout 3600] [--json]

The temporary directory (log, database, store) is deleted at the end, on failure too.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the shared helpers, when run as scripts/bench_big_log.py

from scripts.bench_service import FUEL, SPEED, warm_up  # noqa: E402
from scripts.run_memory import RATE_HZ, wide_log  # noqa: E402
from tests.support.server import FINISHED, Server, run_body  # noqa: E402

CHANNELS = 12
DECIMALS = 6  # as bench_service.make_log's "%.6f": a logger's export, not float64's 17 digits
MIB = 1024 * 1024
SAMPLE_S = 0.05


def csv_header(names: list[str], units: dict[str, str]) -> str:
    """``time [s],u1 [rpm],…,x03,…``: units as ``name [unit]``, unquoted."""
    cells = ["time [s]"] + [f"{n} [{units[n]}]" if units.get(n) else n for n in names]
    return ",".join(cells) + "\n"


def log_blocks(rows: int, block_rows: int) -> Iterator[tuple[pa.RecordBatch, str]]:
    """The log a block at a time (each block its own seed and its own time span), with the
    CSV header; values rounded to :data:`DECIMALS`."""
    for index, start in enumerate(range(0, rows, block_rows)):
        n = min(block_rows, rows - start)
        signals = wide_log(n, CHANNELS, seed=index)
        columns = {"time": np.round(np.arange(start, start + n) / RATE_HZ, DECIMALS)}
        columns |= {name: np.round(signals[name], DECIMALS) for name in signals.names}
        yield pa.RecordBatch.from_pydict(columns), csv_header(signals.names, signals.units)


def write_log(path: Path, rows: int, block_rows: int) -> None:
    """The dense CSV: the header written here, each block by ``pyarrow.csv`` without one."""
    options = pa_csv.WriteOptions(include_header=False)
    with path.open("wb") as f:
        for i, (batch, header) in enumerate(log_blocks(rows, block_rows)):
            if i == 0:
                f.write(header.encode())
            pa_csv.write_csv(batch, f, options)


def grid_run_body(dataset_id: int) -> dict[str, Any]:
    """The SKF on ``y`` over the 12×18 grid of bench_service.py's breakpoints, on ``u1`` ×
    ``u2`` (the service tests' noises, which suit :func:`wide_log`'s map)."""
    table = {
        "axes": [
            {"name": "u1", "breakpoints": SPEED},
            {"name": "u2", "breakpoints": FUEL},
        ]
    }
    return run_body(dataset_id, table=table)


def proc_kib(pid: int, *fields: str) -> dict[str, int]:
    """``fields`` of ``/proc/PID/status`` in KiB (those it has); empty once it is gone."""
    out: dict[str, int] = {}
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return out
    for line in text.splitlines():
        key, _, value = line.partition(":")
        if key in fields:
            out[key] = int(value.split()[0])
    return out


def reset_peak(pid: int) -> bool:
    """``VmHWM := VmRSS`` (``/proc/PID/clear_refs``, Linux ≥ 4.0); whether it was allowed."""
    try:
        Path(f"/proc/{pid}/clear_refs").write_text("5")
    except OSError:
        return False
    return True


def is_worker(pid: int) -> bool:
    """A run worker: a spawned pool process (as :meth:`Server.workers` tells them)."""
    try:
        return b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False


@dataclass
class MemorySampler:
    """Samples the API process and its children every :data:`SAMPLE_S` in a thread: the
    largest ``VmRSS`` per (phase, role) and the last ``VmHWM`` read of each process."""

    server: Server
    phase: str = "start"
    peak_rss_kib: dict[tuple[str, str], int] = field(default_factory=dict)
    hwm_kib: dict[int, int] = field(default_factory=dict)
    roles: dict[int, str] = field(default_factory=dict)
    samples: int = 0
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None

    def processes(self) -> dict[int, str]:
        """The API process and its children now, each with its role."""
        api = self.server.process.pid
        try:
            children = self.server.children()
        except OSError:  # the server is exiting
            children = []
        for pid in children:
            if pid not in self.roles:
                self.roles[pid] = "worker" if is_worker(pid) else "other"
        return {api: "api"} | {pid: self.roles[pid] for pid in children}

    def sample(self) -> None:
        for pid, role in self.processes().items():
            kib = proc_kib(pid, "VmRSS", "VmHWM")
            if "VmRSS" in kib:
                key = (self.phase, role)
                self.peak_rss_kib[key] = max(self.peak_rss_kib.get(key, 0), kib["VmRSS"])
            if "VmHWM" in kib:
                self.hwm_kib[pid] = kib["VmHWM"]
            self.roles.setdefault(pid, role)
        self.samples += 1

    def _loop(self) -> None:
        while not self._stop.is_set():
            self.sample()
            self._stop.wait(SAMPLE_S)

    def start(self) -> None:
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self.sample()  # the last VmHWM of every process still there

    def peak_mib(self, phase: str | None, role: str) -> float | None:
        """The largest ``VmRSS`` of ``role`` during ``phase`` (``None``: any), MiB."""
        values = [
            kib for (p, r), kib in self.peak_rss_kib.items() if r == role and phase in (None, p)
        ]
        return round(max(values) / 1024, 1) if values else None

    def hwm_mib(self, role: str) -> float | None:
        values = [kib for pid, kib in self.hwm_kib.items() if self.roles.get(pid) == role]
        return round(max(values) / 1024, 1) if values else None


def loadavg() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def bench(args: argparse.Namespace, work: Path) -> dict[str, Any]:
    """Generate, serve, upload, run (module docstring); the figures."""
    result: dict[str, Any] = {
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "command": shlex.join([sys.executable, *sys.argv]),
        "nproc": len(os.sched_getaffinity(0)),
        "loadavg_start": loadavg(),
        "rows": args.rows,
        "channels": CHANNELS,
    }
    log_path = work / "log.csv"
    t0 = time.perf_counter()
    write_log(log_path, args.rows, args.block_rows)
    result["generate_s"] = round(time.perf_counter() - t0, 1)
    size = log_path.stat().st_size
    result["csv_mib"] = round(size / MIB, 1)

    database_url = f"sqlite:///{work / 'mapwise.db'}"
    store = {"MAPWISE_STORE_URL": (work / "store").as_uri()}
    server = Server(database_url, workers=args.workers, env=store)
    sampler = MemorySampler(server)
    try:
        with httpx.Client(base_url=server.base, timeout=args.timeout) as client:
            warm_up(client, server, args.timeout)
            sampler.sample()
            pids = [server.process.pid, *server.children()]
            result["vmhwm_reset"] = all(reset_peak(pid) for pid in pids)
            sampler.start()

            sampler.phase = "upload"
            t0 = time.perf_counter()
            with log_path.open("rb") as f:  # httpx sends a file object a chunk at a time
                response = client.post("/api/datasets", files={"file": ("big.csv", f)})
            upload_s = time.perf_counter() - t0
            if response.status_code >= 400:
                raise RuntimeError(f"upload refused: {response.status_code} {response.text}")
            dataset = response.json()
            if dataset["rows"] != args.rows:
                raise RuntimeError(f"the dataset has {dataset['rows']} rows, not {args.rows}")
            result |= {
                "upload_s": round(upload_s, 2),
                "upload_rows_per_s": round(args.rows / upload_s),
                "upload_mib_per_s": round(size / MIB / upload_s, 1),
            }

            sampler.phase = "run"
            t0 = time.perf_counter()
            response = client.post("/api/runs", json=grid_run_body(dataset["id"]))
            if response.status_code >= 400:
                raise RuntimeError(f"run refused: {response.status_code} {response.text}")
            run = server.wait_run(response.json()["id"], FINISHED, args.timeout)
            run_s = time.perf_counter() - t0
            sampler.phase = "end"
            if run["status"] != "succeeded":
                raise RuntimeError(f"the run {run['status']}: {run.get('error')}")
            result |= {
                "run_wall_s": round(run_s, 2),
                "run_samples_per_s": round(args.rows / run_s),
                "run_metrics": run["metrics"],
            }
    finally:
        sampler.stop()
        server.stop()
    result |= {
        "api_rss_mib_before": sampler.peak_mib("start", "api"),
        "api_peak_rss_mib_upload": sampler.peak_mib("upload", "api"),
        "api_peak_rss_mib_run": sampler.peak_mib("run", "api"),
        "api_vmhwm_mib": sampler.hwm_mib("api"),
        "worker_rss_mib_before": sampler.peak_mib("start", "worker"),
        "worker_peak_rss_mib_upload": sampler.peak_mib("upload", "worker"),
        "worker_peak_rss_mib_run": sampler.peak_mib("run", "worker"),
        "worker_vmhwm_mib": sampler.hwm_mib("worker"),
        "workers_seen": sum(role == "worker" for role in sampler.roles.values()),
        "other_children_peak_rss_mib": sampler.peak_mib(None, "other"),
        "memory_samples": sampler.samples,
        "loadavg_end": loadavg(),
    }
    return result


def report(r: dict[str, Any]) -> str:
    m = r["run_metrics"]
    reset = "since the warm-up" if r["vmhwm_reset"] else "since start (reset not allowed)"
    lines = [
        f"date            {r['date']}",
        f"command         {r['command']}",
        f"machine         nproc {r['nproc']}; load average {r['loadavg_start']} at start, "
        f"{r['loadavg_end']} at end",
        f"log             {r['rows']:,} rows × {r['channels']} channels + time at 100 Hz, "
        f"CSV {r['csv_mib']:,} MiB (written in {r['generate_s']} s)",
        f"upload          {r['upload_s']} s: {r['upload_rows_per_s']:,} rows/s, "
        f"{r['upload_mib_per_s']} MiB/s",
        f"run (skf 12×18) {r['run_wall_s']} s wall (POST to finished): "
        f"{r['run_samples_per_s']:,} samples/s; run_s {m.get('run_s')}",
        f"run metrics     {json.dumps(m)}",
        f"API process     VmRSS {r['api_rss_mib_before']} MiB before the upload; peak "
        f"VmRSS {r['api_peak_rss_mib_upload']} MiB during the upload, "
        f"{r['api_peak_rss_mib_run']} MiB during the run; VmHWM {r['api_vmhwm_mib']} MiB "
        f"({reset})",
        f"run worker(s)   VmRSS {r['worker_rss_mib_before']} MiB before the upload (largest); "
        f"peak VmRSS {r['worker_peak_rss_mib_run']} MiB during the run "
        f"({r['worker_peak_rss_mib_upload']} MiB during the upload); VmHWM "
        f"{r['worker_vmhwm_mib']} MiB ({reset}); {r['workers_seen']} workers",
        f"other children  peak VmRSS {r['other_children_peak_rss_mib']} MiB",
        f"sampling        every {SAMPLE_S * 1000:.0f} ms, {r['memory_samples']} samples",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", type=int, default=10_000_000)
    parser.add_argument("--block-rows", type=int, default=1_000_000, help="rows written at once")
    parser.add_argument("--workers", type=int, default=2, help="the server's run workers")
    parser.add_argument("--timeout", type=float, default=3600.0, help="upload and run, seconds")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.rows < 1 or args.block_rows < 1:
        parser.error("--rows and --block-rows must be positive")
    # SIGTERM unwinds like Ctrl-C, so the temporary directory (the log: GBs) is deleted.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    with tempfile.TemporaryDirectory(prefix="mapwise-big-log-") as tmp:
        result = bench(args, Path(tmp))
    print(json.dumps(result) if args.json else report(result))


if __name__ == "__main__":
    main()
