"""Run behaviour through the real app on SQLite and PostgreSQL: gates, locked cells,
failures, cancel and resume, pace, concurrency, simulated datasets, base maps."""

from __future__ import annotations

import time
from collections.abc import Iterator
from datetime import datetime

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.api import create_app
from tests.support.helpers import (
    TABLE,
    final_values,
    log_csv,
    reference_run,
    run_body,
    service_settings,
    start_run,
    upload_ok,
    wait_run,
)


def test_range_gate_counts_rejections_per_run_and_per_cell(client: TestClient, tmp_path) -> None:  # type: ignore[no-untyped-def]
    text = log_csv(3000, seed=5)
    dataset = upload_ok(client, text)
    gates = [{"type": "range", "channel": "temp", "min": 70.0}]
    run = start_run(client, run_body(dataset["id"], gates=gates))
    done = wait_run(client, run["id"])
    assert done["status"] == "succeeded", done["error"]
    ref = reference_run(text, tmp_path, "skf")
    temp = ref["signals"]["temp"]
    rejected = int(np.count_nonzero(temp < 70.0))
    assert rejected > 500
    assert done["rejected"]["gate:range:temp"] == rejected
    assert done["rejected"]["mask"] == rejected
    cells = client.get(f"/api/runs/{run['id']}/cells").json()
    per_cell = np.array(cells["rejected"]["range:temp"])
    assert per_cell.sum() == pytest.approx(rejected)
    assert np.array(cells["visits"]).sum() == pytest.approx(3000 - rejected)
    expected = reference_run(text, tmp_path, "skf", accept=temp >= 70.0)["values"]
    np.testing.assert_array_equal(np.array(final_values(client, run["id"])["values"]), expected)


def test_unknown_gate_channel_is_refused_with_its_field(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(200))
    gates = [{"type": "range", "channel": "oil", "min": 1}]
    response = client.post("/api/runs", json=run_body(dataset["id"], gates=gates))
    assert response.status_code == 422
    assert response.json()["error"]["field"] == "config.gates[0].channel"


def test_locked_cells_never_change(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(1500, seed=6))
    body = run_body(dataset["id"], locked=[0, 5])  # flat indices
    body["table"] = TABLE | {"values": 7.0}
    run = start_run(client, body)
    assert wait_run(client, run["id"])["status"] == "succeeded"
    values = np.array(final_values(client, run["id"])["values"])
    assert values.flat[0] == 7.0
    assert values.flat[5] == 7.0
    assert np.count_nonzero(values != 7.0) == 14
    doc = client.get(f"/api/runs/{run['id']}").json()
    assert doc["estimator_config"]["locked"] == [[0, 0], [1, 1]]


def test_a_failing_run_stores_its_message(client: TestClient) -> None:
    # Torque observers need a uniform time base; this log has an irregular step.
    rows = ["time,speed_rpm,load_torque_nm"] + [
        f"{t},{2000 + k},{10}" for k, t in enumerate([0, 0.001, 0.002, 0.0035, 0.0045, 0.0055])
    ]
    dataset = upload_ok(client, "\n".join(rows) + "\n")
    run = start_run(
        client,
        {
            "dataset_id": dataset["id"],
            "estimator": "uio",
            "signals": {"speed_channel": "speed_rpm", "load_channel": "load_torque_nm"},
            "config": {},
        },
    )
    done = wait_run(client, run["id"])
    assert done["status"] == "failed"
    assert "uniformly sampled" in done["error"]
    assert done["finished_at"] is not None


@pytest.mark.slow
def test_cancel_then_resume_gives_the_uninterrupted_map(client: TestClient) -> None:
    text = log_csv(3000, seed=7, rate_hz=100.0)
    dataset = upload_ok(client, text)
    reference = start_run(client, run_body(dataset["id"]))
    assert wait_run(client, reference["id"])["status"] == "succeeded"
    expected = final_values(client, reference["id"])

    # 30 s of log at 3x real time: ~10 s, cancelled after a few versions
    paced = start_run(client, run_body(dataset["id"], pace=3, version_every={"samples": 300}))
    wait_run(client, paced["id"], until=("running",))
    deadline = time.monotonic() + 30
    while client.get(f"/api/runs/{paced['id']}").json()["n_versions"] < 2:
        assert time.monotonic() < deadline
        time.sleep(0.05)
    cancelled = client.post(f"/api/runs/{paced['id']}/cancel")
    assert cancelled.status_code == 200
    done = wait_run(client, paced["id"])
    assert done["status"] == "cancelled"
    assert 0 < done["progress"] < 1
    assert client.post(f"/api/runs/{paced['id']}/cancel").status_code == 409

    resumed = client.post(f"/api/runs/{paced['id']}/resume")
    assert resumed.status_code == 200
    assert resumed.json()["status"] in ("queued", "running")
    # the rest at 3x real time too: under 10 s
    assert wait_run(client, paced["id"], timeout=60)["status"] == "succeeded"
    got = final_values(client, paced["id"])
    assert got["values"] == expected["values"]
    assert got["variance"] == expected["variance"]
    assert got["rejected"] == expected["rejected"]
    assert client.post(f"/api/runs/{paced['id']}/resume").status_code == 409
    series = client.get(f"/api/runs/{paced['id']}/series", params={"points": 3000}).json()
    ref_series = client.get(f"/api/runs/{reference['id']}/series", params={"points": 3000}).json()
    assert series["series"]["prediction"] == ref_series["series"]["prediction"]


def test_pace_replays_in_real_time_multiples(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(1000, seed=8, rate_hz=100.0))  # 10 s of log
    run = start_run(client, run_body(dataset["id"], pace=5))  # about 2 s
    started = wait_run(client, run["id"], until=("running", "succeeded"))
    done = wait_run(client, run["id"])
    assert done["status"] == "succeeded"
    assert started["status"] == "running"
    # Pacing is a lower bound only (a loaded machine is slower, never faster); how close a
    # run keeps to its pace is `mapwise bench`'s business, not a pass/fail wall clock.
    took = datetime.fromisoformat(done["finished_at"]) - datetime.fromisoformat(done["started_at"])
    assert took.total_seconds() > 1.5
    fast = start_run(client, run_body(dataset["id"]))
    wait_run(client, fast["id"])
    assert final_values(client, fast["id"])["values"] == final_values(client, run["id"])["values"]


def test_cancel_a_queued_run(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(2000, seed=9, rate_hz=100.0))
    # two slow runs occupy both workers, so the third waits in the queue
    slow = [start_run(client, run_body(dataset["id"], pace=4)) for _ in range(2)]
    queued = start_run(client, run_body(dataset["id"]))
    response = client.post(f"/api/runs/{queued['id']}/cancel")
    assert response.status_code == 200
    assert wait_run(client, queued["id"])["status"] == "cancelled"
    assert client.get(f"/api/runs/{queued['id']}/versions").json()["items"] == []
    for run in slow:
        client.post(f"/api/runs/{run['id']}/cancel")
        assert wait_run(client, run["id"])["status"] == "cancelled"


@pytest.fixture(scope="module")
def eight_workers(backend: str, fresh_url) -> Iterator[TestClient]:  # type: ignore[no-untyped-def]
    """An app with eight run workers on a fresh database of the backend."""
    settings = service_settings(fresh_url(backend), run_workers=8)
    with TestClient(create_app(settings)) as c:
        yield c


@pytest.mark.slow
def test_eight_runs_at_once_complete_correctly(eight_workers: TestClient, tmp_path) -> None:  # type: ignore[no-untyped-def]
    client = eight_workers
    texts = [log_csv(2500, seed=20 + i) for i in range(2)]
    datasets = [upload_ok(client, t)["id"] for t in texts]
    estimators = ["kf", "skf", "sskf", "rls"]
    jobs = [(d, e) for d in range(2) for e in estimators]
    # 50 s of log at 5× real time: each run takes 10 s, so all overlap even while the pool's
    # eight workers are still starting on a busy machine
    runs = [start_run(client, run_body(datasets[d], e, pace=5)) for d, e in jobs]
    assert len(runs) == 8
    finished = []
    for (d, estimator), run in zip(jobs, runs, strict=True):
        done = wait_run(client, run["id"], timeout=180)
        assert done["status"] == "succeeded", done["error"]
        finished.append(done)
        expected = reference_run(texts[d], tmp_path, estimator)["values"]
        got = np.array(final_values(client, run["id"])["values"])
        np.testing.assert_array_equal(got, expected)
    last_start = max(datetime.fromisoformat(r["started_at"]) for r in finished)
    first_end = min(datetime.fromisoformat(r["finished_at"]) for r in finished)
    assert last_start < first_end  # all eight were running at the same moment


def test_simulated_dataset_keeps_truth_for_metrics(client: TestClient) -> None:
    response = client.post("/api/datasets/simulate", json={"scenario": "skf-sim1", "seed": 1})
    assert response.status_code == 201, response.text
    dataset = response.json()
    assert dataset["source"] == "scenario:skf-sim1"
    assert dataset["has_truth"] is True
    assert dataset["rows"] == 1400
    body = {
        "dataset_id": dataset["id"],
        "estimator": "kf",
        "signals": {"y": "y"},
        "table": {
            "axes": [
                {"name": "u1", "breakpoints": [500, 1500, 2500, 3500]},
                {"name": "u2", "breakpoints": [0, 20, 40, 60]},
            ]
        },
        "config": {"sigma_w": 1, "sigma_v": 1, "p0": 0},
    }
    done = wait_run(client, start_run(client, body)["id"])
    assert done["status"] == "succeeded", done["error"]
    assert done["metrics"]["rmse"] < 0.05  # SKF §5.1: every filter converges to y = 1
    assert done["metrics"]["coverage"] == 1.0
    bad = client.post("/api/datasets/simulate", json={"scenario": "nope"})
    assert bad.status_code == 422
    assert bad.json()["error"]["field"] == "scenario"


def test_torque_run_on_a_simulated_dataset(client: TestClient) -> None:
    dataset = client.post(
        "/api/datasets/simulate", json={"scenario": "torque-si", "duration_s": 6.0}
    ).json()
    body = {
        "dataset_id": dataset["id"],
        "estimator": "uio",
        "signals": {},
        "config": {},
    }
    done = wait_run(client, start_run(client, body)["id"])
    assert done["status"] == "succeeded", done["error"]
    assert done["produces_map"] is False
    assert "ise" in done["metrics"]
    # no honest held-out check exists for an unmeasured input: the metrics say so (null)
    truth_free = {k: v for k, v in done["metrics"].items() if k.startswith(("holdout:", "nis:"))}
    assert truth_free == {
        "holdout:not_applicable:unmeasured_input": None,
        "nis:not_applicable:no_innovation_covariance": None,
    }
    series = client.get(f"/api/runs/{done['id']}/series", params={"points": 100}).json()
    assert {"torque_nm", "torque_nm_true", "torque_nm_error"} <= set(series["series"])
    assert series["series"]["torque_nm"]["unit"] == "N·m"
    csv = client.get(f"/api/runs/{done['id']}/export", params={"format": "csv"})
    assert csv.status_code == 200
    assert csv.text.splitlines()[0].startswith("time [s],speed_rpm [rpm]")
    assert client.get(f"/api/runs/{done['id']}/export", params={"format": "dcm"}).status_code == 409


def test_base_map_promotion_lineage_and_import(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(1500, seed=11))
    first = start_run(client, run_body(dataset["id"]))
    assert wait_run(client, first["id"])["status"] == "succeeded"
    version = client.get(f"/api/runs/{first['id']}/versions").json()["items"][-1]
    response = client.post(
        "/api/base-maps",
        json={"run_id": first["id"], "version_id": version["id"], "name": "production v1"},
    )
    assert response.status_code == 201, response.text
    base = response.json()
    assert base["lineage"]["run_id"] == first["id"]
    assert base["lineage"]["dataset_id"] == dataset["id"]
    assert base["lineage"]["estimator"] == "skf"
    assert base["lineage"]["parent_base_map_id"] is None
    assert base["values"] == final_values(client, first["id"])["values"]

    second = start_run(client, run_body(dataset["id"]) | {"base_map_id": base["id"]})
    second_doc = client.get(f"/api/runs/{second['id']}").json()
    assert second_doc["estimator_config"]["theta0"] == base["values"]
    assert wait_run(client, second["id"])["status"] == "succeeded"
    v2 = client.get(f"/api/runs/{second['id']}/versions").json()["items"][-1]
    child = client.post(
        "/api/base-maps", json={"run_id": second["id"], "version_id": v2["id"], "name": "v2"}
    ).json()
    assert child["lineage"]["parent_base_map_id"] == base["id"]

    csv_text = client.get(f"/api/runs/{first['id']}/export", params={"format": "csv"}).content
    imported = client.post(
        "/api/base-maps", files={"file": ("map.csv", csv_text)}, data={"name": "from csv"}
    )
    assert imported.status_code == 201, imported.text
    assert imported.json()["values"] == base["values"]
    assert imported.json()["lineage"]["run_id"] is None
    dcm = client.get(f"/api/runs/{first['id']}/export", params={"format": "dcm"}).content
    from_dcm = client.post("/api/base-maps", files={"file": ("m.dcm", dcm)}, data={"name": "dcm"})
    assert from_dcm.status_code == 201, from_dcm.text
    np.testing.assert_allclose(from_dcm.json()["values"], base["values"], rtol=1e-4)
    listing = client.get("/api/base-maps", params={"limit": 2}).json()
    assert listing["total"] >= 4
    assert len(listing["items"]) == 2
    mismatch = run_body(dataset["id"]) | {"base_map_id": base["id"]}
    mismatch["table"] = {"axes": [{"name": "u1", "breakpoints": [0, 1]}, TABLE["axes"][1]]}
    response = client.post("/api/runs", json=mismatch)
    assert response.status_code == 422
    assert response.json()["error"]["field"] == "base_map_id"


def test_dataset_preview_keeps_extremes(client: TestClient) -> None:
    text = "time,x\n" + "".join(f"{k},{1000 if k == 777 else 0}\n" for k in range(5000))
    dataset = upload_ok(client, text)
    preview = client.get(f"/api/datasets/{dataset['id']}/preview", params={"points": 100}).json()
    assert len(preview["time"]) == 100
    assert max(preview["channels"]["x"]["values"]) == 1000


def test_a_column_in_the_wrong_unit_is_refused_with_its_role(client: TestClient) -> None:
    t = np.arange(200) / 1000.0
    rows = ["time [s],n [rad/s],load [N·m],n_rpm [1/min]"]
    rows += [f"{x:.3f},230.0,100.0,2200.0" for x in t]
    dataset = upload_ok(client, "\n".join(rows) + "\n")
    body = {
        "dataset_id": dataset["id"],
        "estimator": "uio",
        "signals": {"speed_channel": "n", "load_channel": "load"},
    }
    response = client.post("/api/runs", json=body)
    assert response.status_code == 422
    error = response.json()["error"]
    assert error["field"] == "signals.speed_channel"
    assert "'rad/s'" in error["message"]
    assert "'rpm'" in error["message"]
    body["signals"]["speed_channel"] = "n_rpm"  # 1/min is rpm
    assert client.post("/api/runs", json=body).status_code == 201


def test_rate_and_holdoff_gates_through_the_api(client: TestClient, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The rate gate (|Δtemp/Δt| ≤ 5 degC/s) and a 2 s hold-off after temp < 25 degC,
    counted per gate (first gate wins) and per cell, against a direct computation."""
    text = log_csv(3000, seed=6)  # 50 Hz, temp = 60 + 40 sin(k/300)
    dataset = upload_ok(client, text)
    gates = [
        {"type": "rate", "channel": "temp", "max_abs": 5.0},
        {"type": "holdoff", "channel": "temp", "below": 25.0, "seconds": 2.0},
    ]
    done = wait_run(client, start_run(client, run_body(dataset["id"], gates=gates))["id"])
    assert done["status"] == "succeeded", done["error"]
    ref = reference_run(text, tmp_path, "skf")["signals"]
    t, temp = ref.time, ref["temp"]
    rate = np.abs(np.diff(temp) / np.diff(t))
    rate = np.concatenate([rate[:1], rate])
    fast = rate > 5.0
    events = np.flatnonzero(temp < 25.0)
    held = np.array([bool(np.any((events <= k) & (t[k] - t[events] <= 2.0))) for k in range(3000)])
    assert fast.sum() > 100
    assert (held & ~fast).sum() > 100
    assert done["rejected"]["gate:rate:temp"] == int(fast.sum())
    assert done["rejected"]["gate:holdoff:temp"] == int((held & ~fast).sum())
    cells = client.get(f"/api/runs/{done['id']}/cells").json()
    assert np.sum(cells["rejected"]["rate:temp"]) == pytest.approx(fast.sum())
    assert np.sum(cells["rejected"]["holdoff:temp"]) == pytest.approx((held & ~fast).sum())
    expected = reference_run(text, tmp_path, "skf", accept=~(fast | held))["values"]
    np.testing.assert_array_equal(np.array(final_values(client, done["id"])["values"]), expected)


def test_a_server_that_executes_no_runs_refuses_them_and_stores_nothing(database_url: str) -> None:
    settings = service_settings(database_url)
    with TestClient(create_app(settings, execute_runs=False)) as client:
        dataset = upload_ok(client, log_csv(300, seed=96))
        before = client.get("/api/runs", params={"limit": 1}).json()["total"]
        response = client.post("/api/runs", json=run_body(dataset["id"]))
        assert response.status_code == 409
        assert "does not execute runs" in response.json()["error"]["message"]
        sweep = run_body(dataset["id"]) | {"parameters": {"sigma_w": [0.01, 0.1]}}
        assert client.post("/api/sweeps", json=sweep).status_code == 409
        assert client.get("/api/runs", params={"limit": 1}).json()["total"] == before
