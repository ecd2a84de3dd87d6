"""Datasets view: upload by drag and drop (progress, units, channel previews), column mapping
into the run form, API errors next to the field, simulate, delete."""

from __future__ import annotations

import re
import uuid

from playwright.sync_api import Page, expect

from tests.frontend.browser import DROP_FILE, EXAMPLE_CSV, shot
from tests.frontend.conftest import Console


def test_drop_a_csv_see_its_channels_and_map_its_columns(page: Page, api) -> None:
    name = f"drop-{uuid.uuid4().hex[:8]}"
    page.goto("/datasets")
    expect(page.get_by_role("heading", name="Datasets", exact=True)).to_be_visible()

    page.evaluate(DROP_FILE, [EXAMPLE_CSV.read_text(), "nox_log.csv"])
    columns = page.locator("[data-upload-columns]")
    expect(columns).to_contain_text("speed_rpm")
    expect(columns.get_by_label("Unit of nox_ppm")).to_have_value("ppm")
    page.fill("#upload-name", name)
    page.get_by_role("button", name="Upload").click()

    progress = page.get_by_role("progressbar", name="Upload progress")
    expect(progress).to_have_attribute("aria-valuenow", "100")
    row = page.locator("[data-dataset-list] tbody tr", has_text=name)
    expect(row).to_have_attribute("aria-current", "true")
    expect(row).to_contain_text("7,500")

    # Channel preview: every channel with its unit and a small plot.
    for channel, unit in (
        ("speed_rpm", "rpm"),
        ("fuel_mg_per_stroke", "mg/stroke"),
        ("nox_ppm", "ppm"),
    ):
        tile = page.locator(f'[data-channel="{channel}"]')
        expect(tile).to_contain_text(f"[{unit}]")
        expect(tile.locator(".main-svg").first).to_be_attached()

    # Column mapping → the run form, prefilled (and a reload keeps it).
    mapping = page.locator("[data-mapping]")
    mapping.get_by_label("Estimator").select_option("skf")
    mapping.get_by_label("Measured output (y)").select_option("nox_ppm")
    mapping.get_by_label("Table axis 1 (x)").select_option("speed_rpm")
    mapping.get_by_label("Table axis 2 (y)").select_option("fuel_mg_per_stroke")
    shot(page, "datasets")
    page.locator("[data-continue]").click()
    dataset_id = next(
        d["id"]
        for d in api.get("/api/datasets", params={"limit": 500}).json()["items"]
        if d["name"] == name
    )
    expect(page).to_have_url(
        re.compile(
            rf"/runs/new\?dataset={dataset_id}&estimator=skf&signals=y:nox_ppm&axes=speed_rpm,fuel_mg_per_stroke$"
        )
    )
    for _ in range(2):
        expect(page.locator("#est-skf")).to_be_checked()
        expect(page.locator("#sig-y")).to_have_value("nox_ppm")
        expect(page.locator("#axis-0-name")).to_have_value("speed_rpm")
        expect(page.locator("#axis-1-name")).to_have_value("fuel_mg_per_stroke")
        page.reload()


def test_a_bad_csv_is_refused_with_the_error_on_its_column(
    page: Page, api, console: Console
) -> None:
    console.allow(r"status of 422")
    name = f"bad-{uuid.uuid4().hex[:8]}"
    page.goto("/datasets")
    page.locator("#upload-file").set_input_files(
        files=[
            {
                "name": "bad.csv",
                "mimeType": "text/csv",
                "buffer": b"time [s],rpm [rpm]\n0,1000\n0.1,abc\n",
            }
        ]
    )
    page.fill("#upload-name", name)
    page.get_by_role("button", name="Upload").click()
    error = page.locator("[data-upload-columns] .field-error")
    expect(error).to_contain_text("abc")
    expect(page.get_by_label("Unit of rpm")).to_have_attribute("aria-invalid", "true")
    names = [d["name"] for d in api.get("/api/datasets", params={"limit": 500}).json()["items"]]
    assert name not in names


def test_simulate_a_scenario_then_delete_it(page: Page, api) -> None:
    name = f"sim-{uuid.uuid4().hex[:8]}"
    page.goto("/datasets")
    page.locator("#sim-scenario").select_option("skf-sim2")
    expect(page.locator("[data-scenario-about]")).to_contain_text("poor excitation")
    page.fill("#sim-seed", "3")
    page.fill("#sim-name", name)
    page.get_by_role("button", name="Simulate").click()
    row = page.locator("[data-dataset-list] tbody tr", has_text=name)
    expect(row).to_have_attribute("aria-current", "true")
    expect(page.locator('[data-channel="u2"]')).to_contain_text("[mg/stroke]")
    created = next(
        d
        for d in api.get("/api/datasets", params={"limit": 500}).json()["items"]
        if d["name"] == name
    )
    assert created["source"] == "scenario:skf-sim2"
    assert created["seed"] == 3

    row.get_by_role("button", name=f"Delete dataset {name}").click()
    page.locator("[data-confirm-ok]").click()
    expect(row).to_have_count(0)
    assert api.get(f"/api/datasets/{created['id']}").status_code == 404
