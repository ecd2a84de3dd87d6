"""Version numbers in the dashboard: the run view's timeline names versions v1…vN (their number
in the run), ``?version=N`` opens version N, an old link's ``?version_id=ID`` still opens its
version, a number the run does not have is said on the page; the Versions view's
``a=RUN:N&b=RUN:N`` opens those two."""

from __future__ import annotations

import re
import uuid

import pytest
from playwright.sync_api import Page, expect

from tests.frontend.browser import upload_example, wait_run
from tests.frontend.test_compare_versions_view import start_run


@pytest.fixture(scope="module")
def numbered(server) -> tuple[dict, list[dict]]:
    """A finished run with ≥ 3 versions whose database ids differ from their numbers (a first
    run on the module's fresh database takes ids 1…n)."""
    with server.api() as api:
        dataset = upload_example(api, f"numbers-{uuid.uuid4().hex[:8]}")
        wait_run(api, start_run(api, dataset["id"], "skf", version_every={"samples": 3000})["id"])
        run = wait_run(
            api, start_run(api, dataset["id"], "skf", version_every={"samples": 2500})["id"]
        )
        assert run["status"] == "succeeded", run
        versions = api.get(f"/api/runs/{run['id']}/versions").json()["items"]
    assert len(versions) >= 3
    assert [v["number"] for v in versions] == list(range(1, len(versions) + 1))
    assert versions[0]["id"] != 1
    return run, versions


def map_shows(page: Page, doc: dict) -> None:
    """Wait until the run view's map heatmap holds ``doc``'s values (rows: the 2nd axis)."""
    page.wait_for_function(
        "z => JSON.stringify(document.querySelector('[data-plot=map]').data?.[0]?.z)"
        " === JSON.stringify(z)",
        arg=[list(col) for col in zip(*doc["values"], strict=True)],
    )


def test_run_view_names_versions_by_number(page: Page, api, numbered) -> None:
    run, versions = numbered
    rid, n = run["id"], len(versions)
    page.goto(f"/runs/{rid}")
    number = page.locator("[data-version-where] [data-version-number]")
    slider = page.locator("[data-version-slider]")
    expect(number).to_have_text(f"v{n}")
    expect(slider).to_have_attribute("aria-valuetext", f"v{n} of {n}")
    slider.focus()
    page.keyboard.press("Home")
    expect(number).to_have_text("v1")
    expect(page).to_have_url(re.compile(rf"/runs/{rid}\?version=1$"))
    for k in range(2, n + 1):
        page.keyboard.press("ArrowRight")
        expect(number).to_have_text(f"v{k}")
        expect(page).to_have_url(re.compile(rf"\?version={k}$"))

    # ?version=2 is the second version (not the version whose database id is 2).
    page.goto(f"/runs/{rid}?version=2")
    expect(number).to_have_text("v2")
    expect(slider).to_have_value("1")
    map_shows(page, api.get(f"/api/runs/{rid}/versions/by-number/2").json())
    expect(page.locator("[data-version-missing]")).to_be_hidden()

    # An old link by database id opens its version, and the URL says its number.
    page.goto(f"/runs/{rid}?version_id={versions[-2]['id']}")
    expect(number).to_have_text(f"v{n - 1}")
    expect(page).to_have_url(re.compile(rf"/runs/{rid}\?version={n - 1}$"))

    # So does the old form, ?version=ID, when no version has that number.
    assert versions[0]["id"] > n
    page.goto(f"/runs/{rid}?version={versions[0]['id']}")
    expect(number).to_have_text("v1")
    expect(page).to_have_url(re.compile(rf"/runs/{rid}\?version=1$"))

    # A number the run does not have is said, not silently replaced by the final version.
    page.goto(f"/runs/{rid}?version={n + 40}")
    missing = page.locator("[data-version-missing]")
    expect(missing).to_be_visible()
    expect(missing).to_contain_text(
        re.compile(rf"run {rid} has no version {n + 40}\b.*v1…v{n}", re.IGNORECASE)
    )
    page.goto(f"/runs/{rid}?version=latest")
    expect(missing).to_contain_text("“latest” is not a version number")


def test_versions_view_opens_run_numbers(page: Page, api, numbered) -> None:
    run, versions = numbered
    rid, n = run["id"], len(versions)
    page.goto(f"/versions?a={rid}:1&b={rid}:{n}")
    expect(page.locator("#version-a")).to_have_value("1")
    expect(page.locator("#version-b")).to_have_value(str(n))
    expect(page.locator("#version-a option:checked")).to_contain_text("v1 ·")
    expect(page.locator('[data-stat="a"]')).to_contain_text(f"run #{rid} v1,")
    expect(page.locator('[data-stat="b"]')).to_contain_text(f"run #{rid} v{n},")
    expect(page.locator('[data-version-info="b"]')).to_contain_text(f"run #{rid} v{n} ·")
    expect(page).to_have_url(re.compile(rf"/versions\?a={rid}:1&b={rid}:{n}$"))
    expect(page.locator("[data-version-missing]")).to_have_count(2)
    for key in ("a", "b"):
        expect(page.locator(f'[data-version-missing="{key}"]')).to_be_hidden()

    # Picking a version writes its number into the URL.
    page.select_option("#version-a", "2")
    expect(page).to_have_url(re.compile(rf"/versions\?a={rid}:2&b={rid}:{n}$"))
    expect(page.locator('[data-stat="a"]')).to_contain_text(f"run #{rid} v2,")

    # An old link's database id (no version has that number) opens its version.
    old = versions[-1]["id"]
    assert old > n
    page.goto(f"/versions?a={rid}:{old}&b={rid}:1")
    expect(page.locator("#version-a")).to_have_value(str(n))
    expect(page).to_have_url(re.compile(rf"\?a={rid}:{n}&b={rid}:1$"))

    # A number the run does not have: said, beside the side's default.
    page.goto(f"/versions?a={rid}:1&b={rid}:{old + 1000}")
    missing = page.locator('[data-version-missing="b"]')
    expect(missing).to_be_visible()
    expect(missing).to_contain_text(
        re.compile(rf"run {rid} has no version {old + 1000}\b", re.IGNORECASE)
    )
    expect(page.locator("#version-b")).to_have_value(str(n))
