"""SQLite under contention: 20 run submissions within a second while 10 writers record
progress at 10 Hz (as run workers do), three times over — no "database is locked", every
submission stored (WAL, a busy timeout and BEGIN IMMEDIATE for every write)."""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import pytest
from fastapi.testclient import TestClient

from app.api import create_app
from app.db.engine import Database
from app.db.repositories import RunRepo
from tests.support.helpers import log_csv, run_body, service_settings, upload_ok


@pytest.mark.slow
def test_twenty_submissions_and_ten_progress_writers_never_lock(fresh_url) -> None:  # type: ignore[no-untyped-def]
    url = fresh_url("sqlite")
    settings = service_settings(url)  # its two run workers write too
    with TestClient(create_app(settings)) as client:
        dataset = upload_ok(client, log_csv(300, seed=95))
        body = run_body(dataset["id"])
        seed_runs = [client.post("/api/runs", json=body) for _ in range(10)]
        assert client.get("/api/runs").json()["total"] == 10, [r.text for r in seed_runs[:1]]
        targets = [r["id"] for r in client.get("/api/runs").json()["items"]]
        errors: list[BaseException] = []
        stop = threading.Event()

        def progress_writer(run_id: int) -> None:
            db = Database(url)  # its own engine and connections, like a worker process
            try:
                k = 0
                while not stop.is_set():
                    with db.write() as s:
                        RunRepo(s).progress(run_id, sample=k, progress=k / 1e6, rejected={})
                    k += 1
                    time.sleep(0.1)
            except BaseException as exc:
                errors.append(exc)
            finally:
                db.dispose()

        for _ in range(3):
            stop.clear()
            writers = [threading.Thread(target=progress_writer, args=(r,)) for r in targets]
            for w in writers:
                w.start()
            time.sleep(0.3)
            t0 = time.monotonic()
            with ThreadPoolExecutor(max_workers=20) as pool:
                responses = list(pool.map(lambda _: client.post("/api/runs", json=body), range(20)))
            submit_s = time.monotonic() - t0
            time.sleep(0.5)
            stop.set()
            for w in writers:
                w.join(timeout=30)
            assert [r.status_code for r in responses] == [201] * 20, [r.text for r in responses]
            assert submit_s < 5.0
        assert errors == []
        assert client.get("/api/runs").json()["total"] == 10 + 3 * 20
