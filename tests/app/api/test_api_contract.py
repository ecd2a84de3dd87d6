"""The minimal REST contract, through the real app, on SQLite and PostgreSQL:
upload → run → poll → export, and the export equals ``mapwise adapt`` on the same CSV."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.cli import main as cli_main
from app.db.migrate import head_revision
from app.io.csv_files import read_csv, write_csv
from app.io.decimate import minmax_decimate
from app.runs.gates import apply_gates, parse_gates
from estimation.estimator import WINDOW_STEPS
from estimation.holdout import holdout_error
from estimation.holdout_ekf import ekf_holdout
from estimation.holdout_observers import lpv_holdout
from estimation.registry import get_spec
from estimation.scenarios import get_scenario
from estimation.signals import Signals
from tests.support.helpers import (
    TABLE,
    TRUE_MAP,
    U1,
    U2,
    final_values,
    log_csv,
    reference_run,
    run_body,
    start_run,
    upload,
    upload_ok,
    wait_run,
)

SPEED = [750, 780, 1000, 1250, 1500, 1750, 2000, 2500, 3000, 3500, 4000, 4500]
FUEL = [0, 5, 10, 15, 20, 25, 30, 34, 38, 42, 46, 50, 55, 60, 65, 70, 75, 80]


def test_health_names_backend_and_revision(client: TestClient, backend: str) -> None:
    body = client.get("/api/health").json()
    assert body["status"] == "ok"
    assert body["database"] == backend
    assert body["revision"] == head_revision()


def test_upload_returns_the_contract_fields(client: TestClient) -> None:
    response = upload(client, log_csv(500), name="drive.csv")
    assert response.status_code == 201, response.text
    doc = response.json()
    assert {"id", "name", "rows", "channels"} <= set(doc)
    assert doc["name"] == "drive.csv"
    assert doc["rows"] == 500
    assert doc["channels"] == [
        {"name": "u1", "unit": "rpm"},
        {"name": "u2", "unit": "mg/stroke"},
        {"name": "y", "unit": "ppm"},
        {"name": "temp", "unit": "degC"},
    ]
    assert doc["rate_hz"] == pytest.approx(50.0)
    assert client.get(f"/api/datasets/{doc['id']}").json() == doc


def test_upload_name_and_units_fields(client: TestClient) -> None:
    text = "time,a,b\n0,1,2\n1,2,3\n2,3,4\n"
    response = upload(client, text, name="../../etc/passwd", units=json.dumps({"a": "bar"}))
    assert response.status_code == 201, response.text
    doc = response.json()
    assert doc["name"] == "passwd"  # a client filename is a label, never a path
    assert doc["channels"] == [{"name": "a", "unit": "bar"}, {"name": "b", "unit": ""}]
    response = client.post(
        "/api/datasets", files={"file": ("x.csv", text.encode())}, data={"name": "My log"}
    )
    assert response.json()["name"] == "My log"


@pytest.mark.parametrize("name", ["run 3/4 \\ cold", "..\\..\\x", "été 🚗", "שם/2"])
def test_dataset_names_are_kept_as_given(client: TestClient, name: str) -> None:
    """A name is a label, never a path: ``/`` and ``\\`` stay (only the client's file name
    is cut to its last component), for uploads and simulations alike."""
    text = b"time,a\n0,1\n1,2\n"
    response = client.post(
        "/api/datasets", files={"file": ("x.csv", text)}, data={"name": f" {name} "}
    )
    assert response.status_code == 201, response.text
    assert response.json()["name"] == name
    response = client.post(
        "/api/datasets/simulate", json={"scenario": "skf-sim1", "name": name, "duration_s": 5}
    )
    assert response.status_code == 201, response.text
    assert client.get(f"/api/datasets/{response.json()['id']}").json()["name"] == name


def test_a_simulation_shorter_than_one_sample_interval_is_refused(client: TestClient) -> None:
    """The schema's per-scenario minimum (two samples) is what the service checks: skf-sim2
    logs at 1 Hz, so 0.6 s is a 422 naming ``duration_s``, nothing stored."""
    before = client.get("/api/datasets").json()["total"]
    response = client.post(
        "/api/datasets/simulate", json={"scenario": "skf-sim2", "duration_s": 0.6}
    )
    assert response.status_code == 422, response.text
    assert response.json()["error"]["field"] == "duration_s"
    assert client.get("/api/datasets").json()["total"] == before
    ok = client.post("/api/datasets/simulate", json={"scenario": "skf-sim2", "duration_s": 1.0})
    assert ok.status_code == 201, ok.text


@pytest.mark.parametrize(
    ("name", "code_point"),
    [("a\u202eb", "U+202E"), ("\u200bx", "U+200B"), ("x\ufeff", "U+FEFF"), ("a\x9bb", "U+009B")],
)
def test_control_characters_in_names_are_refused_alike(
    client: TestClient, name: str, code_point: str
) -> None:
    """The one rule for dataset names and channel names: 422 naming the field and the code
    point, nothing stored."""
    before = client.get("/api/datasets").json()["total"]
    text = b"time,a\n0,1\n1,2\n"
    for response, field in (
        (
            client.post("/api/datasets", files={"file": ("x.csv", text)}, data={"name": name}),
            "name",
        ),
        (
            client.post("/api/datasets/simulate", json={"scenario": "skf-sim1", "name": name}),
            "name",
        ),
        (
            client.post(
                "/api/datasets", files={"file": ("x.csv", f"time,{name}\n0,1\n1,2\n".encode())}
            ),
            "header",
        ),
    ):
        assert response.status_code == 422, response.text
        error = response.json()["error"]
        assert error["field"] == field
        assert code_point in error["message"]
    assert client.get("/api/datasets").json()["total"] == before


@pytest.mark.parametrize(
    ("method", "path", "allow"),
    [
        ("OPTIONS", "/api/datasets", "GET, POST"),
        ("OPTIONS", "/api/datasets/1", "GET, DELETE"),
        ("PUT", "/api/datasets/1", "GET, DELETE"),
        ("GET", "/api/datasets/simulate", "POST"),
        ("DELETE", "/api/datasets/simulate", "POST"),
        ("OPTIONS", "/api/runs", "GET, POST"),
        ("OPTIONS", "/api/runs/1/versions/2", "GET, PATCH"),
        ("PUT", "/api/runs/1/cancel", "POST"),
        ("OPTIONS", "/api/sweeps", "GET, POST"),
        ("OPTIONS", "/api/batches", "GET, POST"),
        ("OPTIONS", "/api/base-maps", "GET, POST"),
        ("POST", "/api/health", "GET"),
    ],
)
def test_405_lists_every_method_of_the_path(
    client: TestClient, method: str, path: str, allow: str
) -> None:
    """Starlette's 405 named only the first route that matched the path (GET or DELETE of
    ``/datasets/{id}``, never both); ``GET /datasets/simulate`` was parsed as an id (422)."""
    response = client.request(method, path)
    assert response.status_code == 405, response.text
    assert response.headers["allow"] == allow
    error = response.json()["error"]
    assert error["code"] == "method_not_allowed"
    assert f"allowed: {allow}" in error["message"]


@pytest.mark.parametrize("estimator", ["kf", "skf", "sskf", "rls", "nlms"])
def test_export_json_equals_mapwise_adapt(
    client: TestClient,
    estimator: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    text = log_csv(2000, seed=3)
    path = tmp_path / "log.csv"
    path.write_text(text)
    dataset = upload_ok(client, text)
    options = {"sigma_v": 0.05}
    if estimator in ("kf", "skf"):
        options |= {"sigma_w": 0.01, "p0": 10.0}
    run = start_run(
        client,
        {
            "dataset_id": dataset["id"],
            "estimator": estimator,
            "signals": {"y": "y"},
            "table": TABLE,
            "config": options,
        },
    )
    assert {"id", "status"} <= set(run)
    assert run["status"] == "queued"
    done = wait_run(client, run["id"])
    assert {"id", "status", "progress", "error"} <= set(done)
    assert (done["status"], done["progress"], done["error"]) == ("succeeded", 1.0, None)

    flags = [f"--{k.replace('_', '-')}={v}" for k, v in options.items()]
    axes = ["--axis", "u1=" + ",".join(map(str, U1)), "--axis", "u2=" + ",".join(map(str, U2))]
    assert (
        cli_main(
            ["adapt", str(path), "--estimator", estimator, *axes, "--y", "y", *flags, "--json"]
        )
        == 0
    )
    expected = json.loads(capsys.readouterr().out)
    got = final_values(client, run["id"])
    expected.pop("timing")
    got.pop("timing")
    assert got == expected
    if estimator in ("kf", "skf"):
        assert np.max(np.abs(np.array(got["values"]) - TRUE_MAP.values)) < 0.15


def test_nox_demo_config_with_sensor_delay_equals_mapwise_adapt(
    client: TestClient, example_csv: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    dataset = upload_ok(client, example_csv.read_bytes(), name="example_nox.csv")
    config = {
        "sigma_w": 15,
        "sigma_v": 25,
        "p0": 10000,
        "sensor": {"lag": 0.96, "delay_s": 0.75, "sigma_f": 50},
        "version_every": {"seconds": 30},
    }
    table = {
        "axes": [
            {"name": "speed_rpm", "breakpoints": SPEED},
            {"name": "fuel_mg_per_stroke", "breakpoints": FUEL},
        ]
    }
    body = {"dataset_id": dataset["id"], "estimator": "skf", "signals": {"y": "nox_ppm"}}
    run = start_run(client, body | {"table": table, "config": config})
    assert wait_run(client, run["id"])["status"] == "succeeded"
    args = [
        "adapt", str(example_csv), "--estimator", "skf",
        "--axis", "speed_rpm=" + ",".join(map(str, SPEED)),
        "--axis", "fuel_mg_per_stroke=" + ",".join(map(str, FUEL)),
        "--y", "nox_ppm", "--sigma-w", "15", "--sigma-v", "25", "--p0", "10000",
        "--lag", "0.96", "--delay-s", "0.75", "--sigma-f", "50", "--time", "time", "--json",
    ]  # fmt: skip
    assert cli_main(args) == 0
    expected = json.loads(capsys.readouterr().out)
    got = final_values(client, run["id"])
    assert {k: v for k, v in got.items() if k != "timing"} == {
        k: v for k, v in expected.items() if k != "timing"
    }
    assert got["rejected"]["delay"] == 38
    cells = client.get(f"/api/runs/{run['id']}/cells").json()
    assert np.sum(cells["rejected"]["delay"]) == pytest.approx(38)  # where the log starts
    versions = client.get(f"/api/runs/{run['id']}/versions").json()["items"]
    # every 30 s of a 150 s log at 50 Hz: 1500, 3000, 4500, 6000 samples, then the final one
    assert [v["final"] for v in versions] == [False] * (len(versions) - 1) + [True]
    assert len(versions) >= 5
    assert versions[-1]["step"] == 7500


def test_run_document_versions_series_cells(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(3000, seed=1))
    run = start_run(client, run_body(dataset["id"], version_every={"samples": 1000}))
    done = wait_run(client, run["id"])
    assert done["status"] == "succeeded"
    assert done["n_versions"] == 3
    assert done["metrics"]["samples"] == 3000
    assert 0.04 < done["metrics"]["output_rmse"] < 0.3  # noise 0.05 plus the transient from θ0 = 0
    assert done["rejected"] == {"mask": 0, "innovation": 0, "delay": 0}
    page = client.get(f"/api/runs/{run['id']}/versions").json()
    versions = page["items"]
    assert [v["step"] for v in versions] == [1000, 2000, 3000]
    assert page["total"] == 3
    second = client.get(f"/api/runs/{run['id']}/versions", params={"limit": 1, "offset": 1})
    assert [v["step"] for v in second.json()["items"]] == [2000]
    too_many = client.post(
        "/api/runs", json=run_body(dataset["id"], version_every={"samples": 2})
    )  # 1500 versions of a 3000-sample log
    assert too_many.status_code == 422
    assert too_many.json()["error"]["field"] == "config.version_every"
    assert ">= 3 samples" in too_many.json()["error"]["message"]
    first = client.get(f"/api/runs/{run['id']}/versions/{versions[0]['id']}").json()
    last = client.get(f"/api/runs/{run['id']}/versions/{versions[-1]['id']}").json()
    assert np.array(first["values"]).shape == (4, 4)
    assert first["values"] != last["values"]
    assert np.all(np.array(last["variances"]) > 0)
    assert np.sum(last["visits"]) == pytest.approx(3000)
    assert np.sum(first["visits"]) == pytest.approx(1000)
    patched = client.patch(
        f"/api/runs/{run['id']}/versions/{versions[0]['id']}", json={"label": "early"}
    )
    assert patched.status_code == 200
    assert patched.json()["label"] == "early"

    series = client.get(f"/api/runs/{run['id']}/series", params={"points": 500}).json()
    assert len(series["time"]) == 500
    assert set(series["series"]) == {"u1", "u2", "measured", "prediction", "residual"}
    assert series["series"]["measured"]["unit"] == "ppm"
    assert all(len(s["values"]) == 500 for s in series["series"].values())

    cells = client.get(f"/api/runs/{run['id']}/cells").json()
    assert cells["visits"] == last["visits"]
    assert cells["rejected"]["innovation"] == np.zeros((4, 4)).tolist()
    assert cells["rejected"]["delay"] == np.zeros((4, 4)).tolist()


def test_exports_csv_dcm_mcap(client: TestClient) -> None:
    from mcap.reader import make_reader

    dataset = upload_ok(client, log_csv(1500, seed=2))
    run = start_run(client, run_body(dataset["id"], version_every={"samples": 500}))
    assert wait_run(client, run["id"])["status"] == "succeeded"
    doc = final_values(client, run["id"])
    url = f"/api/runs/{run['id']}/export"

    csv_text = client.get(url, params={"format": "csv"}).text
    lines = csv_text.strip().splitlines()
    assert lines[0].startswith("u1 [rpm] \\ u2 [mg/stroke],")
    assert [float(x) for x in lines[1].split(",")][1:] == doc["values"][0]

    series_csv = client.get(url, params={"format": "csv", "part": "series"})
    assert series_csv.headers["content-type"].startswith("text/csv")
    header = series_csv.text.splitlines()[0]
    assert header.startswith("time [s],u1 [rpm],u2 [mg/stroke],y [ppm]")
    assert len(series_csv.text.splitlines()) == 1501

    dcm = client.get(url, params={"format": "dcm"})
    assert "KENNFELD Y 4 4" in dcm.text
    assert 'filename="' in dcm.headers["content-disposition"]

    mcap = client.get(url, params={"format": "mcap"})
    reader = make_reader(io.BytesIO(mcap.content))
    topics: dict[str, int] = {}
    last_map = None
    for _schema, channel, message in reader.iter_messages():
        topics[channel.topic] = topics.get(channel.topic, 0) + 1
        if channel.topic == "/map":
            last_map = json.loads(message.data)
    assert topics == {"/signals": 1500, "/map": 3}
    assert last_map is not None
    assert np.reshape(last_map["values"], last_map["shape"]).tolist() == doc["values"]


def test_compare_and_lists_paginate(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(800, seed=4))
    ids = [start_run(client, run_body(dataset["id"], e))["id"] for e in ("skf", "nlms", "rls")]
    for run_id in ids:
        assert wait_run(client, run_id)["status"] == "succeeded"
    compared = client.get("/api/compare", params={"runs": ",".join(map(str, ids))}).json()
    assert [r["id"] for r in compared["runs"]] == ids
    assert all(r["final_version"]["final"] for r in compared["runs"])
    assert compared["runs"][1]["final_version"]["variances"] is None  # nlms has none
    page = client.get("/api/runs", params={"dataset_id": dataset["id"], "limit": 2}).json()
    assert (page["total"], page["limit"], page["offset"], len(page["items"])) == (3, 2, 0, 2)
    rest = client.get(
        "/api/runs", params={"dataset_id": dataset["id"], "limit": 2, "offset": 2}
    ).json()
    assert [r["id"] for r in page["items"] + rest["items"]] == sorted(ids, reverse=True)
    datasets = client.get("/api/datasets", params={"limit": 1}).json()
    assert datasets["limit"] == 1
    assert len(datasets["items"]) == 1
    assert datasets["total"] >= 1


def test_error_bodies(client: TestClient) -> None:
    def error(response, status: int) -> dict:  # type: ignore[no-untyped-def]
        assert response.status_code == status, response.text
        body = response.json()
        assert set(body) == {"error"}
        assert set(body["error"]) == {"code", "message", "field"}
        return body["error"]

    assert error(client.get("/api/runs/987654"), 404)["code"] == "not_found"
    assert error(client.get("/api/no/such/route"), 404)["code"] == "not_found"
    assert error(client.put("/api/runs"), 405)["code"] == "method_not_allowed"
    bad_json = client.post("/api/runs", content=b"{", headers={"content-type": "application/json"})
    assert error(bad_json, 400)["code"] == "validation_error"
    dataset = upload_ok(client, log_csv(300))
    body = run_body(dataset["id"])
    assert error(client.post("/api/runs", json=body | {"estimator": "zzz"}), 422)["field"] == (
        "estimator"
    )
    e = error(client.post("/api/runs", json=body | {"signals": {"y": "nope"}}), 422)
    assert e["field"] == "signals.y"
    assert "nope" in e["message"]
    e = error(client.post("/api/runs", json=body | {"config": {"sigma_v": -1}}), 422)
    assert e["field"] == "config.sigma_v"
    bad_axes = {"axes": [{"name": "u1", "breakpoints": [3, 1]}, TABLE["axes"][1]]}
    e = error(client.post("/api/runs", json=body | {"table": bad_axes}), 422)
    assert e["field"] == "table.axes[0].breakpoints"
    e = error(client.post("/api/runs", json=body | {"config": {"pace": -2}}), 422)
    assert e["field"] == "config.pace"
    e = error(client.post("/api/runs", json=body | {"dataset_id": 999999}), 404)
    assert e["field"] == "dataset_id"
    e = error(client.post("/api/runs", json={"estimator": "skf"}), 422)
    assert e["field"] == "dataset_id"
    e = error(client.get("/api/runs/1/export", params={"format": "xls"}), 422)
    assert e["field"] == "format"


def test_delete_dataset_conflicts_then_forces(client: TestClient) -> None:
    dataset = upload_ok(client, log_csv(300))
    run = start_run(client, run_body(dataset["id"]))
    wait_run(client, run["id"])
    response = client.delete(f"/api/datasets/{dataset['id']}")
    assert response.status_code == 409
    assert response.json()["error"]["code"] == "conflict"
    assert (
        client.delete(f"/api/datasets/{dataset['id']}", params={"force": True}).status_code == 204
    )
    assert client.get(f"/api/datasets/{dataset['id']}").status_code == 404
    assert client.get(f"/api/runs/{run['id']}").status_code == 404


def test_catalogs(client: TestClient) -> None:
    estimators = {e["name"]: e for e in client.get("/api/estimators").json()["items"]}
    assert {"kf", "skf", "sskf", "rls", "nlms", "lpv", "uio"} <= set(estimators)
    skf = estimators["skf"]
    assert skf["kind"] == "table-filter"
    assert skf["needs_table"]
    assert [s["role"] for s in skf["signals"]] == ["y"]
    assert "sigma_w" in skf["config_schema"]["properties"]
    assert "axes" not in skf["config_schema"]["properties"]
    assert skf["defaults"]["sigma_v"] == 1.0
    assert estimators["uio"]["kind"] == "torque"
    assert not estimators["uio"]["needs_table"]
    scenarios = {s["name"]: s for s in client.get("/api/scenarios").json()["items"]}
    assert scenarios["skf-sim1"]["rate_hz"] == 1.0
    assert "skf" in scenarios["skf-sim1"]["estimators"]


def test_openapi_documents_every_route(client: TestClient) -> None:
    spec = client.get("/openapi.json").json()
    paths = spec["paths"]
    for path in (
        "/api/health",
        "/api/datasets",
        "/api/datasets/simulate",
        "/api/datasets/{dataset_id}/preview",
        "/api/runs",
        "/api/runs/{run_id}",
        "/api/runs/{run_id}/cancel",
        "/api/runs/{run_id}/resume",
        "/api/runs/{run_id}/versions/{version_id}",
        "/api/runs/{run_id}/versions/by-number/{number}",
        "/api/runs/{run_id}/series",
        "/api/runs/{run_id}/cells",
        "/api/runs/{run_id}/export",
        "/api/compare",
        "/api/base-maps",
    ):
        assert path in paths, path
    assert "422" in paths["/api/runs"]["post"]["responses"]


def test_csv_export_neutralises_spreadsheet_formulas(client: TestClient) -> None:
    rng = np.random.default_rng(0)
    rows = ["time,=HYPERLINK(1),y"] + [
        f"{k * 0.1},{rng.uniform(0, 10)!r},{rng.uniform(0, 1)!r}" for k in range(300)
    ]
    dataset = upload_ok(client, "\n".join(rows) + "\n")
    body = {
        "dataset_id": dataset["id"],
        "estimator": "nlms",
        "signals": {"y": "y"},
        "table": {"axes": [{"name": "=HYPERLINK(1)", "breakpoints": [0, 5, 10]}]},
        "config": {},
    }
    run = start_run(client, body)
    assert wait_run(client, run["id"])["status"] == "succeeded"
    text = client.get(f"/api/runs/{run['id']}/export", params={"format": "csv"}).text
    first_cells = [line.split(",")[0] for line in text.splitlines()]
    assert first_cells[0].startswith("'=HYPERLINK(1)")
    assert not any(cell.startswith(("=", "+", "@")) for cell in first_cells)
    series = client.get(
        f"/api/runs/{run['id']}/export", params={"format": "csv", "part": "series"}
    ).text
    assert "'=HYPERLINK(1)" in series.splitlines()[0]


@pytest.mark.slow
@pytest.mark.parametrize("sensor", [False, True])
def test_a_streamed_run_over_several_windows_equals_mapwise_adapt(
    client: TestClient, sensor: bool, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A log of 2.5 windows (docs/data-formats.md#streamed-runs): uploaded as a streamed CSV
    (over 16 MiB), run a window at a time from the store, its final map is the one
    `mapwise adapt` makes holding the log whole, bit for bit — across the windows' seams
    and with a sensor delay whose rows each window reads past its end."""
    text = log_csv(WINDOW_STEPS * 5 // 2, seed=4, rate_hz=100.0)
    assert len(text) > 16 * 2**20
    path = tmp_path / "log.csv"
    path.write_text(text)
    dataset = upload_ok(client, text)
    options: dict[str, Any] = {"sigma_v": 0.05, "sigma_w": 0.01, "p0": 10.0}
    flags = [f"--{k.replace('_', '-')}={v}" for k, v in options.items()]
    if sensor:
        options["sensor"] = {"lag": 0.5, "delay_samples": 3, "sigma_f": 0.01}
        flags += ["--lag=0.5", "--delay-samples=3", "--sigma-f=0.01"]
    body = {
        "dataset_id": dataset["id"],
        "estimator": "skf",
        "signals": {"y": "y"},
        "table": TABLE,
        "config": options,
    }
    done = wait_run(client, start_run(client, body)["id"])
    assert done["status"] == "succeeded", done["error"]
    axes = ["--axis", "u1=" + ",".join(map(str, U1)), "--axis", "u2=" + ",".join(map(str, U2))]
    argv = ["adapt", str(path), "--estimator", "skf", *axes, "--y", "y", *flags, "--json"]
    assert cli_main(argv) == 0
    expected = json.loads(capsys.readouterr().out)
    got = final_values(client, done["id"])
    expected.pop("timing")
    got.pop("timing")
    assert got == expected
    metrics = client.get(f"/api/runs/{done['id']}").json()["metrics"]
    assert metrics["samples"] == WINDOW_STEPS * 5 // 2
    assert metrics["holdout:samples"] > 0


@pytest.mark.slow
def test_a_gated_streamed_run_equals_the_whole_log_run_with_its_gates(
    client: TestClient, tmp_path: Path
) -> None:
    """Sample gates on a streamed run (docs/data-formats.md#streamed-runs): scanned a row
    group at a time, their accept mask rides along with each window. The final map is the
    whole-log fit with the whole-log gates' mask, bit for bit; the per-gate counts and the
    held-out check (fitted and scored on the accepted samples) are the whole log's."""
    n = WINDOW_STEPS * 5 // 4  # two filter windows, five row groups
    text = log_csv(n, seed=8, rate_hz=100.0)  # temp = 60 + 40 sin(k/300): up to 13 degC/s
    dataset = upload_ok(client, text)
    gates = [
        {"type": "range", "channel": "u2", "max": 60.0},
        {"type": "rate", "channel": "temp", "max_abs": 10.0},
        {"type": "holdoff", "channel": "temp", "below": 25.0, "seconds": 2.0},
    ]
    body = run_body(dataset["id"], gates=gates)
    done = wait_run(client, start_run(client, body)["id"], timeout=300)
    assert done["status"] == "succeeded", done["error"]
    path = tmp_path / "log.csv"
    path.write_text(text)
    signals = read_csv(path).signals
    expected = apply_gates(parse_gates(gates, signals.names), signals)
    assert all(count > n // 50 for count in expected.rejected.values()), expected.rejected
    assert {k: v for k, v in done["rejected"].items() if k.startswith("gate:")} == {
        f"gate:{k}": v for k, v in expected.rejected.items()
    }
    reference = reference_run(text, tmp_path, "skf", accept=expected.accept)
    np.testing.assert_array_equal(final_values(client, done["id"])["values"], reference["values"])
    axes = [a | {"unit": signals.units[a["name"]]} for a in TABLE["axes"]]
    config = run_body(0)["config"] | {"axes": axes, "output": "y", "output_unit": "ppm"}
    holdout = holdout_error("skf", config, signals, accept=expected.accept).metrics()
    metrics = client.get(f"/api/runs/{done['id']}").json()["metrics"]
    assert metrics["holdout:samples"] == holdout["holdout:samples"]
    assert metrics["holdout:rmse"] == pytest.approx(holdout["holdout:rmse"], rel=1e-9)


@pytest.mark.slow
def test_a_streamed_torque_run_stores_the_whole_log_runs_series(
    client: TestClient, tmp_path: Path
) -> None:
    """A torque estimator on an uploaded log of 2.5 windows (docs/data-formats.md#streamed-runs)
    runs a window at a time from the store; its stored series are the min/max decimation of
    the whole-log run's outputs, bit for bit, and its truth-free check is reported as not
    applicable, as on the whole-log path."""
    n = WINDOW_STEPS * 5 // 2
    text = log_csv(n, seed=5, rate_hz=100.0)
    dataset = upload_ok(client, text)
    channels = {"speed_channel": "u1", "load_channel": "y", "air_channel": "u2"}
    body = {"dataset_id": dataset["id"], "estimator": "adaptive-tv", "signals": {}}
    done = wait_run(client, start_run(client, body | {"config": channels})["id"], timeout=300)
    assert done["status"] == "succeeded", done["error"]
    path = tmp_path / "log.csv"
    path.write_text(text)
    signals = read_csv(path).signals
    whole = get_spec("adaptive-tv").build(channels).fit(signals).outputs
    assert all(np.isfinite(v).all() for v in whole.values())
    stored = minmax_decimate(signals.time, whole, 4000)  # the server's series_points
    time, expected = minmax_decimate(*stored, 4000)  # and as GET decimates it again
    got = client.get(f"/api/runs/{done['id']}/series", params={"points": 4000}).json()
    assert got["time"] == time.tolist()
    assert set(got["series"]) == set(whole)
    for name, values in expected.items():
        assert got["series"][name]["values"] == values.tolist(), name
    metrics = client.get(f"/api/runs/{done['id']}").json()["metrics"]
    assert metrics["samples"] == n
    assert "holdout:not_applicable:unmeasured_input" in metrics


SPEED_GATE = [{"type": "range", "channel": "speed_rpm", "max": 2000.0}]


def _gated_scenario_run(
    client: TestClient, tmp_path: Path, data: Any, name: str, config: dict[str, Any]
) -> tuple[dict[str, Any], Signals, np.ndarray]:
    """A run of ``name`` with :data:`SPEED_GATE` on a scenario's log uploaded as a CSV (so it
    streams, docs/data-formats.md#streamed-runs): the finished run, the log as the server
    parsed it, and the gate's accept mask."""
    assert get_spec(name).streams
    path = tmp_path / "log.csv"
    write_csv(data.signals, path)
    dataset = upload_ok(client, path.read_text())
    body = {"dataset_id": dataset["id"], "estimator": name, "signals": {}}
    run = start_run(client, body | {"config": config | {"gates": SPEED_GATE}})
    done = wait_run(client, run["id"], timeout=300)
    assert done["status"] == "succeeded", done["error"]
    signals = read_csv(path).signals
    accept = apply_gates(parse_gates(SPEED_GATE, signals.names), signals).accept
    assert 0 < np.count_nonzero(~accept) < len(signals) // 2
    return done, signals, accept


@pytest.mark.slow
def test_a_streamed_lpv_run_is_the_whole_log_fit_and_its_check(
    client: TestClient, tmp_path: Path
) -> None:
    """The LPV observer on an uploaded log streams (docs/data-formats.md#streamed-runs): its
    gain is designed on the ρ box of a first pass, each window reads the row before it, and
    its check refits and predicts a window at a time. With a gate, the final (smooth-filled)
    map is the whole-log fit's bit for bit, and the truth-free metrics are
    :func:`lpv_holdout`'s with the same mask."""
    scenario = get_scenario("maf-whtc")
    data = scenario.build(seed=6, duration_s=300.0, mismatch="nominal")
    config = {**scenario.default_config("lpv", data), "fill": "smooth"}
    done, signals, accept = _gated_scenario_run(client, tmp_path, data, "lpv", config)
    fit = get_spec("lpv").build(config).fit(signals, accept=accept)
    assert fit.table is not None
    got = final_values(client, done["id"])["values"]
    np.testing.assert_array_equal(np.asarray(got), fit.table.values)
    metrics = client.get(f"/api/runs/{done['id']}").json()["metrics"]
    check = lpv_holdout("lpv", config, signals, accept=accept).metrics()
    assert {k: metrics[k] for k in check} == check


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ekf-aug", "ekf-map"])
def test_a_streamed_ekf_run_is_the_whole_log_fit_and_its_check(
    client: TestClient, tmp_path: Path, name: str
) -> None:
    """An EKF on an uploaded log streams (docs/data-formats.md#streamed-runs): each window
    reads the row before it, and its check refits and predicts a window at a time. With a
    gate, the final map or bias, the stored series and the diagnostics are the whole-log
    fit's bit for bit, and the truth-free metrics :func:`ekf_holdout`'s up to rounding."""
    scenario = get_scenario("maf-1d-whtc")
    data = scenario.build(seed=4, duration_s=120.0, mismatch="nominal")
    config = scenario.default_config(name, data)
    done, signals, accept = _gated_scenario_run(client, tmp_path, data, name, config)
    fit = get_spec(name).build(config).fit(signals, accept=accept)
    document = client.get(f"/api/runs/{done['id']}").json()
    if fit.table is not None:
        got = final_values(client, done["id"])["values"]
        np.testing.assert_array_equal(np.asarray(got), fit.table.values)
    assert document["rejected"]["mask"] == fit.rejected["mask"]
    series = client.get(f"/api/runs/{done['id']}/series", params={"points": 4000}).json()
    stored = minmax_decimate(signals.time, fit.outputs, 4000)
    time, expected = minmax_decimate(*stored, 4000)
    assert series["time"] == time.tolist()
    for output, values in expected.items():
        assert series["series"][output]["values"] == values.tolist(), output
    check = ekf_holdout(name, config, signals, accept=accept).metrics()
    for key, value in check.items():
        assert document["metrics"][key] == pytest.approx(value, rel=1e-9, abs=1e-12), key
