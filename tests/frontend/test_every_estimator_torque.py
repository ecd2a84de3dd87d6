"""Every estimator of the torque scenario starts from the New-run form with its defaults and
succeeds (the catalog's split: ``tests/frontend/every_estimator.py``); switching datasets
unticks what does not apply, and "Run again…" on a run's page opens the form filled with that
run."""

from __future__ import annotations

import re

import httpx
import pytest
from playwright.sync_api import Page, expect

from tests.frontend.browser import wait_run
from tests.frontend.every_estimator import (
    RUN_URL,
    TORQUE,
    estimators_on,
    pick,
    runs_from_the_form_with_its_defaults,
    scenario_for,
    simulated,
)


@pytest.mark.parametrize("estimator", estimators_on(TORQUE))
def test_every_torque_estimator_runs_from_the_form_with_its_defaults(
    page: Page, api: httpx.Client, estimator: str
) -> None:
    runs_from_the_form_with_its_defaults(page, api, estimator)


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
