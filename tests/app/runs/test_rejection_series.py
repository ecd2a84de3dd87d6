"""A gated run's stored series carry the rejection mask (role ``rejected``: 1 where a gate
or the estimator rejected the sample, 0 where accepted), and it agrees with the run's
``rejected`` counts: sample for sample at full rate, and decimated (``?points=``) every
bucket holding a rejection keeps a 1. The final version's ``cell_rejections`` (now in
``GET /api/runs/{id}/versions/{id}``) spread the same rejections over the cells."""

from __future__ import annotations

import numpy as np
from fastapi.testclient import TestClient

from tests.support.helpers import log_csv, start_run, upload_ok, wait_run
from tests.support.server import run_body

N = 3000  # below the stored series' points: the stored mask is at full rate
GATES = [
    {"type": "range", "channel": "temp", "min": 30.0},
    {"type": "rate", "channel": "temp", "max_abs": 4.0},
]


def _gated_run(client: TestClient) -> dict:
    dataset = upload_ok(client, log_csv(N, seed=18))
    body = run_body(dataset["id"], "skf", gates=GATES, version_every={"samples": 1000})
    done = wait_run(client, start_run(client, body)["id"])
    assert done["status"] == "succeeded", done["error"]
    return done


def test_gated_run_stores_the_rejection_mask(client: TestClient) -> None:
    run = _gated_run(client)
    rejected = run["rejected"]
    gated = sum(v for k, v in rejected.items() if k.startswith("gate:"))
    # The estimator's reasons are disjoint; the gates split its "mask" count.
    total = sum(v for k, v in rejected.items() if not k.startswith("gate:"))
    assert 0 < gated <= total < N, rejected

    full = client.get(f"/api/runs/{run['id']}/series", params={"points": 100_000}).json()
    line = full["series"]["rejected"]
    assert line["role"] == "rejected"
    mask = np.array(line["values"], dtype=float)
    assert mask.size == N
    assert set(np.unique(mask)) == {0.0, 1.0}
    assert int(mask.sum()) == total

    points = 200
    thin = client.get(f"/api/runs/{run['id']}/series", params={"points": points}).json()
    kept = np.array(thin["series"]["rejected"]["values"], dtype=float)
    buckets = points // 2
    assert kept.size == 2 * buckets
    edges = np.linspace(0, N, buckets + 1).astype(int)
    for b in range(buckets):
        any_rejected = mask[edges[b] : edges[b + 1]].max()
        assert kept[2 * b : 2 * b + 2].max() == any_rejected, b
    # Every rejected bucket keeps at least one marker, at a time inside that bucket.
    time = np.array(thin["time"], dtype=float)
    full_time = np.array(full["time"], dtype=float)
    for b in np.flatnonzero(kept[0::2] + kept[1::2] > 0):
        t = time[2 * b : 2 * b + 2][kept[2 * b : 2 * b + 2] == 1.0]
        assert full_time[edges[b]] <= t.min()
        assert t.max() <= full_time[edges[b + 1] - 1]


def test_version_returns_cell_rejections(client: TestClient) -> None:
    run = _gated_run(client)
    versions = client.get(f"/api/runs/{run['id']}/versions").json()["items"]
    final = next(v for v in versions if v["final"])
    doc = client.get(f"/api/runs/{run['id']}/versions/{final['id']}").json()
    cells = doc["cell_rejections"]
    assert {f"gate:{k}" for k in cells} & set(run["rejected"]), (cells.keys(), run["rejected"])
    # Interpolation weights of a sample sum to 1 over the cells: per reason, the cells hold
    # that reason's whole count (samples inside the grid, as log_csv's all are).
    for label, grid in cells.items():
        key = label if label in run["rejected"] else f"gate:{label}"
        assert np.isclose(np.sum(grid), run["rejected"].get(key, 0), atol=1e-6), label
    # The same as the latest cells endpoint (the final version is the latest).
    same = client.get(f"/api/runs/{run['id']}/cells").json()["rejected"]
    assert same == cells
