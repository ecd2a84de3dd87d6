"""Admission control and the semantic config checks of run planning, and the wall-clock
budget a worker enforces."""

from __future__ import annotations

import json
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.api.app import create_app
from app.domain import Channel, Dataset
from app.errors import InvalidRequestError
from app.services.admission import (
    GATE_MASK_BYTES,
    GATES_SAMPLE_BYTES,
    STREAM_ROWS,
    STREAM_SAMPLE_BYTES,
    WORKER_BASE_BYTES,
    GroupBudget,
    Limits,
    OverBudgetError,
    Prediction,
    admit_run,
    human_bytes,
)
from app.services.run_plan import RunRequest, locked_cells, plan_run
from estimation.registry import get_spec, names
from tests.support.helpers import log_csv, service_settings, start_run, upload_ok, wait_run
from tests.support.server import TABLE, run_body

LIMITS = Limits(
    run_memory_bytes=2 * 2**30, max_cells=250_000, versions_bytes=512 * 2**20, run_max_s=6 * 3600
)


def _dataset(rows: int = 3000, rate_hz: float = 50.0) -> Dataset:
    channels = [Channel("u1", "rpm"), Channel("u2", "mg/stroke"), Channel("y", "ppm")]
    return Dataset(
        id=1, name="log", source="csv", rows=rows, rate_hz=rate_hz,
        duration_s=(rows - 1) / rate_hz, time_column="time", channels=channels,
        scenario=None, seed=None, has_truth=False, created_at=datetime.now(UTC),
    )  # fmt: skip


def _request(n1: int = 4, n2: int = 4, estimator: str = "skf", **config: Any) -> RunRequest:
    axes = [
        {"name": "u1", "breakpoints": [float(i) for i in range(n1)]},
        {"name": "u2", "breakpoints": [float(i) for i in range(n2)]},
    ]
    return RunRequest(
        dataset_id=1, estimator=estimator, signals={"y": "y"}, table={"axes": axes}, config=config
    )


def _plan(request: RunRequest, dataset: Dataset | None = None) -> Any:
    return plan_run(request, dataset or _dataset(), None, version_fraction=0.1, limits=LIMITS)


def _admit(name: str, cells: int, samples: int = 10_000, **kw: Any) -> Any:
    args = {
        "corners": 4,
        "channels": 4,
        "version_every": samples,
        "log_duration_s": 100.0,
        "pace": None,
    }
    return admit_run(get_spec(name), cells=cells, samples=samples, limits=LIMITS, **(args | kw))


def test_human_bytes() -> None:
    assert human_bytes(80) == "80 B"
    assert human_bytes(3 * 2**20) == "3.0 MiB"
    assert human_bytes(7.28 * 2**40) == "7.3 TiB"


def test_a_small_run_is_admitted_with_its_prediction() -> None:
    plan = _plan(_request())
    assert plan.prediction is not None
    assert WORKER_BASE_BYTES < plan.prediction.memory_bytes < WORKER_BASE_BYTES + 10 * 2**20
    assert plan.prediction.versions_bytes > 0


@pytest.mark.parametrize(("name", "refits"), [("skf", 1), ("lpv", 1), ("ekf-map", 1), ("uio", 0)])
def test_the_prediction_counts_the_held_out_refit(name: str, refits: int) -> None:
    """Every run refits its estimator for the held-out metrics while its own data are held
    (docs/reliability.md#admission): memory and work count it, except for the torque
    estimators, which have no truth-free check."""
    cost = get_spec(name).cost
    cells, corners = (16, 4) if name != "uio" else (0, 1)
    samples, channels = 100_000, 4
    got = _admit(name, cells, samples=samples, corners=corners, channels=channels)
    data = 8 * 2 * channels * samples
    once = cost.memory_bytes(cells, samples, corners=corners)
    assert got.memory_bytes == WORKER_BASE_BYTES + (1 + refits) * once + data
    work = cost.work(cells, samples, corners=corners)
    assert cost.run_work(cells, samples, corners=corners) == pytest.approx((1 + refits) * work)


@pytest.mark.parametrize("name", ["skf", "sskf", "rls", "nlms", "lpv"])
def test_the_global_cell_cap_names_the_table(name: str) -> None:
    with pytest.raises(OverBudgetError, match=r"250,001 cells > 250,000") as caught:
        _admit(name, 250_001)
    assert caught.value.field == "table.axes"
    assert caught.value.code == "over_budget"


def test_the_kf_has_its_own_cap_and_a_quadratic_memory() -> None:
    with pytest.raises(OverBudgetError, match="kf's cap") as caught:
        _plan(_request(60, 60, "kf"))
    assert caught.value.field == "table.axes"
    tight = Limits(
        run_memory_bytes=300 * 2**20, max_cells=10**6, versions_bytes=2**40, run_max_s=1e9
    )
    with pytest.raises(OverBudgetError, match=r"predicted .* MiB > 300\.0 MiB run budget"):
        admit_run(
            get_spec("kf"), cells=1600, corners=4, samples=1000, channels=3, version_every=1000,
            log_duration_s=20.0, pace=None, limits=tight,
        )  # fmt: skip


def test_a_huge_log_is_refused_by_memory_naming_the_dataset() -> None:
    with pytest.raises(OverBudgetError, match="run budget") as caught:
        _admit("nlms", 16, samples=200_000_000, channels=20)
    assert caught.value.field == "dataset_id"


def test_a_streamed_run_is_predicted_from_its_window_and_its_outputs() -> None:
    """A map filter on an uploaded log holds a window of it (STREAM_ROWS rows) and, for
    every sample, its outputs, status code and final RMSE copy (27 bytes): 10 M samples fit
    a budget the same run holding its log whole does not (docs/reliability.md)."""
    with pytest.raises(OverBudgetError, match="run budget"):
        _admit("skf", 216, samples=10_000_000)
    streamed = _admit("skf", 216, samples=10_000_000, streamed=True)
    spec = get_spec("skf")
    kept = (8 * len(spec.output_units) + STREAM_SAMPLE_BYTES) * 10_000_000
    window = spec.cost.run_memory_bytes(216, STREAM_ROWS, corners=4) + 16 * 4 * STREAM_ROWS
    assert streamed.memory_bytes == WORKER_BASE_BYTES + window + kept
    short = _admit("skf", 216, samples=1000, streamed=True).memory_bytes
    assert (
        short - _admit("skf", 216, samples=1000).memory_bytes == (16 + STREAM_SAMPLE_BYTES) * 1000
    )


@pytest.mark.parametrize(("name", "cells", "kept"), [("lpv", 216, 25), ("ekf-map", 11, 32)])
def test_a_streamed_observer_run_is_predicted_with_what_it_keeps_beyond_its_outputs(
    name: str, cells: int, kept: int
) -> None:
    """The LPV check keeps its fit's output error (25 bytes a sample with its statistics'
    temporaries); an EKF run was measured to keep 32 more than its outputs
    (docs/benchmarks.md#run-memory): each sample of a streamed run costs
    ``8 · outputs + 11 + stream_sample_bytes``."""
    spec = get_spec(name)
    assert spec.cost.stream_sample_bytes == kept
    small, large = 2 * STREAM_ROWS, 3 * STREAM_ROWS  # both hold the same window
    slope = (
        _admit(name, cells, samples=large, streamed=True, corners=2).memory_bytes
        - _admit(name, cells, samples=small, streamed=True, corners=2).memory_bytes
    ) / STREAM_ROWS
    assert slope == 8 * len(spec.output_units) + STREAM_SAMPLE_BYTES + kept


def test_a_streamed_run_on_a_recorded_dataset_is_predicted_with_its_raster() -> None:
    """A dataset stored as recorded streams too, put on its raster a window at a time
    (app.store.raster_rows): its run keeps the raster's time column as well, 8 bytes a
    sample (docs/benchmarks.md#run-memory). The plan passes that on."""
    plain = _admit("skf", 216, samples=10_000, streamed=True).memory_bytes
    raster = _admit("skf", 216, samples=10_000, streamed=True, raster=True).memory_bytes
    assert raster - plain == 8 * 10_000
    timing = (0.0, (3000 - 1) / 50.0, 1.0 / 50.0)  # each channel's span and median step
    recorded = replace(
        _dataset(), channels=[replace(c, timing=timing) for c in _dataset().channels]
    )
    assert recorded.recorded
    dense = _plan(_request()).prediction.memory_bytes
    assert _plan(_request(), recorded).prediction.memory_bytes - dense == 8 * 3000


def test_a_gated_run_is_predicted_with_its_masks() -> None:
    """Each sample gate keeps its mask and first-gate share for the whole log, and a gated
    run its accept mask and each sample's first rejecting gate: ``(2·g + 3)`` bytes a
    sample, streamed or not; a plan with gates passes its count (and is still streamed)."""
    for streamed in (False, True):
        plain = _admit("skf", 216, samples=10_000, streamed=streamed).memory_bytes
        gated = _admit("skf", 216, samples=10_000, streamed=streamed, gates=3).memory_bytes
        assert gated - plain == (GATE_MASK_BYTES * 3 + GATES_SAMPLE_BYTES) * 10_000
    gates = [
        {"type": "range", "channel": "u1", "min": 1.0},
        {"type": "rate", "channel": "y", "max_abs": 5.0},
    ]
    plain = _plan(_request()).prediction.memory_bytes
    gated = _plan(_request(gates=gates)).prediction.memory_bytes
    assert gated - plain == (GATE_MASK_BYTES * 2 + GATES_SAMPLE_BYTES) * 3000


def test_versions_over_budget_suggest_a_cadence() -> None:
    # 100 000 cells of skf: ~7 MiB per version; 100 versions do not fit in 512 MiB
    with pytest.raises(OverBudgetError, match=r"version every .* samples or more fits") as caught:
        _admit("skf", 100_000, samples=10_000, version_every=100)
    assert caught.value.field == "config.version_every"
    assert _admit("skf", 100_000, samples=10_000, version_every=1000).versions_bytes < 2**29


def test_pace_must_fit_the_wall_clock_budget() -> None:
    with pytest.raises(OverBudgetError, match=r"pace >= 0\.\d+ fits") as caught:
        _admit("skf", 16, log_duration_s=3600.0, pace=0.1)  # 10 h > 6 h
    assert caught.value.field == "config.pace"
    assert _admit("skf", 16, log_duration_s=3600.0, pace=0.5).duration_s == pytest.approx(7200)


@pytest.mark.parametrize("pace", [1e-6, 0.009, 0, -1])
def test_pace_has_a_floor(pace: float) -> None:
    with pytest.raises(InvalidRequestError, match=r">= 0\.01") as caught:
        _plan(_request(pace=pace))
    assert caught.value.field == "config.pace"


def test_every_estimator_is_capped() -> None:
    for name in names():
        with pytest.raises(OverBudgetError):
            _admit(name, 10**7)


@pytest.mark.parametrize(
    ("config", "field"),
    [
        ({"p0": 1e308}, "config.p0"),
        ({"sigma_w": 1e200}, "config.sigma_w"),
        ({"sensor": {"delay_s": 1e9}}, "config.sensor.delay_s"),
        ({"sensor": {"delay_samples": 3000}}, "config.sensor.delay_samples"),
    ],
)
def test_semantic_config_checks_name_the_field(config: dict[str, Any], field: str) -> None:
    with pytest.raises(InvalidRequestError) as caught:
        _plan(_request(**config))
    assert caught.value.field == field


def test_a_delay_shorter_than_the_log_is_fine() -> None:
    _plan(_request(sensor={"delay_s": 0.5}))


@pytest.mark.parametrize(
    "raw",
    [
        [[True, False], [False, True]],  # 2×2 mask on a 4×4 table (was read as index lists)
        [[True] * 4] * 3,
        [[True, False, False, False]] * 3 + [[True, False]],  # ragged
        [[0, 9]],  # index list outside the table
        [[1, 2, 3]],  # three indices on a 2-axis table
    ],
)
def test_wrong_lock_masks_are_refused(raw: Any) -> None:
    with pytest.raises(InvalidRequestError) as caught:
        locked_cells(raw, (4, 4))
    assert caught.value.field.startswith("config.locked")


def test_right_lock_masks_are_read() -> None:
    mask = [[False] * 4 for _ in range(4)]
    mask[1][2] = True
    assert locked_cells(mask, (4, 4)) == [[1, 2]]
    assert locked_cells([[1, 2]], (4, 4)) == [[1, 2]]
    assert locked_cells([6], (4, 4)) == [[1, 2]]


def test_a_run_over_its_wall_clock_budget_fails_with_a_clear_error(tmp_path: Path) -> None:
    """Admitted (its computation is predicted to take far less), then failed by the worker
    once the attempt's clock passes MAPWISE_RUN_MAX_S; what it learnt is kept as a version."""
    settings = service_settings(f"sqlite:///{tmp_path / 'db.sqlite'}", run_max_s=1e-3)
    with TestClient(create_app(settings)) as client:
        dataset = upload_ok(client, log_csv(3000))
        run = start_run(client, run_body(dataset["id"], "skf"))
        done = wait_run(client, run["id"])
    assert done["status"] == "failed"
    assert "wall-clock budget of 0.001 s (MAPWISE_RUN_MAX_S)" in done["error"]


def test_a_group_budget_sums_its_members_versions() -> None:
    limits = Limits(
        run_memory_bytes=2**31, max_cells=250_000, versions_bytes=512 * 2**20, run_max_s=1e4,
        group_versions_bytes=1000 * 2**20,
    )  # fmt: skip
    each = Prediction(memory_bytes=2**28, versions_bytes=300 * 2**20, duration_s=1.0)
    budget = GroupBudget(limits, what="sweep", field="parameters")
    for _ in range(3):
        budget.add(each)
    budget.check()  # 900 MiB ≤ 1000 MiB
    budget.add(each)
    budget.add(None)  # a member without a prediction (no map) adds nothing
    with pytest.raises(OverBudgetError) as caught:
        budget.check()
    assert caught.value.field == "parameters"
    assert caught.value.code == "over_budget"
    assert "5 runs would store 1.2 GiB" in caught.value.message
    assert "> 1000.0 MiB sweep budget (MAPWISE_SWEEP_VERSIONS_MB)" in caught.value.message
    assert "3 such runs fit" in caught.value.message


def test_sweeps_and_batches_over_the_total_version_budget_store_nothing(tmp_path: Path) -> None:
    # every member alone is far inside MAPWISE_RUN_VERSIONS_MB; six of them exceed 0.2 MiB
    url = f"sqlite:///{tmp_path / 'db.sqlite'}"
    with TestClient(create_app(service_settings(url, sweep_versions_mb=0.2))) as client:
        dataset = upload_ok(client, log_csv(3000))
        one = run_body(dataset["id"], "skf")
        sweep = {k: one[k] for k in ("dataset_id", "estimator", "signals", "table")} | {
            "parameters": {"sigma_w": [0.001, 0.01, 0.1], "sigma_v": [0.05, 0.5]},
        }
        response = client.post("/api/sweeps", json=sweep)
        assert response.status_code == 422, response.text
        error = response.json()["error"]
        assert error["code"] == "over_budget"
        assert error["field"] == "parameters"
        assert "6 runs would store" in error["message"]
        assert "204.8 KiB sweep budget (MAPWISE_SWEEP_VERSIONS_MB)" in error["message"]
        assert "2 such runs fit" in error["message"]

        batch = {k: one[k] for k in ("estimator", "signals", "table")} | {
            "dataset_ids": [dataset["id"]] * 6
        }
        response = client.post("/api/batches", json=batch)
        assert response.status_code == 422, response.text
        assert response.json()["error"]["field"] == "dataset_ids"
        assert "batch budget" in response.json()["error"]["message"]

        assert client.get("/api/sweeps").json()["items"] == []
        assert client.get("/api/batches").json()["items"] == []
        assert client.get("/api/runs").json()["items"] == []


def test_names_follow_the_one_rule(tmp_path: Path) -> None:
    """Run, group and base-map names are kept as given (``/`` too); a control or format
    character is a 422 naming the field, as for dataset names."""
    url = f"sqlite:///{tmp_path / 'db.sqlite'}"
    with TestClient(create_app(service_settings(url))) as client:
        dataset = upload_ok(client, log_csv(600))
        body = run_body(dataset["id"], "skf")
        for bad in ("evil\u202etxt.exe", "a\nb", "zero\u200bwidth"):
            response = client.post("/api/runs", json=body | {"name": bad})
            assert response.status_code == 422, response.text
            assert response.json()["error"]["field"] == "name"
            assert "U+" in response.json()["error"]["message"]
            sweep = {k: body[k] for k in ("dataset_id", "estimator", "signals", "table")}
            sweep |= {"parameters": {"sigma_v": [0.05]}, "name": bad}
            response = client.post("/api/sweeps", json=sweep)
            assert response.status_code == 422, response.text
            assert response.json()["error"]["field"] == "name"
            document = json.dumps({"axes": TABLE["axes"], "values": 1.0}).encode()
            response = client.post(
                "/api/base-maps", files={"file": ("m.json", document)}, data={"name": bad}
            )
            assert response.status_code == 422, response.text
            assert response.json()["error"]["field"] == "name"
        assert client.get("/api/runs").json()["items"] == []

        run = start_run(client, body | {"name": "  bench/2024 run  "})
        assert run["name"] == "bench/2024 run"
        wait_run(client, run["id"])
        values = [[1.0] * len(TABLE["axes"][1]["breakpoints"])] * len(
            TABLE["axes"][0]["breakpoints"]
        )
        document = json.dumps({"axes": TABLE["axes"], "values": values}).encode()
        response = client.post(
            "/api/base-maps",
            files={"file": ("dir/m.json", document)},
            data={"name": "maps/engine A"},
        )
        assert response.status_code == 201, response.text
        assert response.json()["name"] == "maps/engine A"
        response = client.post("/api/base-maps", files={"file": ("dir\\sub/m.json", document)})
        assert response.status_code == 201, response.text
        assert response.json()["name"] == "m.json"  # a client's directories say nothing
