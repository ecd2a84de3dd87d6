"""New run view: the estimator picker and generated config form, the grid editor with typed
start values and locked cells, and a run started from a base map saved in the UI."""

from __future__ import annotations

import re
import uuid

from playwright.sync_api import Page, expect

from tests.frontend.browser import upload_example, wait_run
from tests.frontend.test_compare_versions_view import start_run
from tests.frontend.test_run_view import RUN_URL, run_form_url


def test_estimator_picker_and_schema_form(page: Page, api) -> None:
    dataset = upload_example(api, f"form-{uuid.uuid4().hex[:8]}")
    catalog = {e["name"]: e for e in api.get("/api/estimators").json()["items"]}
    page.goto(run_form_url(dataset["id"]))
    skf = page.locator('[data-estimator="skf"]')
    expect(skf).to_contain_text(catalog["skf"]["title"])
    expect(skf).to_contain_text("(2014)")
    # Defaults from the catalog, one labelled control per config property.
    for key, value in catalog["skf"]["defaults"].items():
        control = page.locator(f"#cfg-skf-{key}")
        if isinstance(value, int | float) and not isinstance(value, bool):
            expect(control).to_have_value(re.compile(rf"^{value:g}$|^{value}$"))
    expect(page.get_by_label("Use sensor")).not_to_be_checked()
    page.get_by_label("Use sensor").check()
    expect(page.locator("#cfg-skf-sensor-lag")).to_be_visible()
    # A second estimator adds a config tab; the tabs switch with the arrow keys.
    page.check("#est-rls")
    expect(page.get_by_role("tab", name="skf")).to_have_attribute("aria-selected", "true")
    page.get_by_role("tab", name="skf").focus()
    page.keyboard.press("ArrowRight")
    expect(page.get_by_role("tab", name="rls")).to_be_focused()
    expect(page.locator('[data-config="rls"]')).to_be_visible()
    expect(page.locator('[data-config="skf"]')).to_be_hidden()
    expect(page).to_have_url(re.compile(r"estimator=skf,rls"))


def test_typed_start_values_with_locked_cells(page: Page, api) -> None:
    dataset = upload_example(api, f"locked-{uuid.uuid4().hex[:8]}")
    page.goto(run_form_url(dataset["id"]))
    page.fill("#axis-0-bp", "500, 1500, 2500, 3500, 4500")
    page.locator("#axis-0-bp").dispatch_event("change")
    page.fill("#axis-1-bp", "0, 20, 40, 60, 80")
    page.locator("#axis-1-bp").dispatch_event("change")
    page.check("#start-values")
    page.fill("#grid-fill", "250")
    page.get_by_role("button", name="Fill all").click()
    cells = page.locator("[data-values-grid] input[data-cell]")
    expect(cells).to_have_count(25)
    page.check("#grid-lock")
    page.locator('[data-cell="12"]').click()  # the centre cell, visited by the drive
    page.locator('[data-cell="13"]').focus()
    page.keyboard.press("l")
    expect(page.locator("[data-values-grid]")).to_contain_text("2 locked cell(s)")
    page.fill("#cfg-skf-p0", "10000")
    page.fill("#cfg-skf-sigma_w", "5")
    page.fill("#cfg-skf-sigma_v", "50")
    page.locator("[data-start]").click()
    expect(page).to_have_url(RUN_URL)
    run = wait_run(api, int(RUN_URL.search(page.url).group(1)))
    assert run["status"] == "succeeded", run["error"]
    final = api.get(f"/api/runs/{run['id']}/versions").json()["items"][-1]
    values = api.get(f"/api/runs/{run['id']}/versions/{final['id']}").json()["values"]
    assert values[2][2] == 250.0  # locked: untouched
    assert values[2][3] == 250.0
    assert values[2][1] != 250.0  # a visited neighbour moved


def test_save_a_version_as_base_map_and_start_from_it(page: Page, api) -> None:
    dataset = upload_example(api, f"base-{uuid.uuid4().hex[:8]}")
    source = wait_run(api, start_run(api, dataset["id"], "skf")["id"])
    page.goto(f"/versions?a={source['id']}")
    expect(page.locator('[data-stat="max"]')).to_be_visible()
    page.locator('[data-base-map="b"]').click()
    expect(page.locator(".toast")).to_contain_text("Saved base map")
    base = next(
        m
        for m in api.get("/api/base-maps", params={"limit": 500}).json()["items"]
        if f"run {source['id']} version" in m["name"]
    )

    page.goto(run_form_url(dataset["id"]))
    page.check("#start-base")
    page.select_option("#base-map", str(base["id"]))
    expect(page.locator("[data-base-info]")).to_contain_text(f"from run #{source['id']}")
    expect(page.locator("#axis-0-bp")).to_have_value(
        "500, 1000, 1500, 2000, 2500, 3000, 3500, 4000, 4500"
    )
    page.locator("[data-start]").click()
    expect(page).to_have_url(RUN_URL)
    run = api.get(f"/api/runs/{RUN_URL.search(page.url).group(1)}").json()
    assert run["base_map_id"] == base["id"]
    assert wait_run(api, run["id"])["status"] == "succeeded"
