"""Builders and waiting helpers for the service tests (in-process: a ``TestClient``); the
request builders themselves live in :mod:`tests.support.server`, shared with ``scripts/``."""

from __future__ import annotations

import io
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from fastapi.testclient import TestClient

from app.config import Settings
from app.io.csv_files import read_csv
from estimation.registry import get_spec
from estimation.table import Axis, Table
from tests.support.server import FINISHED, TABLE, U1, U2, run_body

TRUE_MAP = Table(
    [Axis("u1", "rpm", U1), Axis("u2", "mg/stroke", U2)],
    np.add.outer(np.array([1.0, 2.0, 3.5, 3.0]), np.array([0.0, 0.5, 1.5, 1.0])),
)


def spiky_log(n: int, spike_at: int, spike: float, rate_hz: float) -> str:
    """``u1 [rpm], u2 [mg/stroke], y [ppm]`` at ``rate_hz``: y is 1…5 ppm plus 0.01 ppm
    noise, except the one sample ``spike_at`` of ``spike`` ppm (the logs of the tests that
    a decimated series keeps its extremes)."""
    rng = np.random.default_rng(3)
    u = np.column_stack([rng.uniform(400, 3600, n), rng.uniform(-5, 65, n)])
    y = 1.0 + u[:, 0] / 1000.0 + rng.normal(0.0, 0.01, n)
    y[spike_at] = spike
    out = io.StringIO()
    np.savetxt(
        out,
        np.column_stack([np.arange(n) / rate_hz, u, y]),
        fmt=[f"%.{math.ceil(math.log10(rate_hz))}f", "%.1f", "%.2f", "%.4f"],
        delimiter=",",
        header="time [s],u1 [rpm],u2 [mg/stroke],y [ppm]",
        comments="",
    )
    return out.getvalue()


def log_csv(n: int = 3000, seed: int = 0, rate_hz: float = 50.0) -> str:
    """A 2-D map log: ``time [s], u1 [rpm], u2 [mg/stroke], y [ppm], temp [degC]``."""
    rng = np.random.default_rng(seed)
    u = np.column_stack([rng.uniform(400, 3600, n), rng.uniform(-5, 65, n)])
    y = TRUE_MAP.evaluate(u) + rng.normal(0.0, 0.05, n)
    temp = 60.0 + 40.0 * np.sin(np.arange(n) / 300.0)
    rows = ["time [s],u1 [rpm],u2 [mg/stroke],y [ppm],temp [degC]"]
    columns = np.column_stack([np.arange(n) / rate_hz, u, y, temp])
    rows += [",".join(repr(float(v)) for v in row) for row in columns]
    return "\n".join(rows) + "\n"


def upload(client: TestClient, text: str | bytes, name: str = "log.csv", **form: str) -> Any:
    content = text.encode() if isinstance(text, str) else text
    return client.post("/api/datasets", files={"file": (name, content)}, data=form)


def upload_ok(client: TestClient, text: str | bytes, name: str = "log.csv") -> dict[str, Any]:
    response = upload(client, text, name)
    assert response.status_code == 201, response.text
    return response.json()


def start_run(client: TestClient, body: dict[str, Any]) -> dict[str, Any]:
    response = client.post("/api/runs", json=body)
    assert response.status_code == 201, response.text
    return response.json()


def wait_run(
    client: TestClient, run_id: int, *, timeout: float = 120.0, until: tuple[str, ...] = FINISHED
) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while True:
        run = client.get(f"/api/runs/{run_id}").json()
        if run["status"] in until:
            return run
        if time.monotonic() > deadline:
            raise AssertionError(f"run {run_id} still {run['status']} after {timeout} s")
        time.sleep(0.05)


def wait_group(client: TestClient, path: str, timeout: float = 180.0) -> dict[str, Any]:
    """A sweep's or batch's document (``path``) once every run in it has finished."""
    deadline = time.monotonic() + timeout
    while True:
        doc = client.get(path).json()
        if all(r["status"] in ("succeeded", "failed", "cancelled") for r in doc["runs"]):
            return doc
        assert time.monotonic() < deadline, doc["counts"]
        time.sleep(0.1)


def final_values(client: TestClient, run_id: int) -> dict[str, Any]:
    response = client.get(f"/api/runs/{run_id}/export", params={"format": "json"})
    assert response.status_code == 200, response.text
    return response.json()


def reference_run(
    text: str, tmp_path: Path, estimator: str, accept: Any = None, **config: Any
) -> dict[str, Any]:
    """The same run done directly with the estimator, outside the service."""
    path = tmp_path / "ref.csv"
    path.write_text(text)
    signals = read_csv(path).signals
    body = run_body(0, estimator, **config)["config"]
    axes = [
        {"name": a["name"], "breakpoints": a["breakpoints"], "unit": signals.units[a["name"]]}
        for a in TABLE["axes"]
    ]
    full = body | {"axes": axes, "output": "y", "output_unit": "ppm"}
    final = get_spec(estimator).build(full).fit(signals, accept=accept)
    return {"values": final.table.values, "signals": signals}


def service_settings(database_url: str, **overrides: object) -> Settings:
    """Settings of a test app: 2 run workers, each started by the first run that needs it
    (most test apps run few runs or none, and a worker's warm-up costs about 1 CPU-second),
    no demo, fast cancel polling, and the TestClient's host (``testserver``) among the
    allowed hosts."""
    base: dict[str, object] = {
        "database_url": database_url,
        "allowed_hosts": ["testserver"],
        "run_workers": 2,
        "run_workers_prestart": False,
        "seed_demo": False,
        "cancel_poll_s": 0.05,
    }
    return Settings(**(base | overrides))
