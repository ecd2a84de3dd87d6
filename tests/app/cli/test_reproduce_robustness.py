"""The robustness study of ``mapwise reproduce`` (app/reproduce/robustness.py): every headline
figure against mismatch and noise level, as a table on stdout, in report.json and as a plot."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.cli import main
from app.reproduce import fidelity
from app.reproduce.robustness import CELLS, parse_parts
from app.reproduce.runner import DEFAULT_KEYS, SECTION_KEYS
from estimation.errors import ConfigError


def test_study_table_json_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out, plots = tmp_path / "r", tmp_path / "plots"
    args = ["reproduce", "--only", "skf", "--robustness", "--robustness-parts", "nox"]
    code = main([*args, "--seeds", "0", "--out", str(out), "--plots", str(plots)])
    stdout, err = capsys.readouterr()
    assert code == 0, err
    # the table on stdout: one column per cell, the NOx headline rows
    header = "| figure | none | nominal | severe | nominal, noise × 0.5 | nominal, noise × 2 |"
    assert header in stdout
    assert "| NOx held-out RMSE, KF [ppm] |" in stdout
    doc = json.loads((out / "report.json").read_text())
    assert doc["command"] == "mapwise reproduce --seeds 0 --only skf,robustness"
    assert [s["key"] for s in doc["sections"]] == ["skf", "robustness"]
    assert doc["sections"][0]["data"] == {}
    data = doc["sections"][1]["data"]
    assert data["parts"] == ["nox"]
    assert [(c["level"], c["noise_scale"]) for c in data["cells"]] == [
        (c.level, c.noise_scale) for c in CELLS
    ]
    records = {(r["level"], r["noise_scale"]): r["figures"] for r in data["records"]}
    assert len(records) == len(CELLS)
    # the figures are the shared fidelity code's, computed live
    assert records[("nominal", 2.0)] == pytest.approx(fidelity.nox("nominal", 0, 2.0), rel=1e-12)
    # the filters' σv is not told of the noise: more noise, worse held-out prediction
    assert records[("nominal", 2.0)]["nox/kf"] > records[("nominal", 0.5)]["nox/kf"]
    page = (plots / "robustness.html").read_text()
    assert page.startswith("<!DOCTYPE html>")
    assert "Plotly.newPlot" in page
    assert "## Robustness study" in (out / "report.md").read_text()


def test_the_study_is_opt_in_and_parts_are_checked() -> None:
    assert "robustness" in SECTION_KEYS
    assert "robustness" not in DEFAULT_KEYS
    assert parse_parts(None) == ("lpv", "lpv-literal", "ekf", "ekf-literal", "nox", "torque")
    assert parse_parts("torque,nox") == ("nox", "torque")
    with pytest.raises(ConfigError, match="robustness-parts"):
        parse_parts("nox,bogus")
