"""Every registered estimator starts from the New-run form with its defaults and succeeds.

For each estimator of the catalog (``GET /api/estimators``, never a hand list) a short
dataset is simulated from a scenario it applies to (one per scenario, shared by the
estimators of a family); the form is opened on /runs/new, the dataset and the estimator are
picked, and it is submitted untouched: the catalog's defaults with the scenario's setup
(on by default for a simulated dataset: its grid, signals and settings). The run must reach
``succeeded`` and the pages log no console error. Then "Run again…" on a run's page opens
the form filled with that run, and switching datasets unticks what does not apply.
"""

from __future__ import annotations

import re
from typing import Any

import httpx
import pytest
from playwright.sync_api import Page, expect

from estimation.registry import names
from estimation.scenarios import Scenario, scenarios
from tests.frontend.browser import wait_run

RUN_URL = re.compile(r"/runs/(\d+)$")
# A few seconds to a minute of data: enough for every estimator to produce its results (the
# torque metrics start 5 s in, the EKFs settle x0 over 30 s), short enough for a quick run.
DURATION_S = {"skf-sim1": None, "maf-whtc": 60.0, "maf-1d-whtc": 60.0, "torque-si": 6.0}
_DATASETS: dict[tuple[str, str], dict[str, Any]] = {}


def scenario_for(estimator: str) -> Scenario:
    """A scenario suggesting ``estimator``, else the first one it applies to."""
    applies = [s for s in scenarios().values() if s.configs(estimator) is not None]
    assert applies, f"no scenario applies to {estimator}"
    return next((s for s in applies if estimator in s.suggested), applies[0])


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
    expect(page.locator("[data-use-setup]")).to_be_visible()
    box = page.locator(f"#est-{estimator}")
    expect(box).to_be_visible()
    for other in page.locator('input[name="estimator"]:checked').all():
        if other.get_attribute("value") != estimator:
            other.uncheck()
    box.check()
    expect(page.locator('input[name="estimator"]:checked')).to_have_count(1)
    expect(page.locator(f'[data-config="{estimator}"]')).to_be_visible()


@pytest.mark.parametrize("estimator", names())
def test_every_estimator_runs_from_the_form_with_its_defaults(
    page: Page, api: httpx.Client, estimator: str
) -> None:
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


def test_the_scenario_setup_fills_grid_signals_and_settings(page: Page, api: httpx.Client) -> None:
    """On a NOx scenario the SKF form shows the scenario's grid and its paper settings, each
    field saying where its value comes from; off, the catalog's defaults come back."""
    dataset = simulated(api, scenario_for("skf"))
    setup = api.get(f"/api/datasets/{dataset['id']}/setup").json()["estimators"]["skf"]
    pick(page, dataset["id"], "skf")
    axes = setup["table"]["axes"]
    expect(page.locator("#axis-0-bp")).to_have_value(re.compile(rf"^{axes[0]['breakpoints'][0]:g}"))
    field = page.locator('[data-config="skf"] [data-key="sigma_w"]')
    expect(field.locator("input")).to_have_value(f"{setup['config']['sigma_w']:g}")
    expect(field.locator("[data-source]")).to_contain_text("scenario")
    page.uncheck("#run-use-setup")
    catalog = {e["name"]: e for e in api.get("/api/estimators").json()["items"]}
    expect(page.locator("#cfg-skf-sigma_w")).to_have_value(
        f"{catalog['skf']['defaults']['sigma_w']:g}"
    )
    expect(page.locator('[data-config="skf"] [data-key="sigma_w"] [data-source]')).to_be_visible()


def test_switching_dataset_unticks_what_does_not_apply(page: Page, api: httpx.Client) -> None:
    torque = simulated(api, scenario_for("uio"))
    maps = simulated(api, scenario_for("skf"))
    pick(page, torque["id"], "uio")
    page.check("#est-smo")
    page.select_option("#run-dataset", str(maps["id"]))
    expect(page.locator("#est-uio")).not_to_be_checked()
    expect(page.locator("#est-smo")).not_to_be_checked()
    expect(page.locator('input[name="estimator"]:checked')).to_have_count(1)
    expect(page.locator('[data-estimator="uio"]')).to_have_attribute("data-applies", "false")


def test_run_again_opens_the_form_filled_with_the_run(page: Page, api: httpx.Client) -> None:
    dataset = simulated(api, scenario_for("uio"))
    body = {
        "dataset_id": dataset["id"],
        "estimator": "smo",
        "signals": {"speed_channel": "speed_rpm", "load_channel": "load_torque_nm"},
        "config": {"lambda1": 123.0, "k": 0.02, "pace": 100, "version_every": {"samples": 500}},
    }
    response = api.post("/api/runs", json=body)
    assert response.status_code == 201, response.text
    source = wait_run(api, response.json()["id"])
    page.goto(f"/runs/{source['id']}")
    page.locator("[data-run-again]").click()
    expect(page).to_have_url(re.compile(rf"/runs/new\?.*from={source['id']}"))
    expect(page.locator(f"[data-from-run='{source['id']}']")).to_be_visible()
    expect(page.locator("#run-dataset")).to_have_value(str(dataset["id"]))
    expect(page.locator("#est-smo")).to_be_checked()
    expect(page.locator("#cfg-smo-lambda1")).to_have_value("123")
    expect(page.locator("#cfg-smo-k")).to_have_value("0.02")
    expect(page.locator("#run-pace")).to_have_value("100")
    expect(page.locator("#run-cadence")).to_have_value("samples")
    expect(page.locator("#run-cadence-n")).to_have_value("500")
    page.fill("#cfg-smo-lambda1", "150")
    page.locator("[data-start]").click()
    expect(page).to_have_url(RUN_URL)
    again = wait_run(api, int(RUN_URL.search(page.url).group(1)))
    assert again["status"] == "succeeded", again["error"]
    assert again["config"]["lambda1"] == 150.0
    assert again["config"]["k"] == 0.02
    assert again["config"]["version_every"] == {"samples": 500}
