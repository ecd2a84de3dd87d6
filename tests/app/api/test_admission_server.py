"""Adversarial requests against a real server: each is refused with a 4xx naming the limit,
nothing is stored, and the server's memory stays where it was.

None of the huge things asked for is ever allocated, here or in the server: the point is
that admission refuses them from their declared cost before anything runs.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from estimation.registry import get_spec, names
from tests.support.helpers import log_csv
from tests.support.server import Server, run_body

pytestmark = pytest.mark.slow

LOG_ROWS = 3000  # 60 s at 50 Hz
RUN_MAX_S = 3600  # so that pace 0.01 on the 60 s log (6000 s) is over budget


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    path = tmp_path_factory.mktemp("admission") / "mapwise.db"
    env = {"MAPWISE_RUN_MAX_S": str(RUN_MAX_S), "MAPWISE_RUN_MEMORY_MB": "1024"}
    srv = Server(f"sqlite:///{path}", env=env)
    try:
        yield srv
    finally:
        srv.stop()


@pytest.fixture(scope="module")
def dataset_id(server: Server) -> int:
    files = {"file": ("log.csv", log_csv(LOG_ROWS).encode())}
    response = server.post("/api/datasets", files=files)
    assert response.status_code == 201, response.text
    return int(response.json()["id"])


def _rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError("no VmRSS")


def _axes(n: int) -> dict[str, Any]:
    """A table of n×n cells over the log's u1, u2: a few KiB of JSON for n = 1000."""
    u1 = [400.0 + 3200.0 * i / (n - 1) for i in range(n)]
    u2 = [-5.0 + 70.0 * i / (n - 1) for i in range(n)]
    return {"axes": [{"name": "u1", "breakpoints": u1}, {"name": "u2", "breakpoints": u2}]}


def _huge_grid(dataset_id: int, name: str) -> tuple[str, dict[str, Any], str]:
    """The largest thing each estimator can be asked for: a 1000×1000 table, a 10 000-value
    map (ekf-map), or — for an estimator without a table — a table all the same."""
    spec = get_spec(name)
    if name == "ekf-map":
        breakpoints = [i * 1e-4 for i in range(10_000)]
        body = {"dataset_id": dataset_id, "estimator": name, "config": {"breakpoints": breakpoints}}
        return "/api/runs", body, "cells"
    body = run_body(dataset_id, name, table=_axes(1000))
    if name not in ("kf", "skf"):
        body["config"] = {}
    if spec.kind != "map_filter":
        body["signals"] = {}
    if name == "lpv" or spec.kind == "map_filter":
        return "/api/runs", body, "cells"
    return "/api/runs", body, "no table"


def _adversarial(dataset_id: int) -> list[tuple[str, dict[str, Any], str]]:
    """(path, JSON body, a word the refusal must contain) for every request."""
    requests = [_huge_grid(dataset_id, name) for name in names()]
    skf = run_body(dataset_id, "skf")
    kf = run_body(dataset_id, "kf")
    big_kf = run_body(dataset_id, "kf", table=_axes(45))  # 2025 cells > kf's 2000
    skf_versions = run_body(dataset_id, "skf", table=_axes(400), version_every={"samples": 30})
    requests += [
        ("/api/runs", big_kf, "kf's cap"),
        ("/api/runs", run_body(dataset_id, "kf", table=_axes(200)), "cells"),  # the 21.6 GB one
        ("/api/runs", skf_versions, "version budget"),
        ("/api/runs", skf | {"config": skf["config"] | {"pace": 1e-6}}, ">= 0.01"),
        ("/api/runs", skf | {"config": skf["config"] | {"pace": 0.01}}, "run budget"),
        ("/api/runs", skf | {"config": skf["config"] | {"sensor": {"delay_s": 1e9}}}, "delay"),
        (
            "/api/runs",
            skf | {"config": skf["config"] | {"sensor": {"delay_samples": 10**9}}},
            "delay",
        ),
        ("/api/runs", kf | {"config": kf["config"] | {"p0": 1e308}}, "too large"),
        ("/api/runs", kf | {"config": kf["config"] | {"sigma_w": 1e300}}, "too large"),
        (
            "/api/runs",
            skf | {"config": skf["config"] | {"locked": [[True, False], [False, True]]}},
            "shape",
        ),
        (
            "/api/sweeps",
            {
                "dataset_id": dataset_id,
                "estimator": "kf",
                "signals": {"y": "y"},
                "table": _axes(100),
                "config": {"sigma_v": 0.05},
                "parameters": {"sigma_w": [0.01, 0.1]},
            },
            "cells",
        ),
        (
            "/api/sweeps",
            {
                "dataset_id": dataset_id,
                "estimator": "skf",
                "signals": {"y": "y"},
                "table": _axes(4),
                "parameters": {"pace": [1.0, 1e-6]},
            },
            "pace",
        ),
        (
            "/api/batches",
            {
                "dataset_ids": [dataset_id, dataset_id],
                "estimator": "skf",
                "signals": {"y": "y"},
                "table": _axes(1000),
            },
            "cells",
        ),
    ]
    return requests


def _counts(server: Server) -> dict[str, int]:
    return {
        path: int(server.get(path, params={"limit": 1})["total"])
        for path in ("/api/runs", "/api/sweeps", "/api/batches", "/api/base-maps")
    }


def _huge_base_map() -> bytes:
    """A 1500×1500 map document (about 9 MiB of JSON)."""
    n = 1500
    axes = [
        {"name": "a", "unit": "", "breakpoints": list(range(n))},
        {"name": "b", "unit": "", "breakpoints": list(range(n))},
    ]
    row = "[" + ",".join(["0"] * n) + "]"
    values = "[" + ",".join([row] * n) + "]"
    return ('{"axes": ' + json.dumps(axes) + ', "values": ' + values + "}").encode()


def test_adversarial_requests_are_refused_and_store_nothing(
    server: Server, dataset_id: int
) -> None:
    requests = _adversarial(dataset_id)
    assert len(requests) >= 20
    before = _counts(server)
    rss_before = _rss_kib(server.process.pid)
    refusals: list[dict[str, Any]] = []
    for path, body, word in requests:
        response = server.post(path, json=body)
        assert 400 <= response.status_code < 500, (path, response.status_code, response.text)
        error = response.json()["error"]
        assert error["field"], error
        assert word in error["message"], (word, error)
        refusals.append(error)
    response = server.post(
        "/api/base-maps", files={"file": ("huge.json", _huge_base_map())}, data={"name": "huge"}
    )
    assert response.status_code == 422, response.text
    error = response.json()["error"]
    assert error["code"] == "over_budget"
    assert "2,250,000 cells" in error["message"]
    over = [e for e in refusals if e["code"] == "over_budget"]
    assert len(over) >= 10  # the huge grids, the caps, the versions, the paced duration
    assert _counts(server) == before
    growth_mib = (_rss_kib(server.process.pid) - rss_before) / 1024
    print(f"{len(requests) + 1} refusals; server RSS grew {growth_mib:.1f} MiB")
    assert growth_mib < 100, f"server RSS grew {growth_mib:.0f} MiB"
    assert server.process.poll() is None


def test_an_admitted_run_still_runs(server: Server, dataset_id: int) -> None:
    response = server.post("/api/runs", json=run_body(dataset_id, "skf"))
    assert response.status_code == 201, response.text
    run = server.wait_run(response.json()["id"], ("succeeded", "failed"))
    assert run["status"] == "succeeded", run


def test_refusals_name_the_budget_figures(server: Server, dataset_id: int) -> None:
    response = server.post("/api/runs", json=run_body(dataset_id, "kf", table=_axes(1000)))
    error = response.json()["error"]
    assert response.status_code == 422
    assert error == {
        "code": "over_budget",
        "message": "the table has 1,000,000 cells > 2,000, kf's cap",
        "field": "table.axes",
    }
    error = server.post("/api/runs", json=run_body(dataset_id, "skf", pace=0.01)).json()["error"]
    assert error == {
        "code": "over_budget",
        "message": "a 60 s log at pace 0.01 takes 100.0 min > 60.0 min run budget "
        "(MAPWISE_RUN_MAX_S); pace >= 0.0167 fits",
        "field": "config.pace",
    }
