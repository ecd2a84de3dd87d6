"""Peak memory of one run's worker on a wide log: ROWS × CHANNELS, the run reading three.

    .venv/bin/python scripts/run_memory.py --rows 2000000 --channels 12

builds a SQLite database and an artifact store in a temporary directory, stores a dataset
of ``u1 [rpm]``, ``u2 [mg/stroke]`` and ``y [ppm]`` (the 4×4 map of the service tests,
plus noise) and ``CHANNELS − 3`` further noise channels, plans an ``skf`` run on it (or, with
``--estimator``, a torque estimator reading ``u1`` as its speed, ``y`` as its load and ``u2``
as its air flow) as ``POST /api/runs`` would, and executes that run in a fresh worker process
(:func:`app.runs.worker.execute_run`). The worker first executes the same run on a short
log (imports, JIT compilation, database connections), then resets its peak resident set
(``/proc/self/clear_refs``) and executes the measured run: the printed growth is its peak
``VmHWM`` minus its ``VmRSS`` before the run, what the run itself needed at its largest.
An air-path observer (``--estimator lpv``, ``ekf-aug``, ``ekf-map``) runs instead on 600 s of
its scenario's log (``maf-whtc``, ``maf-1d-whtc``: every channel, ``--channels`` not used)
repeated to ``ROWS`` at 10 Hz, with the scenario's config for it. ``--recorded`` stores the
wide log as recorded (docs/data-formats.md#multi-rate): ``u1`` on its own jittered timestamps
at twice the rate, the other channels on theirs, so the run puts them on the raster of ``y``.
``--code DIR`` executes the worker from another checkout (e.g. ``git archive HEAD`` unpacked
there), to compare before and after a change.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from dataclasses import astuple, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from app.config import Settings
from app.db.engine import Database
from app.db.migrate import upgrade
from app.db.repositories import DatasetRepo
from app.domain import Channel
from app.io.resample import Track, span_of
from app.services.run_plan import RunRequest
from app.services.runs import RunService
from app.store import open_store, save_staged, stage_recorded, stage_signals
from estimation.scenarios import get_scenario
from estimation.signals import Signals
from estimation.table import Axis, Table
from tests.support.server import U1, U2, run_body

ROOT = Path(__file__).resolve().parents[1]
MIB = 1024 * 1024
USED = ("u1", "u2", "y")  # what the planned run reads: its table's axes and its output
RATE_HZ = 100.0
RANGE_GATE = {"type": "range", "channel": "u2", "max": 60.0}  # rejects about 7 %
TORQUE_ESTIMATORS = ("uio", "smo", "dirty", "adaptive-const", "adaptive-tv")
TORQUE_CHANNELS = {"speed_channel": "u1", "load_channel": "y"}  # an adaptive law's air: u2
AIRPATH_SCENARIOS = {"lpv": "maf-whtc", "ekf-aug": "maf-1d-whtc", "ekf-map": "maf-1d-whtc"}
AIRPATH_SECONDS = 600.0  # of the scenario's log, repeated to the rows asked for

PEAK_HELPERS = """
import gc
from pathlib import Path

def kib(field):
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise OSError(field)
"""
"""``kib(field)`` of /proc/self/status, for the measuring processes' scripts (this one's and
scripts/whole_read.py's)."""

_WORKER = (
    PEAK_HELPERS
    + """
import json, sys
from app.runs.worker import WorkerContext, execute_run

url, store, warm, run = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
context = WorkerContext(database_url=url, store_url=store, live_fps=1.0)
warmed = execute_run(warm, context)
gc.collect()
Path("/proc/self/clear_refs").write_text("5")  # VmHWM := VmRSS (Linux >= 4.0)
before = kib("VmRSS")
status = execute_run(run, context)
print(json.dumps({"warm": warmed, "status": status, "before_kib": before,
                  "peak_kib": kib("VmHWM")}))
"""
)


@dataclass(frozen=True, slots=True)
class Workbench:
    """A database and a store holding a short run (to warm a worker) and the measured one."""

    database_url: str
    store_url: str
    warm_run: int
    run: int
    log_bytes: int  # the measured dataset's time and channels as float64 arrays


@dataclass(frozen=True, slots=True)
class Peak:
    status: str
    before_bytes: int
    peak_bytes: int

    @property
    def growth_bytes(self) -> int:
        return self.peak_bytes - self.before_bytes


def wide_log(rows: int, channels: int, seed: int = 0) -> Signals:
    """``u1``, ``u2``, ``y = map(u1, u2) + noise`` and ``channels − 3`` noise channels
    ``x03``, ``x04``, … (random: they compress no better than measured channels)."""
    if channels < len(USED):
        raise ValueError(f"a wide log has at least {len(USED)} channels, not {channels}")
    rng = np.random.default_rng(seed)
    true_map = Table(
        [Axis("u1", "rpm", U1), Axis("u2", "mg/stroke", U2)],
        np.add.outer(np.array([1.0, 2.0, 3.5, 3.0]), np.array([0.0, 0.5, 1.5, 1.0])),
    )
    u = np.column_stack([rng.uniform(400, 3600, rows), rng.uniform(-5, 65, rows)])
    data = {"u1": u[:, 0].copy(), "u2": u[:, 1].copy()}
    data["y"] = true_map.evaluate(u) + rng.normal(0.0, 0.05, rows)
    del u
    for i in range(len(USED), channels):
        data[f"x{i:02d}"] = rng.normal(0.0, 1.0, rows)
    units = {"u1": "rpm", "u2": "mg/stroke", "y": "ppm"}
    return Signals(np.arange(rows) / RATE_HZ, data, units, copy=False)


def airpath_log(rows: int, estimator: str) -> tuple[Signals, dict[str, Any]]:
    """:data:`AIRPATH_SECONDS` of ``estimator``'s scenario repeated to ``rows`` samples (the
    time running on at the scenario's rate), and the scenario's config for ``estimator``."""
    scenario = get_scenario(AIRPATH_SCENARIOS[estimator])
    data = scenario.build(seed=0, duration_s=AIRPATH_SECONDS, mismatch="nominal")
    log = data.signals
    channels = {name: np.resize(log[name], rows) for name in log.names}
    time = np.arange(rows) / scenario.rate_hz
    return Signals(time, channels, log.units, copy=False), scenario.default_config(estimator, data)


def recorded_tracks(signals: Signals, seed: int = 0) -> list[Track]:
    """The wide log as channels recorded on their own timestamps: ``u1`` at twice the rate
    on jittered timestamps (each value held for two of them), the others on the log's."""
    rng = np.random.default_rng(seed)
    step = float(signals.time[1] - signals.time[0]) / 2.0
    fast = signals.time[0] + step * (np.arange(2 * len(signals)) + rng.uniform(-0.2, 0.2))
    tracks = [Track("u1", signals.units["u1"], fast, np.repeat(signals["u1"], 2), False)]
    for name in signals.names[1:]:
        tracks.append(Track(name, signals.units.get(name, ""), signals.time, signals[name], False))
    return tracks


def _add_dataset(
    db: Database, store_url: str, signals: Signals, name: str, recorded: bool = False
) -> int:
    store = open_store(store_url)
    channels = [Channel(n, signals.units.get(n, "")) for n in signals.names]
    if recorded:
        tracks = recorded_tracks(signals)
        staging = stage_recorded(store, tracks, dict(signals.units))
        spans = {t.name: span_of(t) for t in tracks}
        channels = [replace(c, timing=astuple(spans[c.name])[1:]) for c in channels]
    else:
        staging = stage_signals(store, signals)
    with staging as staged, db.write() as s:
        repo = DatasetRepo(s)
        dataset = repo.add(
            name=name,
            source="csv",
            rows=len(signals),
            rate_hz=1.0 / float(signals.time[1] - signals.time[0]),
            duration_s=float(signals.time[-1] - signals.time[0]),
            time_column="time",
            channels=channels,
        )
        repo.attach_samples(dataset.id, save_staged(store, dataset.id, staged), staged.sha256)
        return dataset.id


def _add_run(db: Database, dataset_id: int, estimator: str, config: dict[str, Any]) -> int:
    """A run of ``estimator`` on the dataset with service ``config`` (e.g. its gates), planned
    and stored as ``POST /api/runs`` does it: a map filter over the 4×4 table with output
    ``y``, a torque estimator with ``u1`` for its speed and ``y`` for its load, an air-path
    observer with its scenario's config (in ``config``)."""
    if estimator in AIRPATH_SCENARIOS:
        body = {"dataset_id": dataset_id, "estimator": estimator, "signals": {}, "config": config}
    elif estimator in TORQUE_ESTIMATORS:
        air = {"air_channel": "u2"} if estimator.startswith("adaptive") else {}
        body = {
            "dataset_id": dataset_id,
            "estimator": estimator,
            "signals": {},
            "config": TORQUE_CHANNELS | air | config,
        }
    else:
        body = run_body(dataset_id, estimator, **config)
    service = RunService(db, Settings(database_url=db.url), executor=None)
    with db.write() as s:
        return service.store_in(s, RunRequest(**body)).id


def workbench(
    directory: Path,
    rows: int,
    channels: int,
    config: dict[str, Any] | None = None,
    estimator: str = "skf",
    recorded: bool = False,
) -> Workbench:
    """The database (SQLite) and store under ``directory``, with both runs of ``estimator``
    queued (with the run config ``config``, e.g. ``{"gates": [...]}``), on datasets stored
    as recorded with ``recorded`` (:func:`recorded_tracks`)."""
    config = config or {}
    database_url = f"sqlite:///{directory / 'mapwise.db'}"
    store_url = (directory / "store").as_uri()
    upgrade(database_url, store_url=store_url)
    db = Database(database_url)
    try:
        if estimator in AIRPATH_SCENARIOS:
            short, run_config = airpath_log(4000, estimator)
            signals = airpath_log(rows, estimator)[0]
            config = config | run_config
        else:
            short, signals = wide_log(4000, channels, seed=1), wide_log(rows, channels)
        warm = _add_dataset(db, store_url, short, "warm-up", recorded)
        log_bytes = (len(signals.names) + 1) * len(signals) * 8
        measured = _add_dataset(db, store_url, signals, "wide", recorded)
        del signals
        return Workbench(
            database_url,
            store_url,
            _add_run(db, warm, estimator, config),
            _add_run(db, measured, estimator, config),
            log_bytes,
        )
    finally:
        db.dispose()


def worker_peak(bench: Workbench, code: Path = ROOT, timeout_s: float = 600.0) -> Peak:
    """Execute the measured run in a fresh worker process (module docstring)."""
    env = os.environ | {"PYTHONPATH": str(code), "OPENBLAS_NUM_THREADS": "1"}
    args = [bench.database_url, bench.store_url, str(bench.warm_run), str(bench.run)]
    done = subprocess.run(
        [sys.executable, "-c", _WORKER, *args],
        capture_output=True,
        text=True,
        cwd=code,
        env=env,
        timeout=timeout_s,
        check=False,
    )
    if done.returncode != 0:
        raise RuntimeError(f"the worker exited {done.returncode}: {done.stderr[-2000:]}")
    out = json.loads(done.stdout.strip().splitlines()[-1])
    if out["warm"] != "succeeded":
        raise RuntimeError(f"the warm-up run {out['warm']}")
    return Peak(out["status"], out["before_kib"] * 1024, out["peak_kib"] * 1024)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", type=int, default=2_000_000)
    parser.add_argument("--channels", type=int, default=12)
    parser.add_argument("--code", type=Path, default=ROOT, help="the checkout to execute")
    parser.add_argument(
        "--gate", action="store_true", help="with a range gate on u2 (<= 60 mg/stroke)"
    )
    parser.add_argument(
        "--estimator",
        default="skf",
        choices=["skf", *TORQUE_ESTIMATORS, *AIRPATH_SCENARIOS],
        help="skf on the 4×4 map, a torque estimator (speed u1, load y, air u2), or an "
        "air-path observer on its scenario's log",
    )
    parser.add_argument(
        "--recorded",
        action="store_true",
        help="store the log as recorded, u1 at twice the rate (module docstring)",
    )
    args = parser.parse_args()
    if (args.gate or args.recorded) and args.estimator in AIRPATH_SCENARIOS:
        parser.error("--gate and --recorded apply to the wide log, not an air-path log")
    config = {"gates": [RANGE_GATE]} if args.gate else {}
    with tempfile.TemporaryDirectory(prefix="mapwise-run-memory-") as tmp:
        bench = workbench(
            Path(tmp), args.rows, args.channels, config, args.estimator, args.recorded
        )
        peak = worker_peak(bench, args.code.resolve())
    print(
        f"{args.rows} rows ({bench.log_bytes / MIB:.0f} MiB as float64), {args.estimator}"
        f"{' gated' if args.gate else ''}{' as recorded' if args.recorded else ''}: run "
        f"{peak.status}, "
        "worker RSS "
        f"{peak.before_bytes / MIB:.0f} MiB before the run, peak {peak.peak_bytes / MIB:.0f} "
        f"MiB: +{peak.growth_bytes / MIB:.0f} MiB"
    )


if __name__ == "__main__":
    main()
