"""Every run stores its truth-free metrics (app/runs/results.py, docs/tuning.md): held-out
prediction error and NIS for a map filter and an EKF, held-out error and output-error
statistics for the LPV observer. That a torque run says neither applies is checked with the
torque run of tests/app/runs/test_runs.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.io.csv_files import read_csv
from estimation.holdout import holdout_error
from estimation.registry import get_spec
from estimation.scenarios import get_scenario
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


def _scenario_csv(scenario: str, seed: int, duration_s: float) -> tuple[str, dict]:
    """A realisation of ``scenario`` as an uploaded log would carry it (every channel, with
    its unit; repr floats, so the upload reads back exactly), and its ``lpv``/EKF configs."""
    sc = get_scenario(scenario)
    data = sc.build(seed=seed, duration_s=duration_s)
    s = data.signals
    names = s.names
    header = ["time [s]"] + [f"{c} [{s.units[c]}]" if s.units.get(c) else c for c in names]
    rows = [",".join(header)]
    columns = np.column_stack([s.time] + [s[c] for c in names])
    rows += [",".join(repr(float(v)) for v in row) for row in columns]
    configs = {e: sc.default_config(e, data) for e in sc.suggested}
    return "\n".join(rows) + "\n", configs


@pytest.mark.parametrize(
    ("scenario", "estimator", "keys"),
    [
        ("maf-whtc", "lpv", {"holdout:base_rmse", "residual:mean_over_rms", "residual:rms"}),
        ("maf-1d-whtc", "ekf-map", {"holdout:base_rmse", "nis:mean", "nis:in_band"}),
    ],
)
def test_observer_runs_store_their_truth_free_metrics(
    client: TestClient, tmp_path: Path, scenario: str, estimator: str, keys: set[str]
) -> None:
    """An LPV and an EKF run store held-out prediction error of the MAF (kg/s) and, for the
    EKF, NIS; for LPV its output-error statistics and NIS marked not applicable — equal to
    :func:`estimation.registry.EstimatorSpec.holdout_check` on the same log and config."""
    text, configs = _scenario_csv(scenario, seed=100, duration_s=60.0)
    dataset = upload_ok(client, text)
    body = {"dataset_id": dataset["id"], "estimator": estimator, "signals": {}}
    done = wait_run(client, start_run(client, body | {"config": configs[estimator]})["id"])
    assert done["status"] == "succeeded", done["error"]
    metrics = client.get(f"/api/runs/{done['id']}").json()["metrics"]

    path = tmp_path / "log.csv"
    path.write_text(text)
    signals = read_csv(path).signals
    check = get_spec(estimator).holdout_check()
    expected = check(estimator, done["estimator_config"], signals).metrics()
    assert keys | {"holdout:rmse", "holdout:mae", "holdout:samples"} <= set(expected)
    assert set(expected) <= set(metrics)
    for name, value in expected.items():
        if value is None:
            assert metrics[name] is None, name
        else:
            assert metrics[name] == pytest.approx(value, rel=1e-9), name
    assert metrics["holdout:samples"] == len(signals) - round(0.7 * len(signals))
    if estimator == "lpv":
        assert metrics["nis:not_applicable:no_innovation_covariance"] is None
    else:
        assert metrics["nis:mean_band_low"] < 1.0 < metrics["nis:mean_band_high"]
