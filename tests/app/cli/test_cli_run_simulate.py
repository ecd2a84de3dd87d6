"""``mapwise run`` and ``mapwise simulate`` through the real CLI entry point."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.io.csv_files import read_csv
from estimation.scenarios import get_scenario, scenarios

EXPECTED_SCENARIOS = {
    "skf-sim1", "skf-sim2", "skf-sim3", "nox-sdmp", "nox-nedc",
    "maf-whtc", "maf-ftp75", "maf-1d-whtc", "torque-si", "torque-rig",
}  # fmt: skip


def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_catalog_lists_every_scenario(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(["simulate", "--list", "--json"], capsys)
    assert code == 0
    catalog = {entry["name"]: entry for entry in json.loads(out)}
    assert set(catalog) >= EXPECTED_SCENARIOS
    for entry in catalog.values():
        assert entry["description"]
        assert entry["rate_hz"] > 0
        assert entry["suggested_estimators"]
        assert all(c["name"] for c in entry["channels"])


def test_run_json_contract_and_paper_ordering(capsys: pytest.CaptureFixture[str]) -> None:
    """skf-sim2 (SKF §5.2): KF and SKF converge on the excited cells, SSKF does not."""
    results = {}
    for estimator in ("kf", "skf", "sskf"):
        code, out, _ = run(
            ["run", "--scenario", "skf-sim2", "--estimator", estimator, "--json"], capsys
        )
        assert code == 0
        doc = json.loads(out)
        assert {"scenario", "estimator", "seed", "config", "metrics", "timing", "map"} <= set(doc)
        assert {"rmse", "max_abs_error", "mean_relative_error", "coverage"} <= set(doc["metrics"])
        assert doc["map"]["estimator"] == estimator
        assert doc["config"]["sigma_v"] == 1.0
        results[estimator] = doc["metrics"]
    assert results["kf"]["coverage"] == 0.5
    assert results["kf"]["max_abs_error"] < 0.05
    assert results["skf"]["max_abs_error"] < 0.05
    assert results["sskf"]["max_abs_error"] > 0.3


def test_set_reaches_nested_keys_and_is_validated(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(
        [
            "run", "--scenario", "nox-sdmp", "--estimator", "skf", "--duration", "60",
            "--set", "sigma_w=7", "--set", "sensor.lag=0.9", "--json",
        ],
        capsys,
    )  # fmt: skip
    assert code == 0
    config = json.loads(out)["config"]
    assert config["sigma_w"] == 7
    assert config["sensor"]["lag"] == 0.9
    assert config["sensor"]["sigma_f"] == 50.0  # untouched defaults stay
    for bad, message in [
        ("sigma_x=1", "sigma_x: Extra inputs are not permitted"),
        ("sigma_v=-2", "sigma_v: Input should be greater than 0"),
        ("sensor.lag=2", "sensor.lag: Input should be less than 1"),
        ("novalue", "expected key=value"),
    ]:
        code, out, err = run(
            ["run", "--scenario", "skf-sim1", "--estimator", "kf", "--set", bad], capsys
        )
        assert code == 2, bad
        assert out == ""
        assert message in err
        assert err.count("\n") == 1


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["run", "--scenario", "nope", "--estimator", "kf"], "unknown scenario 'nope'"),
        (["run", "--scenario", "skf-sim1", "--estimator", "nope"], "unknown estimator 'nope'"),
        (["run", "--scenario", "maf-whtc", "--estimator", "kf"], "does not apply"),
        (["run", "--scenario", "skf-sim2", "--estimator", "kf", "--duration", "500"], "duration"),
        (["simulate", "--scenario", "skf-sim1"], "--out FILE.csv (or --plot OUT.html)"),
        (["simulate", "--out", "x.csv"], "--scenario NAME is required"),
    ],
)
def test_bad_run_and_simulate_arguments(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(args, capsys)
    assert code == 2
    assert out == ""
    assert message in err
    assert err.count("\n") == 1


def test_simulate_writes_signals_and_truth_that_round_trip(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    csv_path, truth_path = tmp_path / "nox.csv", tmp_path / "truth.json"
    code, _, _ = run(
        [
            "simulate", "--scenario", "nox-nedc", "--seed", "4", "--duration", "30",
            "--out", str(csv_path), "--truth", str(truth_path),
        ],
        capsys,
    )  # fmt: skip
    assert code == 0
    data = get_scenario("nox-nedc").build(seed=4, duration_s=30)
    log = read_csv(csv_path)
    assert log.time_column == "time"
    assert log.signals.units["nox_ppm"] == "ppm"
    np.testing.assert_array_equal(log.signals.time, data.signals.time)
    for name in data.signals.names:
        np.testing.assert_array_equal(log.signals[name], data.signals[name])
    truth = json.loads(truth_path.read_text())
    assert truth["scenario"] == "nox-nedc"
    assert truth["seed"] == 4
    assert np.array(truth["true_map"]["values"]).shape == (12, 18)


@pytest.mark.parametrize("name", sorted(EXPECTED_SCENARIOS))
def test_every_scenario_is_seeded_finite_and_carries_its_true_map(name: str) -> None:
    scenario = scenarios()[name]
    duration = min(scenario.duration_s, 60.0)
    a = scenario.build(seed=1, duration_s=duration)
    b = scenario.build(seed=1, duration_s=duration)
    c = scenario.build(seed=2, duration_s=duration)
    assert {n for n, _ in scenario.channels} <= set(a.signals.names)
    for channel in a.signals.names:
        np.testing.assert_array_equal(a.signals[channel], b.signals[channel])
        assert np.all(np.isfinite(a.signals[channel]))
    differs = any(not np.array_equal(a.signals[n], c.signals[n]) for n in a.signals.names)
    assert differs == (name != "skf-sim2")  # SKF §5.2 is noise-free: nothing to seed
    assert a.truth
    json.dumps(a.truth)  # the truth is JSON-able for --truth
    if name.startswith("torque"):
        assert a.true_map is None
        return
    assert a.true_map is not None
    points = a.scoring_points()
    assert points.shape == (len(a.signals), a.true_map.ndim)


def test_simulate_plot_is_a_self_contained_page(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    page = tmp_path / "nox.html"
    code, out, _ = run(
        ["simulate", "--scenario", "nox-nedc", "--duration", "20", "--plot", str(page)], capsys
    )
    assert code == 0
    assert str(page) in out
    html = page.read_text()
    assert not re.search(r"<script[^>]*\bsrc=", html)  # Plotly.js inlined: works offline
    assert "Plotly.newPlot" in html
    assert "nox_ppm [ppm]" in html
    assert "true map with the operating points" in html
