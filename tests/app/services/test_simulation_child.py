"""Simulations execute in the server's simulating child (app/services/simulation.py): one
child started at the first simulation and reused; a child killed mid-simulation is a 500 that
says how, stores nothing, and the next simulation starts a new child."""

from __future__ import annotations

import json
import os
import signal
import threading
import time

import pytest
from fastapi.testclient import TestClient

from app.errors import InvalidRequestError
from app.services.simulation import SimulationRequest, Simulator


def _simulator(client: TestClient) -> Simulator:
    simulator = client.app.state.services.datasets.simulator  # type: ignore[attr-defined]
    assert simulator is not None  # a file database and a local store: a child can reach them
    return simulator


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
