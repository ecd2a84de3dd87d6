"""Every registered estimator on every scenario it applies to (issue 18: "every estimator
runs from the dashboard with its defaults, on every scenario it applies to"), started as the
dashboard starts it: the scenario's setup over the catalog's defaults, through the REST API,
to ``succeeded``; the map estimators scored against the truth on the scenario's grid.
test_every_estimator.py runs each estimator on its own scenario on both backends and checks
its series and frames; every pair runs here, on SQLite (the backend is not what they test)."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from estimation.registry import names
from estimation.scenarios import scenarios
from tests.support.helpers import start_run, wait_run
from tests.support.scenario_runs import scenario_for, scenario_request

PAIRS = [
    (estimator, scenario.name)
    for estimator in names()
    for scenario in scenarios().values()
    if scenario.configs(estimator) is not None
]

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def backend() -> str:
    return "sqlite"


def test_the_pairs_cover_every_estimator_and_scenario() -> None:
    assert {e for e, _ in PAIRS} == set(names())
    assert {s for _, s in PAIRS} == set(scenarios())
    assert all((e, scenario_for(e).name) in PAIRS for e in names())


@pytest.mark.parametrize(("estimator", "scenario"), PAIRS)
def test_every_estimator_succeeds_on_every_scenario_it_applies_to(
    client: TestClient, estimator: str, scenario: str
) -> None:
    body = scenario_request(client, estimator, scenarios()[scenario])
    done = wait_run(client, start_run(client, body)["id"], timeout=300)
    assert done["status"] == "succeeded", f"{estimator} on {scenario}: {done['error']}"
    if done["produces_map"] and estimator != "ekf-def":
        assert {"map_rmse", "rmse"} & set(done["metrics"]), done["metrics"]
