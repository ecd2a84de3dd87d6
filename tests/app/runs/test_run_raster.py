"""A run on a dataset stored as recorded reads the channels it needs on the slowest raster
among them (docs/data-formats.md#multi-rate), through the real app: on a multi-rate MDF4
written by asammdf and uploaded without a raster, a map whose axes and output are all 10 ms
channels runs on the 10 ms raster, the same map with a 100 ms axis on the 100 ms raster; the
run is planned with that raster's rows, its metrics say which (``raster_s``), and its
exports come back on that raster."""

from __future__ import annotations

import csv
import io
import warnings
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.io.ingest import IngestLimits, ingest
from app.io.resample import Raster, resample
from estimation.estimator import WINDOW_STEPS
from estimation.holdout import holdout_error
from estimation.registry import get_spec
from estimation.signals import Signals
from tests.support.helpers import (
    final_values,
    log_csv,
    run_body,
    start_run,
    upload,
    upload_ok,
    wait_run,
)
from tests.support.measurements import NMOT, POLE, T10, T100, write_measurement
from tests.support.server import TABLE

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

MODE_AXIS = {"name": "mode", "breakpoints": [0.0, 1.0, 2.0]}


@pytest.fixture(scope="module")
def dataset(client: TestClient, tmp_path_factory: pytest.TempPathFactory) -> dict:  # type: ignore[type-arg]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        measurement = write_measurement(Path(tmp_path_factory.mktemp("raster")))
    response = upload(client, measurement.bytes(), name="canape.mf4")
    assert response.status_code == 201, response.text
    return response.json()


STATUS_AXIS = {"name": "status", "breakpoints": [0.0, 3.0, 6.0, 9.0, 12.0]}


def _body(dataset_id: int, second_axis: dict, **config: object) -> dict:  # type: ignore[type-arg]
    return {
        "dataset_id": dataset_id,
        "estimator": "skf",
        "signals": {"y": POLE},
        "table": {"axes": [MODE_AXIS, second_axis]},
        "config": {"sigma_w": 0.01, "sigma_v": 0.05, "p0": 10.0, **config},
    }


def _run(client: TestClient, dataset_id: int, second_axis: dict, **config: object) -> dict:  # type: ignore[type-arg]
    done = wait_run(client, start_run(client, _body(dataset_id, second_axis, **config))["id"])
    assert done["status"] == "succeeded", done["error"]
    return done


def _exported_rows(client: TestClient, run_id: int) -> list[dict[str, str]]:
    params = {"format": "csv", "part": "series"}
    response = client.get(f"/api/runs/{run_id}/export", params=params)
    assert response.status_code == 200, response.text
    rows = list(csv.DictReader(io.StringIO(response.text)))
    # the run's outputs (with the output's unit): on the raster of the channels read
    assert any(k == "prediction" or k.startswith("prediction [") for k in rows[0]), list(rows[0])
    return rows


def test_the_dataset_describes_its_whole_read(client: TestClient, dataset: dict) -> None:  # type: ignore[type-arg]
    assert (dataset["rows"], dataset["rate_hz"]) == (T100.size, pytest.approx(10.0))
    assert any("stored as recorded" in n for n in dataset["notes"])
    assert dataset["masked"] == {POLE: 10, "lambda": 3}
    preview = client.get(f"/api/datasets/{dataset['id']}/preview").json()
    assert len(preview["time"]) == T100.size
    assert preview["time"][0] == pytest.approx(T100[0])


def test_a_run_on_ten_ms_channels_runs_on_the_ten_ms_raster(
    client: TestClient,
    dataset: dict,  # type: ignore[type-arg]
) -> None:
    done = _run(client, dataset["id"], STATUS_AXIS)
    assert done["metrics"]["raster_s"] == pytest.approx(0.01)
    assert done["metrics"]["samples"] == done["n_samples"] == T10.size  # planned: 10 ms
    series = _exported_rows(client, done["id"])
    assert float(series[1]["time [s]"]) - float(series[0]["time [s]"]) == pytest.approx(0.01)


def test_a_run_needing_a_hundred_ms_channel_runs_on_the_hundred_ms_raster(
    client: TestClient,
    dataset: dict,  # type: ignore[type-arg]
) -> None:
    speed_axis = {"name": NMOT, "breakpoints": [800.0, 1300.0, 1900.0]}
    done = _run(client, dataset["id"], speed_axis)
    assert done["metrics"]["raster_s"] == pytest.approx(0.1)
    assert done["metrics"]["samples"] == done["n_samples"] == T100.size
    series = _exported_rows(client, done["id"])
    assert float(series[1]["time [s]"]) - float(series[0]["time [s]"]) == pytest.approx(0.1)
    assert {float(row["mode"]) for row in series} <= {0.0, 1.0, 2.0}  # held: recorded only


def test_a_run_may_choose_its_raster(client: TestClient, dataset: dict) -> None:  # type: ignore[type-arg]
    on_speed = _run(client, dataset["id"], STATUS_AXIS, raster=f"channel:{NMOT}")
    assert on_speed["metrics"]["raster_s"] == pytest.approx(0.1)
    assert on_speed["metrics"]["samples"] == on_speed["n_samples"] == T100.size
    assert on_speed["config"]["raster"] == f"channel:{NMOT}"  # the run's record says which
    on_rate = _run(client, dataset["id"], STATUS_AXIS, raster="50ms")
    assert on_rate["metrics"]["raster_s"] == pytest.approx(0.05)
    # the span of the 10 ms channels, 0.005 … 1.995 s, every 50 ms
    assert on_rate["metrics"]["samples"] == on_rate["n_samples"] == 40


def test_a_bad_run_raster_is_refused_naming_its_field(
    client: TestClient,
    dataset: dict,  # type: ignore[type-arg]
) -> None:
    for raster, message in (
        ("fast please", "not understood"),
        ("channel:nope", "raster channel 'nope' is not in dataset"),
        (5, "must be a string"),
        ("100s", "the raster gives 1 sample over the log"),  # the log spans 2 s
        ("1e-9s", "run budget"),  # billions of samples: over budget because of the raster
    ):
        response = client.post("/api/runs", json=_body(dataset["id"], STATUS_AXIS, raster=raster))
        assert response.status_code == 422, response.text
        error = response.json()["error"]
        assert error["field"] == "config.raster"
        assert message in error["message"]
    dense = upload_ok(client, log_csv(200))
    response = client.post("/api/runs", json=run_body(dense["id"], raster="10ms"))
    assert response.status_code == 422, response.text
    assert response.json()["error"]["field"] == "config.raster"
    assert "stored as recorded" in response.json()["error"]["message"]


def _long_measurement(path: Path, rows: int) -> bytes:
    """A multi-rate MDF4 written by asammdf: ``u1`` at about 1 kHz on jittered timestamps,
    with masked (NaN) samples, and ``u2`` and ``y`` at 2 ms for ``rows`` samples, ``y`` a
    smooth map of both plus noise."""
    from asammdf import MDF, Signal

    rng = np.random.default_rng(11)
    t2 = 0.001 + 0.002 * np.arange(rows)
    t1 = np.cumsum(rng.uniform(0.0009, 0.0011, 2 * rows + 20))
    u1 = 2000.0 + 1400.0 * np.sin(t1 / 9.0)
    u2 = 30.0 + 28.0 * np.sin(t2 / 23.0)
    y = 1e-3 * np.interp(t2, t1, u1) + 0.05 * u2 + rng.normal(0.0, 0.05, rows)
    u1[rng.choice(u1.size, 200, replace=False)] = np.nan
    mdf = MDF(version="4.10")
    mdf.append([Signal(u1, t1, name="u1", unit="rpm")])
    mdf.append([Signal(u2, t2, name="u2", unit="%"), Signal(y, t2, name="y", unit="ppm")])
    saved = Path(mdf.save(path, overwrite=True))
    mdf.close()
    return saved.read_bytes()


@pytest.mark.slow
def test_a_streamed_run_over_several_windows_equals_the_whole_read_fit(
    client: TestClient, tmp_path: Path
) -> None:
    """A run on a dataset stored as recorded streams (docs/data-formats.md#streamed-runs): it
    puts its channels on their raster a window at a time. On a multi-rate MDF4 of 2.5
    windows on that raster, the final map is the fit on the whole read (the channels
    resampled at once), bit for bit, across the windows' seams; its raster, sample count
    and held-out check are the whole read's."""
    rows = WINDOW_STEPS * 5 // 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        data = _long_measurement(tmp_path / "long.mf4", rows)
    response = upload(client, data, name="long.mf4")
    assert response.status_code == 201, response.text
    dataset = response.json()
    assert any("stored as recorded" in n for n in dataset["notes"])
    done = wait_run(client, start_run(client, run_body(dataset["id"]))["id"], timeout=300)
    assert done["status"] == "succeeded", done["error"]

    parsed = ingest(data)
    limits = IngestLimits()
    table = resample(
        parsed.recorded, Raster(), max_rows=limits.max_rows, max_values=limits.max_values
    )
    assert table.raster == Raster(channel="u2")  # the slowest: 2 ms, the first on a tie
    signals = Signals(table.time, table.channels, table.units)
    assert rows - 2 <= len(signals) <= rows  # 2.5 windows
    axes = [a | {"unit": signals.units[a["name"]]} for a in TABLE["axes"]]
    config = run_body(0)["config"] | {"axes": axes, "output": "y", "output_unit": "ppm"}
    fit = get_spec("skf").build(config).fit(signals)
    assert fit.table is not None
    got = final_values(client, done["id"])["values"]
    np.testing.assert_array_equal(np.asarray(got), fit.table.values)
    metrics = client.get(f"/api/runs/{done['id']}").json()["metrics"]
    assert metrics["samples"] == done["n_samples"] == len(signals)
    assert metrics["raster_s"] == float(np.median(np.diff(signals.time)))
    holdout = holdout_error("skf", config, signals).metrics()
    assert metrics["holdout:samples"] == holdout["holdout:samples"]
    assert metrics["holdout:rmse"] == pytest.approx(holdout["holdout:rmse"], rel=1e-9)
