"""The robustness study of ``mapwise reproduce`` (app/reproduce/robustness.py): every headline
figure against mismatch and noise level, as a table on stdout, in report.json and as a plot."""

from __future__ import annotations

import json
import math
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
    assert doc["command"] == (
        "mapwise reproduce --seeds 0 --only skf,robustness --robustness-parts nox"
    )
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


def _cells(stdout: str, label: str) -> list[str]:
    """The cells after the label of the stdout table's row ``label``."""
    (line,) = [ln for ln in stdout.splitlines() if ln.startswith(f"| {label} |")]
    return [c.strip() for c in line.strip().strip("|").split("|")][1:]


@pytest.mark.slow  # a whole reproduce of the paper forms: 20 s, the fast lane's longest test
def test_the_literal_paper_forms_run_beside_the_modified_ones(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The LPV and EKF parts of the study, literal and modified, end to end through
    ``mapwise reproduce`` on one seed with every scenario cut to its first 60 s."""
    parts = "lpv,lpv-literal,ekf,ekf-literal"
    args = ["reproduce", "--only", "skf", "--robustness", "--robustness-parts", parts]
    args += ["--robustness-duration", "60", "--seeds", "0", "--out", str(tmp_path)]
    code = main(args)
    stdout, err = capsys.readouterr()
    assert code == 0, err
    doc = json.loads((tmp_path / "report.json").read_text())
    assert doc["command"] == (
        f"mapwise reproduce --seeds 0 --only skf,robustness --robustness-parts {parts} "
        "--robustness-duration 60"
    )
    data = doc["sections"][1]["data"]
    assert data["parts"] == parts.split(",")
    assert data["duration_s"] == 60.0
    records = {(r["level"], r["noise_scale"]): r["figures"] for r in data["records"]}
    assert len(records) == len(CELLS)
    modified = ["ekf/ekf-def", "ekf/ekf-aug", "ekf/ekf-map"]
    modified += [f"lpv/{s}/{p}" for s in ("maf-whtc", "maf-ftp75") for p in ("full", "segment")]
    literal = ["ekf/ekf-aug/diag", "ekf/ekf-map/diag"]
    literal += [f"{k}/literal" for k in modified if k.startswith("lpv/")]
    for cell, figures in records.items():
        # the modified forms in every cell; the literal LPV law at none and nominal only
        wanted = modified + [k for k in literal if k.startswith("ekf/") or cell[0] != "severe"]
        for key in wanted:
            assert key in figures, (cell, key)
            assert figures[key] is not None, (cell, key)
            assert math.isfinite(figures[key]), (cell, key)
            assert figures[key] > 0.0, (cell, key)
    # the figures are the shared fidelity code's at the cut duration
    token = fidelity.DURATION_S.set(60.0)
    try:
        expected = fidelity.ekf_literal("nominal", 0) | fidelity.lpv_literal("nominal", 0)
    finally:
        fidelity.DURATION_S.reset(token)
    nominal = records[("nominal", 1.0)]
    assert {k: nominal[k] for k in expected} == pytest.approx(expected, rel=1e-12)
    # both forms are rows of the printed table, with a number in every cell that ran
    for label in (
        "LPV MRE, WHTC 0–600 s (paper ETC part 1: 10.41 %)",
        "LPV MRE, WHTC 0–600 s, paper's law Γ = 200 I",
        "LPV MRE, FTP-75 0–505 s (paper: 5.28 %)",
        "LPV MRE, FTP-75 0–505 s, paper's law Γ = 200 I",
        "EKF W_c RMSE, Aug [g/s]",
        "EKF W_c RMSE, Aug, paper's diagonal cap [g/s]",
        "EKF W_c RMSE, Map [g/s]",
        "EKF W_c RMSE, Map, paper's diagonal cap [g/s]",
    ):
        cells = _cells(stdout, label)
        assert len(cells) == len(CELLS)
        for column, cell in zip(CELLS, cells, strict=True):
            if "paper's law" in label and column.level == "severe":
                assert cell == "—"
            else:
                assert math.isfinite(float(cell)), (label, cell)
    md = (tmp_path / "report.md").read_text()
    assert "cut to its first 60 s (`--robustness-duration`)" in md
