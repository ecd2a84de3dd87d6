"""``mapwise reproduce`` through the real CLI entry point: files, sections, and numbers that
are ``mapwise run``'s own (computed live, never stored)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from app.cli import main
from app.cli.run import execute_scenario, run_scenario
from app.reproduce import paper_values as pv
from app.reproduce import runner
from app.reproduce.ekf import build as build_ekf
from app.reproduce.lpv import build as build_lpv
from app.reproduce.report import num, pct
from app.reproduce.skf_sims import TOLERANCE
from app.reproduce.torque import build as build_torque
from estimation.registry import registry


def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


def table_rows(markdown: str, *first_cells: str) -> list[list[str]]:
    """Markdown table rows whose leading cells are ``first_cells``."""
    rows = []
    for line in markdown.splitlines():
        if not line.startswith("| "):
            continue
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]
        if cells[: len(first_cells)] == list(first_cells):
            rows.append(cells)
    return rows


def test_skf_section_default_dir_and_numbers_of_mapwise_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    code, out, err = run(["reproduce", "--only", "skf", "--seeds", "0"], capsys)
    assert code == 0, err
    md_path = tmp_path / "reproduce" / "report.md"
    html_path = tmp_path / "reproduce" / "report.html"
    assert f"wrote {Path('reproduce') / 'report.md'}" in out
    md = md_path.read_text()
    assert "## SKF paper §5 — synthetic checks" in md
    assert "## SKF paper §6" not in md  # --only skf
    assert "mapwise reproduce --seeds 0 --only skf" in md
    for number in (1, 2, 3):
        for estimator, label in (("kf", "KF"), ("skf", "SKF"), ("sskf", "SSKF")):
            metrics = run_scenario(f"skf-sim{number}", estimator, seed=0)["metrics"]
            (row,) = table_rows(md, f"{number} ({pv.SKF_SIM_REFS[number]})", label, "0")
            expected = pv.SKF_SIM_CONVERGES[number][estimator]
            converged = metrics["max_abs_error"] <= TOLERANCE
            assert row[3] == ("converges" if expected else "does not converge")
            assert row[4] == ("converged" if converged else "not converged")
            assert row[5] == num(metrics["rmse"])
            assert row[6] == num(metrics["max_abs_error"])
            assert row[8] == str(int(metrics["visited_cells"]))
    assert "**Verdict:** All 9 (simulation, filter, seed) outcomes match the paper" in md

    html = html_path.read_text()
    assert html.startswith("<!DOCTYPE html>")
    assert not re.search(r"<script[^>]+src=", html)  # Plotly.js inlined, nothing fetched
    assert "Plotly.newPlot" in html
    assert len(html) > 3_000_000
    assert html.count('class="plotly-graph-div"') == 5
    assert 'id="skf"' in html
    assert "<table>" in html


@pytest.mark.slow
def test_torque_tables_beside_the_papers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _out, err = run(
        ["reproduce", "--out", str(tmp_path / "r"), "--only", "torque", "--seeds", "1"], capsys
    )
    assert code == 0, err
    md = (tmp_path / "r" / "report.md").read_text()
    assert "torque-si: TQ Table III beside ours." in md
    assert "torque-rig: TQ Table VII beside ours." in md
    uio = run_scenario("torque-si", "uio", seed=1)["metrics"]
    (row,) = table_rows(md, "ISE", "UIO (14)", num(pv.TQ_TABLE_III["uio"]["ise"], 5))
    assert row[3] == num(uio["ise"])
    (row,) = table_rows(md, "SD [N·m]", "UIO (14)", num(pv.TQ_TABLE_III["uio"]["sd"], 5))
    assert row[3] == num(uio["sd"])
    assert row[4] == f"{uio['sd'] / pv.TQ_TABLE_III['uio']['sd']:.2f}"
    tv = run_scenario("torque-rig", "adaptive-tv", seed=1, overrides={"kappa": 0.1})["metrics"]
    paper_sd = num(pv.TQ_TABLE_VII["(54) κ = 0.1"]["sd"], 5)
    (row,) = table_rows(md, "SD [N·m]", "(54) κ = 0.1", paper_sd)
    assert row[3] == num(tv["sd"])
    # Under the frozen Γ = 10·I of (54) (docs/estimators.md#dev-tq-gamma-54) Table IV's
    # ordering holds on torque-si seed 1; on the rig it differs, explained with the live
    # spans of Θ̂ against the simulator's Θ.
    assert "torque-si Table IV: as in the paper ((54) κ = 0.1) on 1 of 1 seeds" in md
    tv_run = execute_scenario("torque-rig", "adaptive-tv", seed=1, overrides={"kappa": 0.1})
    t = tv_run.data.signals.time
    window = (t >= t[0] + pv.TQ_WINDOW_S[0]) & (t <= t[0] + pv.TQ_WINDOW_S[1])
    theta1 = tv_run.final.outputs["theta1"][window]
    assert (
        f"(54) κ = 0.1 θ̂1 {num(float(theta1.min()), 3)}…{num(float(theta1.max()), 3)} N·m/rpm" in md
    )
    # The paper's own ISE contradicts ∫τ̃² dt over 25 s (it exceeds T·MAE²): said, with numbers.
    assert "The paper's ISE exceeds T·MAE²" in md
    assert "in 14 of 14 entries" in md
    # The paper's Table VII best is (50) κ = 0.1 — computed from the constants, flagged.
    assert "in the paper's own Table VII the lowest ISE and SD belong to (50) κ = 0.1" in md
    assert "Figure (interactive, in report.html):* torque-si (seed 1)" in md


@pytest.mark.slow
def test_nox_and_lpv_scores_are_mapwise_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run(
        ["reproduce", "--out", str(tmp_path), "--only", "lpv,nox", "--seeds", "2"], capsys
    )
    assert code == 0, err
    md = (tmp_path / "report.md").read_text()
    assert md.index("## SKF paper §6") < md.index("## LPV paper §4")  # report order, not --only's
    kf = run_scenario("nox-sdmp", "kf", seed=2)["metrics"]
    (row,) = table_rows(md, "nox-sdmp", "2", "KF")
    assert row[3:7] == [
        num(kf["rmse"]),
        num(kf["max_abs_error"]),
        pct(kf["mean_relative_error"], 1),
        num(kf["output_rmse"]),
    ]
    cal36 = run_scenario("nox-nedc", "skf", seed=2, overrides={"sigma_w": 7.0})["metrics"]
    (row,) = table_rows(md, "nox-nedc", "2", "SKF Cal (36)")
    assert row[3] == num(cal36["rmse"])
    for scenario in ("maf-whtc", "maf-ftp75"):
        lpv = run_scenario(scenario, "lpv", seed=2)["metrics"]
        (row,) = table_rows(md, f"{scenario} ({pv.LPV_REFS[scenario]})", "2")
        paper = pv.LPV_MEAN_RELATIVE_ERROR[scenario]
        assert row[2:5] == [
            pct(paper),
            pct(lpv["mean_relative_error"]),
            "yes" if lpv["mean_relative_error"] <= paper else "no",
        ]
    assert "10.41 %" in md
    assert "5.28 %" in md


@pytest.mark.slow
@pytest.mark.skipif(
    not {"ekf-def", "ekf-aug", "ekf-map"} <= set(registry()), reason="EKF not registered yet"
)
def test_ekf_table1_uses_the_registered_observers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run(
        ["reproduce", "--out", str(tmp_path), "--only", "ekf", "--seeds", "0"], capsys
    )
    assert code == 0, err
    md = (tmp_path / "report.md").read_text()
    (row,) = table_rows(md, "0", "W_c [kg/s]", "RMSE (`mapwise run`)")
    for cell, name in zip(row[3:], ("ekf-def", "ekf-aug", "ekf-map"), strict=True):
        assert cell == num(run_scenario("maf-1d-whtc", name, seed=0)["metrics"]["rmse"])
    assert "Table 1's pattern" in md


def test_sections_say_not_available_when_estimators_are_not_registered() -> None:
    known = set(registry()) - {"ekf-def", "ekf-aug", "ekf-map", "lpv", "adaptive-tv"}
    ekf = build_ekf([0], known=known)
    assert ekf.verdict == (
        "Not available: ekf-def, ekf-aug, ekf-map are not registered in the estimator registry yet."
    )
    assert build_lpv([0], known=known).verdict.startswith("Not available")
    torque = build_torque([0], known=known)
    assert "adaptive: not available (adaptive-tv not registered)" in torque.verdict
    assert torque.verdict.startswith("Lowest ISE and SD — torque-si Table III: as in the paper")


def test_a_failing_section_is_reported_and_the_rest_written(tmp_path: Path) -> None:
    section = runner._build_section("no-such-section", [0])
    assert section.verdict.startswith("FAILED: KeyError")
    assert "Traceback" in section.blocks[0].markdown  # type: ignore[union-attr]


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--seeds", "x"], "--seeds"),
        (["--seeds", ""], "--seeds"),
        (["--seeds", "1,-2"], "--seeds"),
        (["--only", "skf,foo"], "--only: unknown section 'foo'"),
        (["--only", ""], "--only"),
        (["--out", "FILE"], "--out"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(
    args: list[str], fragment: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory\n")
    args = [str(blocker / "sub") if a == "FILE" else a for a in args]
    code, out, err = run(["reproduce", *args], capsys)
    assert code == 2
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("mapwise: error: ")
    assert fragment in lines[0]
