"""New run view: the estimator picker and generated config form, the grid editor with typed
start values and locked cells, and a run started from a base map saved in the UI."""

from __future__ import annotations

import re
import uuid

from playwright.sync_api import Page, expect

from tests.frontend.browser import upload_example, wait_run
from tests.frontend.conftest import Console
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
    expect(page.get_by_role("tab", name="skf", exact=True)).to_have_attribute(
        "aria-selected", "true"
    )
    page.get_by_role("tab", name="skf", exact=True).focus()
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
        if m["lineage"]["run_id"] == source["id"]
    )
    # Named by the run and the version's number in it (1…n), not a database id.
    number = base["lineage"]["version_number"]
    assert base["name"] == f"{source['name']} v{number}", base["name"]

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


def post_runs(page: Page) -> list:
    """POST /api/runs requests the page makes (collected as they happen)."""
    posts: list = []
    page.on(
        "request",
        lambda r: posts.append(r) if r.method == "POST" and r.url.endswith("/api/runs") else None,
    )
    return posts


def test_import_a_base_map_needs_a_matching_map(page: Page, api) -> None:
    dataset = upload_example(api, f"base-check-{uuid.uuid4().hex[:8]}")
    source = wait_run(api, start_run(api, dataset["id"], "skf")["id"])
    final = api.get(f"/api/runs/{source['id']}/versions").json()["items"][-1]
    r = api.post(
        "/api/base-maps",
        json={"run_id": source["id"], "version_id": final["id"], "name": "checked map"},
    )
    assert r.status_code == 201, r.text
    base = r.json()
    posts = post_runs(page)
    page.goto(run_form_url(dataset["id"]))

    # "Import a base map" with none chosen: an error next to the picker, nothing sent.
    page.check("#start-base")
    page.locator("[data-start]").click()
    error = page.locator(".field:has(#base-map) .field-error")
    expect(error).to_contain_text("Choose a base map")
    expect(page.locator("#base-map")).to_have_attribute("aria-invalid", "true")
    expect(page).to_have_url(re.compile(r"/runs/new\?"))

    # A chosen map whose grid was edited afterwards: refused, nothing sent.
    page.select_option("#base-map", str(base["id"]))
    expect(page.locator("#axis-0-bp")).to_have_value(
        ", ".join(f"{v:g}" for v in base["axes"][0]["breakpoints"])
    )
    page.fill("#axis-0-bp", "500, 1500, 2500, 3500, 4500")
    page.locator("#axis-0-bp").dispatch_event("change")
    page.locator("[data-start]").click()
    expect(error).to_contain_text(f"no longer matches base map #{base['id']}")
    expect(error).to_contain_text("axis 1 (speed_rpm)")
    assert posts == []

    # Chosen again, its grid comes back and the map's values go with base_map_id.
    page.select_option("#base-map", "")
    page.select_option("#base-map", str(base["id"]))
    # The map's grid is fetched and filled in: only then does the form match it (a click
    # before that is refused with the mismatch message, as above).
    expect(page.locator("#axis-0-bp")).to_have_value(
        ", ".join(f"{v:g}" for v in base["axes"][0]["breakpoints"])
    )
    with page.expect_request(lambda r: r.method == "POST" and r.url.endswith("/api/runs")) as req:
        page.locator("[data-start]").click()
    body = req.value.post_data_json
    assert body["base_map_id"] == base["id"]
    assert body["table"]["values"] == base["values"]
    assert [a["breakpoints"] for a in body["table"]["axes"]] == [
        a["breakpoints"] for a in base["axes"]
    ]
    expect(page).to_have_url(RUN_URL)


def test_several_estimators_are_checked_before_any_run_starts(page: Page, api) -> None:
    dataset = upload_example(api, f"multi-check-{uuid.uuid4().hex[:8]}")
    posts = post_runs(page)
    page.goto(run_form_url(dataset["id"]))
    page.check("#est-kf")
    page.fill("#cfg-skf-sigma_v", "-1")
    page.get_by_role("tab", name="kf", exact=True).click()
    page.fill("#cfg-kf-sigma_v", "0")
    page.get_by_role("tab", name="skf", exact=True).click()
    page.locator("[data-start]").click()
    # Both forms' errors are shown (each next to its field); the first one's tab is open.
    expect(page.locator(".field:has(#cfg-skf-sigma_v) .field-error")).to_contain_text(
        "greater than 0"
    )
    expect(page.locator('[data-config="skf"]')).to_be_visible()
    expect(page.get_by_role("tab", name="skf", exact=True)).to_have_attribute("data-invalid", "")
    expect(page.get_by_role("tab", name="kf", exact=True)).to_have_attribute("data-invalid", "")
    page.get_by_role("tab", name="kf", exact=True).click()
    expect(page.locator(".field:has(#cfg-kf-sigma_v) .field-error")).to_contain_text(
        "greater than 0"
    )
    assert posts == [], "a run was posted although a form was invalid"
    expect(page).to_have_url(re.compile(r"/runs/new\?"))


def test_a_refused_run_among_several_reports_the_started_ones(
    page: Page, api, console: Console
) -> None:
    console.allow(r"status of 422")
    dataset = upload_example(api, f"multi-fail-{uuid.uuid4().hex[:8]}")
    page.goto(run_form_url(dataset["id"]))
    page.check("#est-kf")
    page.check("#est-rls")
    expect(page.locator("[data-start]")).to_have_text("Start 3 runs")
    seen: list[str] = []

    def refuse_kf(route) -> None:
        body = route.request.post_data_json
        seen.append(body["estimator"])
        if body["estimator"] == "kf":
            route.fulfill(
                status=422,
                json={"error": {"code": "invalid", "message": "kf refused (test)", "field": None}},
            )
        else:
            route.continue_()

    page.route("**/api/runs", refuse_kf)
    page.locator("[data-start]").click()
    expect(page).to_have_url(re.compile(r"/compare\?runs=\d+,\d+$"))
    ids = [int(i) for i in page.url.split("runs=")[1].split(",")]
    runs = [api.get(f"/api/runs/{i}").json() for i in ids]
    assert sorted(r["estimator"] for r in runs) == ["rls", "skf"]
    assert sorted(seen) == ["kf", "rls", "skf"]  # every run was tried
    toast = page.locator(".toast.error")
    for r in runs:
        expect(toast).to_contain_text(f"#{r['id']} {r['estimator']}")
    expect(toast).to_contain_text("kf: kf refused (test)")
    expect(page.locator("[data-metrics-table] tbody tr")).to_have_count(2)
    for r in runs:
        wait_run(api, r["id"])


def test_a_cleared_number_is_an_error_in_view_never_a_silent_default(page: Page, api) -> None:
    """A blank σw once started a run with the server's default, which its record did not
    show; now the field says it needs a value, mid-screen, not under the sticky action bar."""
    dataset = upload_example(api, f"blank-{uuid.uuid4().hex[:8]}")
    posts = post_runs(page)
    page.goto(run_form_url(dataset["id"]))
    default = api.get("/api/estimators").json()["items"]
    sigma_w = next(e for e in default if e["name"] == "skf")["defaults"]["sigma_w"]
    page.fill("#cfg-skf-sigma_w", "")
    page.locator("[data-start]").click()
    error = page.locator(".field:has(#cfg-skf-sigma_w) .field-error")
    expect(error).to_contain_text(f"give a value (the default is {sigma_w:g})")
    expect(page.locator("#cfg-skf-sigma_w")).to_be_focused()
    expect(error).to_be_in_viewport()
    bar = page.locator(".form-actions").first.bounding_box()
    box = error.bounding_box()
    assert bar is not None
    assert box is not None
    assert box["y"] + box["height"] <= bar["y"], (box, bar)  # not hidden behind the bar
    assert posts == [], "a run was posted with a blank field"
