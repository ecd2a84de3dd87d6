"""A reload keeps the view: the version scrubbed to on the Run page (?version=N, N its number
in the run), the reference run and sorted column of Compare (?ref=&sort=), and the New-run form
as it was filled in."""

from __future__ import annotations

import json
import re
import uuid
from pathlib import Path

from playwright.sync_api import Page, expect

from tests.frontend.browser import upload_example, wait_run
from tests.frontend.test_compare_versions_view import start_run
from tests.frontend.test_run_view import heatmap_z, run_form_url


def test_run_page_keeps_the_scrubbed_version(page: Page, api) -> None:
    dataset = upload_example(api, f"url-run-{uuid.uuid4().hex[:8]}")
    run = wait_run(api, start_run(api, dataset["id"], "skf", version_every={"samples": 2500})["id"])
    versions = api.get(f"/api/runs/{run['id']}/versions").json()["items"]
    n = len(versions)
    assert n >= 3
    page.goto(f"/runs/{run['id']}")
    where = page.locator("[data-version-where]")
    expect(where).to_contain_text(f"version {n} of {n}")
    expect(page).to_have_url(re.compile(rf"/runs/{run['id']}$"))  # the final map: no ?version

    page.locator("[data-version-slider]").focus()
    page.keyboard.press("Home")
    expect(where).to_contain_text(f"version 1 of {n}")
    expect(page).to_have_url(re.compile(rf"/runs/{run['id']}\?version=1$"))
    page.keyboard.press("ArrowRight")
    expect(page).to_have_url(re.compile(r"\?version=2$"))

    page.reload()
    expect(where).to_contain_text(f"version 2 of {n}")
    expect(page.locator("[data-version-slider]")).to_have_value("1")
    doc = api.get(f"/api/runs/{run['id']}/versions/{versions[1]['id']}").json()
    page.wait_for_function(
        "z => JSON.stringify(document.querySelector('[data-plot=map]').data?.[0]?.z)"
        " === JSON.stringify(z)",
        arg=[list(col) for col in zip(*doc["values"], strict=True)],
    )
    assert heatmap_z(page, '[data-plot="map"]')[0] == [row[0] for row in doc["values"]]
    # The export acts on the version shown.
    with page.expect_download() as download:
        page.locator("[data-export-menu]").click()
        page.locator('[data-export="json"]').click()
    exported = json.loads(Path(download.value.path()).read_text())
    assert exported["values"] == doc["values"]


def test_compare_keeps_reference_and_sort(page: Page, api) -> None:
    dataset = upload_example(api, f"url-compare-{uuid.uuid4().hex[:8]}")
    a = wait_run(api, start_run(api, dataset["id"], "skf")["id"])
    b = wait_run(api, start_run(api, dataset["id"], "kf")["id"])
    page.goto(f"/compare?runs={a['id']},{b['id']}")
    expect(page.locator('[data-plot^="diff-"]')).to_have_count(1)
    expect(page.locator(f'[data-plot="diff-{b["id"]}"]')).to_have_count(1)

    page.select_option("#diff-ref", str(b["id"]))
    expect(page.locator(f'[data-plot="diff-{a["id"]}"]')).to_have_count(1)
    expect(page).to_have_url(re.compile(rf"[?&]ref={b['id']}(&|$)"))
    header = page.locator('th:has([data-sort="m:output_rmse"])')
    page.locator('[data-sort="m:output_rmse"]').click()
    page.locator('[data-sort="m:output_rmse"]').click()
    expect(header).to_have_attribute("aria-sort", "descending")
    expect(page).to_have_url(
        re.compile(rf"/compare\?runs={a['id']},{b['id']}&ref={b['id']}&sort=output_rmse:desc$")
    )

    page.reload()
    expect(page.locator("#diff-ref")).to_have_value(str(b["id"]))
    expect(page.locator(f'[data-plot="diff-{a["id"]}"]')).to_have_count(1)
    expect(header).to_have_attribute("aria-sort", "descending")
    rows = page.locator("[data-metrics-table] tbody tr")
    order = [int(x) for x in rows.evaluate_all("rows => rows.map(r => r.dataset.runId)")]
    rmse = {r["id"]: r["metrics"]["output_rmse"] for r in (a, b)}
    assert order == sorted(rmse, key=rmse.get, reverse=True)

    # A pasted link with a sort on a plain column works too.
    page.goto(f"/compare?runs={a['id']},{b['id']}&sort=id:desc")
    expect(page.locator('th:has([data-sort="id"])')).to_have_attribute("aria-sort", "descending")
    order = [int(x) for x in rows.evaluate_all("rows => rows.map(r => r.dataset.runId)")]
    assert order == [b["id"], a["id"]]


def test_new_run_form_survives_a_reload(page: Page, api) -> None:
    dataset = upload_example(api, f"url-form-{uuid.uuid4().hex[:8]}")
    page.goto(run_form_url(dataset["id"]))
    page.fill("#axis-0-bp", "600, 1600, 2600, 3600")
    page.locator("#axis-0-bp").dispatch_event("change")
    page.fill("#axis-1-bp", "0, 20, 40, 60")
    page.locator("#axis-1-bp").dispatch_event("change")
    page.fill("#cfg-skf-sigma_w", "7.5")
    page.fill("#cfg-skf-theta0", "250")
    page.get_by_label("Use sensor").check()
    page.select_option("#run-pace", "5")
    page.select_option("#run-cadence", "samples")
    page.fill("#run-cadence-n", "900")
    page.fill("#run-name", "draft survives")
    page.locator("[data-add-gate]").click()
    page.select_option("#gate-0-channel", "speed_rpm")
    page.fill("#gate-0-min", "1200")
    page.check("#start-values")
    page.fill("#grid-fill", "222")
    page.get_by_role("button", name="Fill all").click()
    page.locator('[data-values-grid] input[data-cell="5"]').fill("333")
    page.locator('[data-values-grid] input[data-cell="5"]').dispatch_event("change")
    page.check("#grid-lock")
    page.locator('[data-cell="3"]').click()
    expect(page.locator("[data-values-grid]")).to_contain_text("1 locked cell(s)")

    page.reload()
    expect(page.locator("#axis-0-bp")).to_have_value("600, 1600, 2600, 3600")
    expect(page.locator("#axis-1-name")).to_have_value("fuel_mg_per_stroke")
    expect(page.locator("#cfg-skf-sigma_w")).to_have_value("7.5")
    expect(page.locator("#cfg-skf-theta0")).to_have_value("250")
    expect(page.get_by_label("Use sensor")).to_be_checked()
    expect(page.locator("#cfg-skf-sensor-lag")).to_be_visible()
    expect(page.locator("#run-pace")).to_have_value("5")
    expect(page.locator("#run-cadence")).to_have_value("samples")
    expect(page.locator("#run-cadence-n")).to_have_value("900")
    expect(page.locator("#run-cadence-n")).to_be_visible()
    expect(page.locator("#run-name")).to_have_value("draft survives")
    expect(page.locator("#gate-0-channel")).to_have_value("speed_rpm")
    expect(page.locator("#gate-0-min")).to_have_value("1200")
    expect(page.locator("#start-values")).to_be_checked()
    expect(page.locator('[data-values-grid] input[data-cell="5"]')).to_have_value("333")
    expect(page.locator('[data-values-grid] input[data-cell="0"]')).to_have_value("222")
    expect(page.locator("[data-values-grid]")).to_contain_text("1 locked cell(s)")

    # What was restored is what gets sent.
    page.get_by_label("Use sensor").uncheck()
    with page.expect_request(lambda r: r.url.endswith("/api/runs") and r.method == "POST") as req:
        page.locator("[data-start]").click()
    body = req.value.post_data_json
    assert body["table"]["axes"][0]["breakpoints"] == [600, 1600, 2600, 3600]
    assert body["table"]["axes"][1]["breakpoints"] == [0, 20, 40, 60]
    assert body["table"]["values"][1][1] == 333  # flat index 5 of a 4 × 4 grid
    assert body["config"]["sigma_w"] == 7.5
    assert body["config"]["pace"] == 5
    assert body["config"]["version_every"] == {"samples": 900}
    assert body["config"]["locked"] == [3]
    assert body["config"]["gates"] == [{"type": "range", "channel": "speed_rpm", "min": 1200}]
    assert body["name"] == "draft survives"
    expect(page).to_have_url(re.compile(r"/runs/\d+$"))
    # A started run clears the draft: the form starts afresh.
    page.goto(run_form_url(dataset["id"]))
    expect(page.locator("#run-name")).to_have_value("")
    expect(page.locator("#start-constant")).to_be_checked()
