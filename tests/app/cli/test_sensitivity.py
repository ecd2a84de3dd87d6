"""The declared tuning rule for Γ of TQ (54) (app/reproduce/sensitivity.py): the sweep covers
every grid value, the rule picks the argmin of the seed-mean ISE, and the paper's Γ for (50)
diverges in (54). Short scenarios and few seeds keep it fast; the full sweep is the report's
``sensitivity`` section (docs/estimators.md#dev-tq-gamma-54)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.cli.run import execute_scenario
from app.reproduce import SECTION_KEYS
from app.reproduce.report import num
from app.reproduce.sensitivity import GRID, GammaSweep, paper_gamma_run, sweep, table
from estimation.torque.config import AdaptiveTvConfig

SHORT_S = 8.0


def test_sweep_has_every_grid_value_and_the_rule_picks_the_argmin() -> None:
    result = sweep(GRID, (0, 1), duration_s=SHORT_S)
    assert result.grid == GRID
    assert all(len(result.ise[g]) == 2 for g in GRID)
    means = [float(np.mean(result.ise[g])) for g in GRID]
    assert result.chosen == GRID[int(np.argmin(means))]
    # the numbers are mapwise run's own, with Γ = g·I
    g = GRID[2]
    run = execute_scenario(
        "torque-si",
        "adaptive-tv",
        seed=1,
        duration_s=SHORT_S,
        mismatch="nominal",
        overrides={"gamma": (g, g)},
    )
    assert result.ise[g][1] == run.result["metrics"]["ise"]
    rows = table(result).rows
    assert [r[0].split()[0] for r in rows] == [f"{g:g}" for g in GRID]
    assert sum("(selected)" in r[0] for r in rows) == 1
    assert "(selected)" in rows[GRID.index(result.chosen)][0]
    assert rows[0][-1] == num(means[0])


def test_the_rule_takes_the_lowest_mean_not_the_lowest_single_seed() -> None:
    result = GammaSweep(
        grid=(1.0, 3.0, 10.0),
        seeds=(0, 1),
        ise={1.0: (50.0, 400.0), 3.0: (120.0, 130.0), 10.0: (math.inf, 10.0)},
    )
    assert result.chosen == 3.0


def test_the_papers_gamma_for_law_50_diverges_in_law_54() -> None:
    paper = paper_gamma_run(0, duration_s=15.0)
    assert paper.diverged_at_s is not None
    assert paper.diverged_at_s < 15.0


def test_the_section_is_part_of_reproduce() -> None:
    assert "sensitivity" in SECTION_KEYS


@pytest.mark.slow
def test_reproduce_prints_the_table_and_the_default_is_the_rules_choice(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The full rule (grid 1–100, tuning seeds 0–4) through ``mapwise reproduce``: the frozen
    default of AdaptiveTvConfig is the grid value it selects."""
    code = main(["reproduce", "--out", str(tmp_path), "--only", "sensitivity"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "it is the frozen default" in out
    md = (tmp_path / "report.md").read_text()
    g = AdaptiveTvConfig().gamma[0]
    assert AdaptiveTvConfig().gamma == (g, g)
    assert f"| {g:g} (selected) (default) |" in md
    for value in GRID:
        assert f"| {value:g}" in md
    assert "diverges for (54)" in md
