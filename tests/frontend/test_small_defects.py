"""Small dashboard defects of issue 18 (item 6), each against the real server: the Datasets
table fits its card, rejection counts add up, the export menu offers only what a run has,
Compare keeps statuses current, the delete dialog speaks plainly, unknown addresses get
the "Page not found" view, and the Versions view names a run that is not there."""

from __future__ import annotations

import re
import uuid

import pytest
from playwright.sync_api import Page, expect

from tests.frontend.browser import DROP_FILE, shot, upload_example, wait_run
from tests.frontend.conftest import Console

SKF_CONFIG = {"theta0": 300, "p0": 1e4, "sigma_w": 5, "sigma_v": 50}
GRID = {
    "axes": [
        {"name": "speed_rpm", "breakpoints": [500, 1500, 2500, 3500, 4500]},
        {"name": "fuel_mg_per_stroke", "breakpoints": [0, 20, 40, 60, 80]},
    ]
}


def start_run(api, dataset_id: int, **config) -> dict:
    body = {
        "dataset_id": dataset_id,
        "estimator": "skf",
        "signals": {"y": "nox_ppm"},
        "table": GRID,
        "config": {**SKF_CONFIG, **config},
    }
    r = api.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    return r.json()


@pytest.mark.parametrize("size", [(1400, 900), (1024, 768)])
def test_the_datasets_table_fits_its_card(page: Page, api, size: tuple[int, int]) -> None:
    """No horizontal scroll inside the "Your datasets" card, and every row's New run and
    Delete buttons lie inside the card (a long name wraps instead of pushing them out)."""
    upload_example(api, f"a rather long dataset name for the layout check {uuid.uuid4().hex}")
    page.set_viewport_size({"width": size[0], "height": size[1]})
    page.goto("/datasets")
    rows = page.locator("[data-dataset-list] tbody tr")
    expect(rows.first).to_be_visible()
    card = page.locator(".card", has=page.locator("[data-dataset-list]"))
    wrap = page.locator("[data-dataset-list] .table-wrap")
    overflow = wrap.evaluate("el => el.scrollWidth - el.clientWidth")
    assert overflow <= 0, f"the table is {overflow} px wider than its card at {size}"
    box = card.bounding_box()
    assert box is not None
    for i in range(rows.count()):
        for name in (re.compile(r"^New run on "), re.compile(r"^Delete dataset ")):
            button = rows.nth(i).get_by_label(name)
            b = button.bounding_box()
            assert b is not None
            where = f"{name.pattern} at x {b['x']}…{b['x'] + b['width']}, card {box} at {size}"
            assert b["x"] >= box["x"], where
            assert b["x"] + b["width"] <= box["x"] + box["width"], where
    doc_overflow = page.evaluate(
        "() => document.documentElement.scrollWidth - document.documentElement.clientWidth"
    )
    assert doc_overflow <= 0
    shot(page, f"datasets-{size[0]}x{size[1]}")


def test_rejected_samples_add_up_to_the_total(page: Page, api) -> None:
    """Two overlapping gates and the innovation gate: the top-level reasons sum to the total
    (the metric card), the gates split the sample-gates row, and the rule for a sample
    failing two gates is in a tooltip."""
    dataset = upload_example(api, f"rejections-{uuid.uuid4().hex[:8]}")
    gates = [
        {"type": "range", "channel": "speed_rpm", "min": 1500},
        {"type": "range", "channel": "fuel_mg_per_stroke", "max": 40},
    ]
    run = wait_run(api, start_run(api, dataset["id"], gates=gates, gate_sigma=1.5)["id"])
    assert run["status"] == "succeeded", run["error"]
    page.goto(f"/runs/{run['id']}")
    host = page.locator("[data-gates]")
    total_row = host.locator('[data-gate="total"]')
    expect(total_row).to_be_visible()

    def count(locator) -> int:
        return int(locator.locator("b").inner_text().replace(",", ""))

    total = count(total_row)
    card = page.locator('[data-metric="rejected"] .v')
    assert int(card.inner_text().replace(",", "")) == total
    top = host.locator(".gate:not(.sub):not(.total)")
    assert sum(count(top.nth(i)) for i in range(top.count())) == total
    mask = host.locator('[data-gate="mask"]')
    subs = host.locator(".gate.sub")
    assert subs.count() == 2
    assert sum(count(subs.nth(i)) for i in range(subs.count())) == count(mask)
    assert count(host.locator('[data-gate="innovation"]')) > 0
    assert "counted once" in (mask.get_attribute("title") or "")
    assert "first" in (subs.first.get_attribute("title") or "")
    assert total == sum(v for k, v in run["rejected"].items() if not k.startswith("gate:"))
    shot(page, "rejected-add-up")


def test_a_torque_run_offers_only_series_exports(page: Page, api) -> None:
    """A run without a map offers CSV and MCAP of its series, not JSON/DCM map files that
    would fail; the CSV it downloads is its time series."""
    sim = api.post(
        "/api/datasets/simulate", json={"scenario": "torque-si", "seed": 0, "duration_s": 6.0}
    )
    assert sim.status_code == 201, sim.text
    body = {
        "dataset_id": sim.json()["id"],
        "estimator": "smo",
        "signals": {"speed_channel": "speed_rpm", "load_channel": "load_torque_nm"},
        "config": {},
    }
    r = api.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    run = wait_run(api, r.json()["id"])
    assert run["status"] == "succeeded", run["error"]
    assert run["produces_map"] is False
    page.goto(f"/runs/{run['id']}")
    page.locator("[data-export-menu]").click()
    items = page.locator('[role="menu"] [data-export]')
    expect(items).to_have_count(2)
    assert [items.nth(i).get_attribute("data-export") for i in range(2)] == ["csv", "mcap"]
    with page.expect_download() as info:
        page.locator('[data-export="csv"]').click()
    with open(info.value.path(), encoding="utf-8") as f:
        header = f.readline()
    assert header.startswith("time"), header


def test_a_map_run_still_offers_every_map_format(page: Page, api) -> None:
    dataset = upload_example(api, f"formats-{uuid.uuid4().hex[:8]}")
    run = wait_run(api, start_run(api, dataset["id"])["id"])
    page.goto(f"/runs/{run['id']}")
    page.locator("[data-export-menu]").click()
    items = page.locator('[role="menu"] [data-export]')
    expect(items).to_have_count(4)
    assert {items.nth(i).get_attribute("data-export") for i in range(4)} == {
        "json",
        "csv",
        "dcm",
        "mcap",
    }


def test_compare_keeps_the_run_list_status_current(page: Page, api) -> None:
    """A run still going when Compare opens is shown as finished once it finishes, in the
    metrics table and in the run list below alike. The run is paced at real time (150 s of
    log) and cancelled once the page shows it going, so a loaded machine cannot finish it
    before the page has loaded."""
    dataset = upload_example(api, f"compare-{uuid.uuid4().hex[:8]}")
    run = start_run(api, dataset["id"], pace=1)
    page.goto(f"/compare?runs={run['id']}")
    row = page.locator(f'tr[data-run-id="{run["id"]}"]').last
    expect(row).to_be_visible()
    expect(row.locator(".badge")).to_have_text(re.compile("queued|running"))
    assert api.post(f"/api/runs/{run['id']}/cancel").status_code == 200
    done = wait_run(api, run["id"])
    assert done["status"] == "cancelled"
    for badge in (row.locator(".badge"), page.locator("[data-comparison] .badge").first):
        expect(badge).to_have_text("cancelled", timeout=30_000)
    expect(page.locator(".badge", has_text="running")).to_have_count(0)


def test_the_delete_dialog_speaks_plainly(page: Page, api, console: Console) -> None:
    """Deleting a dataset that runs use: the second question names the runs in words, not
    the API's ``?force=true``."""
    console.allow(r"status of 409")
    name = f"in-use-{uuid.uuid4().hex[:8]}"
    dataset = upload_example(api, name)
    wait_run(api, start_run(api, dataset["id"])["id"])
    page.goto("/datasets")
    page.get_by_label(f"Delete dataset {name}").click()
    page.locator("[data-confirm-ok]").click()
    dialog = page.locator("dialog[data-confirm]")
    expect(dialog).to_contain_text("Dataset in use")
    text = dialog.inner_text()
    assert "force" not in text
    assert "used by 1 run" in text
    assert "map versions" in text
    dialog.get_by_role("button", name="Cancel").click()
    assert api.get(f"/api/datasets/{dataset['id']}").status_code == 200


def test_an_unknown_address_shows_not_found_in_the_dashboard(page: Page) -> None:
    page.goto("/no/such/page")
    expect(page.get_by_role("heading", name="Page not found")).to_be_visible()
    expect(page.locator("nav")).to_be_visible()
    page.get_by_role("link", name="Datasets").first.click()
    expect(page).to_have_url(re.compile(r"/datasets$"))


def test_a_run_that_is_not_there_has_a_heading_and_a_way_on(page: Page, console: Console) -> None:
    """/runs/999999 once showed only a bare banner: no heading, no link."""
    console.allow(r"status of 404")
    page.goto("/runs/999999")
    heading = page.get_by_role("heading", name="Not found", exact=True)
    expect(heading).to_be_visible()
    expect(page.get_by_role("alert")).to_contain_text("999999")
    page.locator("#main").get_by_role("link", name="runs").click()
    expect(page).to_have_url(re.compile(r"/compare$"))


def test_versions_names_a_run_that_is_not_there(page: Page, api) -> None:
    dataset = upload_example(api, f"versions-{uuid.uuid4().hex[:8]}")
    wait_run(api, start_run(api, dataset["id"])["id"])
    page.goto("/versions?a=999:1")
    banner = page.locator('[data-run-missing="a"]')
    expect(banner).to_be_visible()
    expect(banner).to_contain_text("run 999 not found")
    expect(banner).to_contain_text("no version 1")


def test_a_csv_without_time_asks_for_its_rate(page: Page, console: Console) -> None:
    """The upload form sees the missing time column and asks for the rows' rate; without
    it the server's refusal lands on that field; with it the dataset says which rate."""
    console.allow(r"status of 422")
    text = "speed [rpm],nox [ppm]\n" + "".join(f"{1000 + k},{k % 7}\n" for k in range(300))
    name = f"no-time-{uuid.uuid4().hex[:8]}"
    page.goto("/datasets")
    page.evaluate(DROP_FILE, [text, "no_time.csv"])
    rate = page.get_by_label("Sample rate of the rows [Hz]")
    expect(rate).to_be_visible()
    expect(page.locator("[data-upload-rate]")).to_contain_text("No time column")
    page.fill("#upload-name", name)
    page.get_by_role("button", name="Upload").click()
    expect(rate).to_have_attribute("aria-invalid", "true")
    expect(page.locator("[data-upload-rate]")).to_contain_text("rate_hz")
    rate.fill("20")
    page.get_by_role("button", name="Upload").click()
    row = page.locator("[data-dataset-list] tbody tr", has_text=name)
    expect(row).to_contain_text("20 Hz")
    expect(page.locator("[data-ingest-report]")).to_contain_text("given rate of 20 Hz")
