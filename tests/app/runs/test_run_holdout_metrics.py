"""Every map-filter run stores its truth-free metrics: held-out prediction error and NIS
(app/runs/results.py, docs/tuning.md). That a torque run stores none is checked with the
torque run of tests/app/runs/test_runs.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.io.csv_files import read_csv
from estimation.holdout import holdout_error
from tests.support.helpers import TABLE, log_csv, run_body, start_run, upload_ok, wait_run


def test_map_filter_run_stores_holdout_and_nis_metrics(client: TestClient, tmp_path: Path) -> None:
    text = log_csv(3000, seed=5)
    dataset = upload_ok(client, text)
    gates = [{"type": "range", "channel": "temp", "min": 70.0}]
    done = wait_run(client, start_run(client, run_body(dataset["id"], gates=gates))["id"])
    assert done["status"] == "succeeded", done["error"]
    metrics = done["metrics"]

    path = tmp_path / "log.csv"
    path.write_text(text)
    signals = read_csv(path).signals
    axes = [a | {"unit": signals.units[a["name"]]} for a in TABLE["axes"]]
    config = run_body(0)["config"] | {"axes": axes, "output": "y", "output_unit": "ppm"}
    expected = holdout_error("skf", config, signals, accept=signals["temp"] >= 70.0).metrics()
    assert set(expected) <= set(metrics)
    for name, value in expected.items():
        assert metrics[name] == pytest.approx(value, rel=1e-12), name
    assert metrics["holdout:rmse"] < 0.2 < metrics["holdout:base_rmse"]
    assert metrics["holdout:samples"] == np.count_nonzero(signals["temp"][2100:] >= 70.0)
    assert metrics["nis:mean_band_low"] < 1.0 < metrics["nis:mean_band_high"]
    assert {"output_rmse", "coverage", "samples", "accepted", "run_s"} <= set(metrics)
