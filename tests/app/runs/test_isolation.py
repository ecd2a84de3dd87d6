"""Isolation of runs from each other's crashes, and the OS memory limit of a run:

* 20 random ``kill -9``s of run workers during 8 runs on a real server with the default
  lost-run policy: a kill loses at most the attempt of the run its worker executed (read
  from the worker's name, ``mw-run-<id>``, while it is stopped), every other run completes
  without a manual step, and every map — resumed or not — equals an uninterrupted run's;
* a run that exceeds its memory limit fails with the out-of-memory message, its worker
  lives on, and a concurrent run succeeds;
* the limit itself: an allocation beyond the budget raises ``MemoryError``, and the limit is
  lifted afterwards.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from app.db.engine import Database
from app.db.repositories import RunRepo
from app.runs.limits import out_of_memory_message
from tests.support.helpers import log_csv, reference_run, run_body, start_run, upload_ok
from tests.support.server import FINISHED, U1, U2, Server

KILLS = 20
RUNS = 8


def _name(pid: int) -> str:
    """What the process calls itself: ``mw-run-<id>`` while a worker executes run ``<id>``."""
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except FileNotFoundError:
        return ""


def _stop_and_name(pid: int) -> str | None:
    """Stop ``pid`` (so it cannot move on to another run) and read its name; ``None`` if it
    is gone."""
    try:
        os.kill(pid, signal.SIGSTOP)
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except (ProcessLookupError, FileNotFoundError):
        return None


def _claimed(server: Server, name: str) -> bool:
    """Whether the (stopped) worker called ``name`` holds an attempt of its run: the run is
    ``running`` once the worker's claim has committed."""
    if not name.startswith("mw-run-"):
        return False
    return server.get(f"/api/runs/{name.removeprefix('mw-run-')}")["status"] == "running"


def _resume_interrupted(server: Server, ids: list[int], killed: dict[int, int]) -> None:
    """The default policy leaves a run whose worker was killed interrupted: resume it (only
    a killed run may need this). One request lists the interrupted runs, not one per run in
    ``ids``: the storm calls this between kills."""
    interrupted = server.get("/api/runs", params={"status": "interrupted", "limit": 100})
    assert interrupted["total"] == len(interrupted["items"]), interrupted["total"]
    for run in interrupted["items"]:
        if run["id"] not in ids:
            continue
        assert run["id"] in killed, run  # an innocent run was interrupted
        response = server.post(f"/api/runs/{run['id']}/resume")
        assert response.status_code == 200, response.text


@pytest.mark.slow
def test_twenty_worker_kills_lose_only_the_killed_runs_attempts(
    backend: str,
    fresh_url,  # type: ignore[no-untyped-def]
    tmp_path: Path,
) -> None:
    server = Server(fresh_url(backend), workers=4)
    rng = random.Random(15)
    killed: dict[int, int] = {}  # run id -> kills of the worker executing it
    idle_kills = 0
    try:
        text = log_csv(2000, seed=151, rate_hz=100.0)  # 20 s of log
        dataset = upload_ok(server.http, text)
        body = run_body(dataset["id"], pace=2, version_every={"samples": 200})  # 10 s a run
        ids = [int(start_run(server.http, body)["id"]) for _ in range(RUNS)]
        deadline = time.monotonic() + 300  # a bound against a hang, not a speed check
        kills = 0
        while kills < KILLS:
            assert time.monotonic() < deadline, server.output()
            time.sleep(rng.uniform(0.1, 1.0))
            _resume_interrupted(server, ids, killed)
            workers = server.workers()
            if kills % 2:  # every other kill hits a worker that executes a run
                workers = [pid for pid in workers if _name(pid).startswith("mw-run-")]
            if not workers:
                continue
            pid = rng.choice(workers)
            name = _stop_and_name(pid)
            if name is None:
                continue
            if kills % 2 and not _claimed(server, name):
                # Named for its run but not yet holding an attempt (still loading it): a
                # kill here loses nothing, so it would not test what this kill is for.
                os.kill(pid, signal.SIGCONT)
                continue
            os.kill(pid, signal.SIGKILL)
            kills += 1
            if name.startswith("mw-run-"):
                run_id = int(name.removeprefix("mw-run-"))
                killed[run_id] = killed.get(run_id, 0) + 1
            else:
                idle_kills += 1  # idle or still starting: no run may lose anything
        runs = {}
        for run_id in ids:
            while True:
                run = server.wait_run(run_id, FINISHED, timeout=120)
                if run["status"] != "interrupted":
                    break
                _resume_interrupted(server, [run_id], killed)
            runs[run_id] = run
        expected = reference_run(text, tmp_path, "skf")["values"]
        for run_id, run in runs.items():
            assert run["status"] == "succeeded", run
            # Each attempt after the first replaced one lost by a kill of its own worker.
            assert run["attempt"] - 1 <= killed.get(run_id, 0), (run, killed)
            got = server.get(f"/api/runs/{run_id}/export", params={"format": "json"})
            np.testing.assert_array_equal(np.array(got["values"]), expected)
            steps = [v["step"] for v in server.get(f"/api/runs/{run_id}/versions")["items"]]
            assert steps == sorted(set(steps)), steps  # nothing written twice
        assert sum(r["attempt"] - 1 for r in runs.values()) > 0, killed  # kills hit runs
        assert server.get("/api/runs", params={"status": "running"})["total"] == 0
    finally:
        server.stop()


def _hungry_copy(url: str, template_id: int, breakpoints: int) -> int:
    """A queued copy of run ``template_id`` (a ``kf``) on a ``breakpoints``² grid, stored
    directly: a run the cost model let through although it needs more than its budget."""
    grid = [
        {**axis, "breakpoints": list(np.linspace(lo, hi, breakpoints))}
        for axis, (lo, hi) in zip(
            _template(url, template_id).estimator_config["axes"],
            [(U1[0], U1[-1]), (U2[0], U2[-1])],
            strict=True,
        )
    ]
    return _copy(url, template_id, axes=grid)


def _template(url: str, run_id: int) -> Any:
    db = Database(url)
    try:
        with db.read() as s:
            return RunRepo(s).get(run_id)
    finally:
        db.dispose()


def _copy(url: str, run_id: int, *, axes: Any = None, **config: Any) -> int:
    run = _template(url, run_id)
    estimator_config = dict(run.estimator_config)
    table_spec = dict(run.table or {})
    if axes is not None:
        estimator_config["axes"] = axes
        table_spec["axes"] = axes
    db = Database(url)
    try:
        with db.write() as s:
            return (
                RunRepo(s)
                .add(
                    dataset_id=run.dataset_id,
                    name=run.name,
                    estimator=run.estimator,
                    signals=run.signals,
                    table_spec=table_spec,
                    config=run.config | config,
                    estimator_config=estimator_config,
                    produces_map=run.produces_map,
                    n_samples=run.n_samples,
                    base_map_id=None,
                )
                .id
            )
    finally:
        db.dispose()


@pytest.mark.slow
def test_a_run_over_its_memory_limit_fails_alone(backend: str, fresh_url) -> None:  # type: ignore[no-untyped-def]
    url = fresh_url(backend)
    first = Server(url, workers=2)
    try:
        dataset = upload_ok(first.http, log_csv(2000, seed=152, rate_hz=100.0))
        template = int(start_run(first.http, run_body(dataset["id"], "kf"))["id"])
        assert first.wait_run(template, FINISHED)["status"] == "succeeded"
    finally:
        first.stop()
    # The full KF's covariance on an 80×80 grid is 6400² doubles, 312 MiB: over the smallest
    # budget, 256 MiB (never allocated: the allocation fails). The other run is a copy of
    # the template on the same server; when its worker claims it is a matter of start-up.
    hungry = _hungry_copy(url, template, 80)
    modest = _copy(url, template, pace=4)
    server = Server(url, workers=2, env={"MAPWISE_RUN_MEMORY_MB": "256"})
    try:
        failed = server.wait_run(hungry, FINISHED, timeout=60)
        assert failed["status"] == "failed", failed
        assert failed["error"] == out_of_memory_message(256), failed
        assert (failed["attempt"], failed["lost_attempts"]) == (1, 0)  # its worker lived on
        done = server.wait_run(modest, FINISHED, timeout=60)
        assert done["status"] == "succeeded", done
        assert (done["attempt"], done["lost_attempts"]) == (1, 0)
    finally:
        server.stop()


_LIMIT_CHILD = """
import resource
import numpy as np
from app.runs.limits import MIB, memory_limit

before = resource.getrlimit(resource.RLIMIT_DATA)
try:
    with memory_limit(32):
        np.ones(64 * MIB // 8)
    print("allocated")
except MemoryError:
    print("MemoryError")
assert resource.getrlimit(resource.RLIMIT_DATA) == before
assert np.ones(64 * MIB // 8).sum() == 64 * MIB // 8  # allowed again
with memory_limit(None):
    assert resource.getrlimit(resource.RLIMIT_DATA) == before
print("lifted")
"""


def test_memory_limit_raises_memory_error_then_lifts() -> None:
    # A fresh process: in a long-lived one, malloc may serve the allocation from free heap
    # it already holds (counted in VmData before the limit was set), as a worker reusing
    # memory between runs would.
    result = subprocess.run(
        [sys.executable, "-c", _LIMIT_CHILD],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=Path(__file__).resolve().parents[3],
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["MemoryError", "lifted"]


def test_out_of_memory_message_names_the_limit_and_setting() -> None:
    assert out_of_memory_message(2048) == (
        "out of memory: the run exceeded its 2048 MiB limit (MAPWISE_RUN_MEMORY_MB)"
    )
