"""The Simulate form's duration: bounded by the scenario's record (shown beside the field),
sent as ``duration_s`` so only the first seconds are simulated, and a refused value named
next to the field; while the server simulates, a progress bar follows the plant
integrator's steps (POST /api/datasets/simulate/stream)."""

from __future__ import annotations

import uuid

import httpx
from playwright.sync_api import Page, expect

from tests.frontend.conftest import Console


def test_simulate_only_the_first_seconds(page: Page, api: httpx.Client, console: Console) -> None:
    items = api.get("/api/scenarios").json()["items"]
    scenario = next(s for s in items if s["name"] == "skf-sim2")
    name = f"sim-short-{uuid.uuid4().hex[:8]}"
    page.goto("/datasets")
    page.locator("#sim-scenario").select_option("skf-sim2")
    duration = page.locator("#sim-duration")
    expect(duration).to_have_attribute("max", str(scenario["duration_s"]).removesuffix(".0"))
    expect(page.locator("#sim-duration-help")).to_contain_text("up to")

    # Longer than the record: refused by the server, named next to the field.
    console.allow(r"status of 422")
    duration.fill(str(scenario["duration_s"] * 2))
    page.fill("#sim-name", name)
    page.get_by_role("button", name="Simulate").click()
    expect(duration).to_have_attribute("aria-invalid", "true")
    expect(page.locator(".field-error")).to_contain_text("duration")

    duration.fill("20")
    page.get_by_role("button", name="Simulate").click()
    row = page.locator("[data-dataset-list] tbody tr", has_text=name)
    expect(row).to_have_attribute("aria-current", "true")
    created = next(
        d
        for d in api.get("/api/datasets", params={"limit": 500}).json()["items"]
        if d["name"] == name
    )
    assert 19.0 <= created["duration_s"] <= 20.0
    expect(page.locator("[data-sim-progress]")).to_have_text("")


def test_a_long_simulation_shows_its_progress(page: Page, api: httpx.Client) -> None:
    """The whole WHTC air path (two plant runs, ~2 s): the bar passes through values between
    0 and 100 % as the server streams them, then the new dataset is selected."""
    name = f"sim-progress-{uuid.uuid4().hex[:8]}"
    page.goto("/datasets")
    page.locator("#sim-scenario").select_option("maf-whtc")
    page.fill("#sim-name", name)
    page.fill("#sim-seed", "7")
    # Every value the bar shows, recorded in the page as it changes.
    page.evaluate(
        """() => {
            window.simValues = [];
            const bar = document.querySelector("[data-sim-bar]");
            new MutationObserver(() => window.simValues.push(Number(bar.ariaValueNow)))
                .observe(bar, {attributes: true, attributeFilter: ["aria-valuenow"]});
        }"""
    )
    with page.expect_response("**/api/datasets/simulate/stream") as response:
        page.get_by_role("button", name="Simulate").click()
    assert response.value.status == 200
    row = page.locator("[data-dataset-list] tbody tr", has_text=name)
    expect(row).to_have_attribute("aria-current", "true", timeout=120_000)
    values = page.evaluate("window.simValues")
    assert any(0 < v < 100 for v in values), values
    assert values[-1] == 100, values
    expect(page.locator("[data-sim-bar]")).to_be_hidden()
    expect(page.locator("[data-sim-progress]")).to_have_text("")
