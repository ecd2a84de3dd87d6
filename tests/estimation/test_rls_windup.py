"""Why the NOx scenarios give RLS a short memory and the covariance limit (estimation.scenarios).

RLS with exponential forgetting (docs/algorithms.md §2.4) winds up where the regressor stays
constant: in the directions of the active block the data do not see, P grows as λ^-k. The NEDC
at 50 Hz dwells on one operating point for thousands of samples (idle, cruises), so the
forgetting the papers' other filters never need blows the map up unless P is capped.
"""

from __future__ import annotations

import numpy as np
import pytest

from app.cli.run import execute_scenario
from estimation.scenarios import get_scenario

WOUND_UP = {"forgetting": 0.995, "limit": "none"}


@pytest.fixture(scope="module")
def nedc():  # type: ignore[no-untyped-def]
    return get_scenario("nox-nedc").build(seed=0, mismatch="none")


def test_nedc_dwells_on_constant_regressors(nedc) -> None:  # type: ignore[no-untyped-def]
    points = nedc.signals.stack(["speed_rpm", "fuel_mg_per_stroke"])
    same = np.all(points[1:] == points[:-1], axis=1)
    assert same.mean() > 0.5  # most samples repeat the previous operating point exactly


def test_scenario_rls_settings_keep_the_map_bounded(nedc) -> None:  # type: ignore[no-untyped-def]
    config = get_scenario("nox-nedc").default_config("rls")
    assert config["limit"] == "p0"
    assert 1.0 / (1.0 - config["forgetting"]) == pytest.approx(1000.0)
    ours = execute_scenario("nox-nedc", "rls", seed=0, data=nedc).result["metrics"]
    wound = execute_scenario("nox-nedc", "rls", seed=0, data=nedc, overrides=WOUND_UP).result[
        "metrics"
    ]
    assert ours["mean_relative_error"] < 0.3
    assert wound["mean_relative_error"] > 10 * ours["mean_relative_error"]
    assert wound["max_abs_error"] > 5000.0  # ppm: cells driven far outside any NOx value
