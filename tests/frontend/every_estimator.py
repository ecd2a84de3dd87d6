"""What the every-estimator browser tests share: a short simulated dataset per scenario, the
New-run form opened on one estimator, and the check that an estimator started from the form
with its defaults succeeds (``test_every_estimator*.py``).

The catalog (``estimation.registry.names()``, never a hand list) is split over three test
files by the scenario each estimator runs on, so the parallel phase runs them side by side:
the NOx-map scenario's estimators, the torque scenario's, and every other scenario's (the
air path's, and any new family's: none is left out).
"""

from __future__ import annotations

import re
from typing import Any

import httpx
from playwright.sync_api import Page, expect

from estimation.registry import names
from estimation.scenarios import Scenario, scenarios
from tests.frontend.browser import wait_run

RUN_URL = re.compile(r"/runs/(\d+)$")
# A few seconds to a minute of data: enough for every estimator to produce its results (the
# torque metrics start 5 s in, the EKFs settle x0 over 30 s), short enough for a quick run.
DURATION_S = {"skf-sim1": None, "maf-whtc": 60.0, "maf-1d-whtc": 60.0, "torque-si": 6.0}
# The scenarios with a test file of their own; ``estimators_elsewhere`` takes the rest.
MAPS, TORQUE = "skf-sim1", "torque-si"
_DATASETS: dict[tuple[str, str], dict[str, Any]] = {}


def scenario_for(estimator: str) -> Scenario:
    """A scenario suggesting ``estimator``, else the first one it applies to."""
    applies = [s for s in scenarios().values() if s.configs(estimator) is not None]
    assert applies, f"no scenario applies to {estimator}"
    return next((s for s in applies if estimator in s.suggested), applies[0])


def estimators_on(scenario: str) -> list[str]:
    """The registered estimators that run on ``scenario`` (:func:`scenario_for`)."""
    return [n for n in names() if scenario_for(n).name == scenario]


def estimators_elsewhere() -> list[str]:
    """The registered estimators on a scenario other than ``MAPS`` and ``TORQUE``."""
    return [n for n in names() if scenario_for(n).name not in (MAPS, TORQUE)]


def simulated(api: httpx.Client, scenario: Scenario) -> dict[str, Any]:
    """One short simulated dataset per scenario and server."""
    key = (str(api.base_url), scenario.name)
    if key not in _DATASETS:
        body: dict[str, Any] = {"scenario": scenario.name, "seed": 0}
        if DURATION_S.get(scenario.name) is not None:
            body["duration_s"] = DURATION_S[scenario.name]
        response = api.post("/api/datasets/simulate", json=body, timeout=120)
        assert response.status_code == 201, response.text
        _DATASETS[key] = response.json()
    return _DATASETS[key]


def pick(page: Page, dataset_id: int, estimator: str) -> None:
    """Open New run, pick the dataset and only ``estimator``."""
    page.goto("/runs/new")
    page.select_option("#run-dataset", str(dataset_id))
    expect(page.locator("#run-dataset")).to_have_value(str(dataset_id))
    # The pick loads the dataset in the background and ends by writing it into the URL: until
    # then the form may still tick its own suggestion (when none is ticked) or rewrite the URL
    # of the page the test has moved on to, so everything below waits for it.
    expect(page).to_have_url(re.compile(rf"[?&]dataset={dataset_id}(&|$)"))
    expect(page.locator("[data-use-setup]")).to_be_visible()
    box = page.locator(f"#est-{estimator}")
    expect(box).to_be_visible()
    for other in page.locator('input[name="estimator"]:checked').all():
        if other.get_attribute("value") != estimator:
            other.uncheck()
    box.check()
    expect(page.locator('input[name="estimator"]:checked')).to_have_count(1)
    expect(page.locator(f'[data-config="{estimator}"]')).to_be_visible()


def runs_from_the_form_with_its_defaults(page: Page, api: httpx.Client, estimator: str) -> None:
    """``estimator``, picked on the New-run form with its scenario's dataset and submitted
    untouched, succeeds; its finished run's page shows its family's views."""
    catalog = {e["name"]: e for e in api.get("/api/estimators").json()["items"]}
    assert estimator in catalog
    dataset = simulated(api, scenario_for(estimator))
    pick(page, dataset["id"], estimator)
    expect(page.locator("#run-use-setup")).to_be_checked()
    with page.expect_response(
        lambda r: r.url.endswith("/api/runs") and r.request.method == "POST"
    ) as created:
        page.locator("[data-start]").click()
    assert created.value.status == 201, estimator
    expect(page).to_have_url(RUN_URL)
    run_id = int(RUN_URL.search(page.url).group(1))
    # The run view has its own tests: leave it, so the run gets the machine.
    page.goto("about:blank")
    run = wait_run(api, run_id, timeout_s=180)
    assert run["status"] == "succeeded", f"{estimator}: {run['error']}"
    assert run["estimator"] == estimator
    assert run["dataset_id"] == dataset["id"]
    # The finished run's page shows its family's views: the torque views (estimate vs true
    # torque, scoring window) for the torque estimators alone.
    page.goto(f"/runs/{run_id}")
    expect(page.locator("[data-run-status] .badge")).to_have_text("succeeded")
    expect(page.locator("[data-plot] .main-svg").first).to_be_attached()
    torque_views = page.locator('[data-plot="torque"]')
    if catalog[estimator]["kind"] == "torque":
        expect(torque_views).to_have_count(1)
    else:
        expect(torque_views).to_have_count(0)
    # Every RMSE card states its unit, unless the measured output is dimensionless ("-").
    units = {c["name"]: c["unit"] for c in dataset["channels"]}
    output = (run.get("signals") or {}).get("y")
    if output is None or units.get(output, "") not in ("", "-"):
        rmse_cards = page.locator('[data-metric$="rmse"]')
        for k in range(rmse_cards.count()):
            expect(rmse_cards.nth(k).locator(".u")).not_to_be_empty()
    # θ̂2's own axis (adaptive-tv) has its own round ticks, not θ̂1's positions mapped onto it.
    if estimator == "adaptive-tv":
        page.locator('[data-plot="theta"] .main-svg').first.wait_for(state="attached")
        ticks = page.eval_on_selector(
            '[data-plot="theta"]',
            "el => { const a = el._fullLayout.yaxis2; return [a.dtick, a._vals.map((v) => v.x)]; }",
        )
        step, values = float(ticks[0]), ticks[1]
        assert values, ticks
        assert all(abs(v / step - round(v / step)) < 1e-6 for v in values), ticks
    # A 1-D map's plots name what they show on the y axis, as a 2-D map's colour bars do.
    final = (
        run["n_versions"]
        and api.get(f"/api/runs/{run_id}/versions/by-number/{run['n_versions']}").json()
    )
    if final and len(final.get("axes") or []) == 1:
        y_title = "el => el._fullLayout.yaxis.title.text"
        hits = page.locator('[data-plot="hits"] .main-svg').first
        hits.wait_for(state="attached")
        assert page.eval_on_selector('[data-plot="hits"]', y_title) == "hits [samples]"
        variance = page.eval_on_selector('[data-plot="variance"]', y_title)
        assert variance.startswith("variance ["), variance
    # The measured output's RMSE is in the residual's unit, whatever the map's (the EKF's
    # map q is relative, its output the MAF's kg/s).
    lines = api.get(f"/api/runs/{run_id}/series", params={"points": 2}).json()["series"]
    residual_unit = (lines.get("residual") or {}).get("unit")
    if "output_rmse" in run["metrics"] and residual_unit not in (None, "", "-"):
        expect(page.locator('[data-metric="output_rmse"] .u')).to_have_text(residual_unit)
