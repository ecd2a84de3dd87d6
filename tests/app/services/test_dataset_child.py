"""Simulations and uploads read whole execute in the server's dataset child
(app/services/dataset_child.py): one child started at the first and reused; a child killed
mid-simulation is a 500 that says how, stores nothing, and the next request starts a new
child."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.db.engine import Database
from app.db.migrate import upgrade
from app.errors import AppError, InvalidRequestError
from app.io.errors import InputError
from app.services.dataset_child import DatasetChild, SimulationRequest
from app.services.datasets import DatasetService
from app.store import open_store
from tests.support.helpers import log_csv, service_settings


def _simulator(client: TestClient) -> DatasetChild:
    child = client.app.state.services.datasets.child  # type: ignore[attr-defined]
    assert child is not None  # a file database and a local store: a child can reach them
    return child


def test_one_child_simulates_in_turn_and_errors_keep_their_field(client: TestClient) -> None:
    first = client.post("/api/datasets/simulate", json={"scenario": "skf-sim2", "duration_s": 5})
    assert first.status_code == 201, first.text
    pid = _simulator(client).pid()
    assert pid is not None
    assert pid != os.getpid()
    second = client.post("/api/datasets/simulate", json={"scenario": "skf-sim1", "seed": 3})
    assert second.status_code == 201, second.text
    assert _simulator(client).pid() == pid  # the same child, kept between simulations
    assert second.json()["seed"] == 3
    # An error raised in the child keeps its class and field: a duration the route would
    # have refused first, asked of the child directly.
    request = SimulationRequest("skf-sim2", 0, None, 1e-9, "nominal")
    with pytest.raises(InvalidRequestError, match="duration must be in") as raised:
        _simulator(client).simulate(request, None)
    assert raised.value.field == "duration_s"
    assert _simulator(client).pid() == pid


def test_a_killed_child_is_a_500_stores_nothing_and_is_replaced(client: TestClient) -> None:
    before = client.get("/api/datasets?limit=1").json()["total"]
    lines: list[dict] = []

    def stream() -> None:
        body = {"scenario": "maf-whtc", "seed": 11}
        with client.stream("POST", "/api/datasets/simulate/stream", json=body) as response:
            for line in response.iter_lines():
                lines.append(json.loads(line))

    reader = threading.Thread(target=stream)
    reader.start()
    deadline = time.monotonic() + 60
    while not any(line.get("progress", 0) > 0 for line in lines):  # the plant integrates
        assert time.monotonic() < deadline, lines
        assert reader.is_alive(), lines
        time.sleep(0.02)
    killed = _simulator(client).pid()
    assert killed is not None
    os.kill(killed, signal.SIGKILL)
    reader.join(60)
    assert lines[-1]["status"] == 500, lines[-1]
    assert "killed by SIGKILL" in lines[-1]["error"]["message"]
    assert client.get("/api/datasets?limit=1").json()["total"] == before

    again = client.post("/api/datasets/simulate", json={"scenario": "skf-sim2", "duration_s": 5})
    assert again.status_code == 201, again.text
    assert _simulator(client).pid() not in (None, killed)


def _mdf4(path: Path, samples: int, seed: int = 0) -> Path:
    """One ``rpm`` channel at 100 Hz, written by asammdf."""
    from asammdf import MDF, Signal

    t = np.arange(samples) * 0.01
    values = np.random.default_rng(seed).uniform(800, 6000, samples)
    mdf = MDF(version="4.10")
    mdf.append([Signal(values, t, name="rpm", unit="1/min")])
    mdf.save(path, overwrite=True)
    return path


def _upload(service: DatasetService, source: Any, name: str) -> Any:
    return service.upload(
        source, filename=name, name=None, units=None, max_bytes=1 << 30, max_whole_bytes=1 << 30
    )


@contextlib.contextmanager
def _service(database_url: str, memory_mb: float) -> Iterator[DatasetService]:
    """A dataset service with a child, as the server makes it, on the module's database."""
    settings = service_settings(database_url)
    upgrade(database_url, store_url=settings.store_url)
    db = Database(database_url)
    service = DatasetService(db, open_store(settings.store_url), in_child=True, memory_mb=memory_mb)
    try:
        yield service
    finally:
        service.close()
        db.dispose()


@pytest.fixture
def service(database_url: str) -> Iterator[DatasetService]:
    with _service(database_url, 512) as service:
        yield service


def test_uploads_read_whole_execute_in_the_child(service: DatasetService, tmp_path: Path) -> None:
    """A CSV under 1 MiB is read in the server; an MDF4 log is read by the child, whichever
    way the file comes: a path, an open file (its descriptor passed), bytes. The stored
    samples are the file's."""
    small = tmp_path / "small.csv"
    small.write_text(log_csv(500))
    assert _upload(service, small, "small.csv").rows == 500
    assert service.child is not None
    assert service.child.pid() is None  # not started: read here
    path = _mdf4(tmp_path / "log.mf4", 3000)
    with path.open("rb") as file:
        sources = [path, file, path.read_bytes()]
        datasets = [_upload(service, source, "log.mf4") for source in sources]
    pid = service.child.pid()
    assert pid not in (None, os.getpid())
    for dataset in datasets:
        assert (dataset.source, dataset.rows) == ("mdf4", 3000)
        _, signals = service.signals(dataset.id)
        expected = np.random.default_rng(0).uniform(800, 6000, 3000)
        np.testing.assert_array_equal(signals["rpm"], expected)
        np.testing.assert_array_equal(signals.time, np.arange(3000) * 0.01)
    assert service.child.pid() == pid  # one child, kept


def test_an_upload_predicted_over_the_memory_budget_is_a_413_before_it_is_read(
    database_url: str, tmp_path: Path
) -> None:
    """An MDF4 file of 64 MB is predicted to need 5 × its size to read whole
    (WHOLE_READ_FACTOR): over a 64 MiB budget it is refused naming ``file`` and the
    prediction, before any child starts, and nothing is stored."""
    with _service(database_url, 64) as service:
        before = service.list(limit=1, offset=0).total
        big = _mdf4(tmp_path / "big.mf4", 4_000_000)
        with pytest.raises(InputError, match=r"predicted\) > 64 MiB budget") as raised:
            _upload(service, big, "big.mf4")
        assert (raised.value.field, raised.value.status) == ("file", 413)
        assert service.child is not None
        assert service.child.pid() is None
        assert service.list(limit=1, offset=0).total == before


def test_a_child_out_of_memory_answers_then_leaves_for_a_new_one(database_url: str) -> None:
    """Under a budget a simulation does not fit in (the air-path plant over the whole
    1800 s WHTC needs about 40 MiB, here 8), it is a 500 saying so (out of memory, or the
    error of the C code that ran short, e.g. psycopg's); the child then leaves (a
    MemoryError may have struck inside an import or a cache) and the next request, a short
    simulation that fits, starts a clean one. The child is forked with the numerics loaded,
    so the budget is short for the simulation itself, not for importing them."""
    with _service(database_url, 8) as service:
        child = service.child
        assert child is not None
        request = SimulationRequest("maf-whtc", 0, None, None, "nominal")
        with pytest.raises(AppError) as raised:  # where the C code says MemoryError
            child.simulate(request, None)
        assert raised.value.status == 500
        assert "out of memory" in raised.value.message or "Error" in raised.value.message
        assert child.pid() is None  # it left, and was collected
        short = SimulationRequest("skf-sim2", 0, "after", 5.0, "nominal")
        dataset_id = child.simulate(short, None)
        assert service.get(dataset_id).name == "after"
        assert child.pid() is not None
