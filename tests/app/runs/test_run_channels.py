"""A run reads only the channels it uses (column projection of the dataset's Parquet file):
the same run on a log with thirty more channels gives bit for bit the versions, cells,
series and metrics it gives on the log of just the channels it uses."""

from __future__ import annotations

from typing import Any

import numpy as np
from fastapi.testclient import TestClient

from tests.support.helpers import log_csv, run_body, start_run, upload_ok, wait_run

EXTRA = 30


def _widened(text: str, seed: int) -> str:
    """``text`` with ``EXTRA`` noise columns interleaved before and after its own."""
    rng = np.random.default_rng(seed)
    lines = text.rstrip("\n").split("\n")
    n = len(lines) - 1
    extra = rng.normal(0.0, 1.0, (n, EXTRA))
    half = EXTRA // 2
    head = [f"a{i:02d} [V]" for i in range(half)]
    tail = [f"z{i:02d} [bar]" for i in range(EXTRA - half)]
    out = []
    for k, line in enumerate(lines):
        time, rest = line.split(",", 1)
        if k == 0:
            out.append(",".join([time, *head, rest, *tail]))
            continue
        row = [repr(float(v)) for v in extra[k - 1]]
        out.append(",".join([time, *row[:half], rest, *row[half:]]))
    return "\n".join(out) + "\n"


def _outcome(client: TestClient, run_id: int) -> dict[str, Any]:
    """Everything a run stored, but ids, names and times of day."""
    done = wait_run(client, run_id)
    assert done["status"] == "succeeded", done["error"]
    versions = []
    for item in client.get(f"/api/runs/{run_id}/versions").json()["items"]:
        version = client.get(f"/api/runs/{run_id}/versions/{item['id']}").json()
        versions.append(
            {k: v for k, v in version.items() if k not in ("id", "run_id", "created_at")}
        )
    metrics = {k: v for k, v in done["metrics"].items() if k != "run_s"}
    return {
        "versions": versions,
        "cells": client.get(f"/api/runs/{run_id}/cells").json(),
        "series": client.get(f"/api/runs/{run_id}/series", params={"points": 5000}).json(),
        "rejected": done["rejected"],
        "metrics": metrics,
    }


def test_a_run_on_a_wider_log_is_bit_identical(client: TestClient) -> None:
    text = log_csv(3000, seed=31)
    narrow = upload_ok(client, text)
    wide = upload_ok(client, _widened(text, seed=32))
    assert len(wide["channels"]) == len(narrow["channels"]) + EXTRA
    gates = [{"type": "range", "channel": "temp", "min": 40.0}]
    config = {"gates": gates, "version_every": {"samples": 400}}
    outcomes = []
    for dataset in (narrow, wide):
        run = start_run(client, run_body(dataset["id"], **config))
        outcomes.append(_outcome(client, run["id"]))
    assert len(outcomes[0]["versions"]) == 8  # 7 at the cadence, then the final one
    assert outcomes[0]["rejected"]["gate:range:temp"] > 0
    lines = {"u1", "u2", "measured", "prediction", "residual", "rejected"}
    assert set(outcomes[0]["series"]["series"]) == lines  # inputs and output were read
    assert outcomes[0] == outcomes[1]  # JSON floats round-trip: equal here is bit for bit
