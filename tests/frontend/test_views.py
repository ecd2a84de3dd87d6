"""Every view: loads without console errors, has its own URL that survives a reload, labels
every control, works from the keyboard; history navigation; cold and cached loads."""

from __future__ import annotations

import contextlib
import uuid

import pytest
from playwright.sync_api import Error, Page, Route, expect

from tests.frontend.browser import shot, upload_example, wait_run
from tests.frontend.page_load import measure_loads, views
from tests.frontend.test_compare_versions_view import start_run

UNLABELLED = """
() => [...document.querySelectorAll('main input, main select, main textarea, main button')]
  .filter(el => el.type !== 'hidden' && el.offsetParent !== null)
  .filter(el => !(el.labels && el.labels.length) && !el.getAttribute('aria-label')
                && !el.getAttribute('aria-labelledby')
                && !(el.tagName === 'BUTTON' && el.textContent.trim()))
  .map(el => el.outerHTML.slice(0, 120))
"""


@pytest.fixture(scope="module")
def finished_run(server) -> dict:
    with server.api() as api:
        dataset = upload_example(api, f"views-{uuid.uuid4().hex[:8]}")
        run = start_run(api, dataset["id"], "skf")
        return wait_run(api, run["id"])


def test_every_view_has_its_url_labels_and_no_console_errors(
    page: Page, finished_run: dict
) -> None:
    for name, url, title in views(finished_run):
        page.goto(url)
        heading = page.locator("[data-page-title]")
        expect(heading).to_have_text(title)
        page.wait_for_load_state("networkidle")
        assert page.evaluate(UNLABELLED) == [], name
        shot(page, f"view-{name}")
        before = page.url
        page.reload()
        expect(page.locator("[data-page-title]")).to_have_text(title)
        assert page.url == before


def test_dark_theme_applies_to_page_and_plots(page: Page, finished_run: dict) -> None:
    page.goto(f"/runs/{finished_run['id']}")
    expect(page.locator("[data-version-where]")).to_contain_text("final")
    page.locator("[data-theme-toggle]").click()
    expect(page.locator("html")).to_have_attribute("data-theme", "dark")
    light_text = "#4a5567"  # --text-2 of the light theme
    page.wait_for_function(
        "c => document.querySelector('[data-plot=map]')._fullLayout.xaxis.title.font.color !== c",
        arg=light_text,
    )
    shot(page, "view-run-dark")
    page.reload()
    expect(page.locator("html")).to_have_attribute("data-theme", "dark")


def test_keyboard_only_navigation_and_history(page: Page, finished_run: dict) -> None:
    page.goto("/")
    expect(page).to_have_url(f"{page.url.split('/datasets')[0]}/datasets")
    expect(page.locator("[data-page-title]")).to_have_text("Datasets")
    page.keyboard.press("Tab")
    expect(page.locator(".skip-link")).to_be_focused()
    page.keyboard.press("Tab")
    expect(page.locator(".brand")).to_be_focused()
    page.keyboard.press("Tab")
    page.keyboard.press("Tab")
    nav_new_run = page.get_by_role("navigation", name="Main").get_by_role("link", name="New run")
    expect(nav_new_run).to_be_focused()
    page.keyboard.press("Enter")
    expect(page).to_have_url(f"{page.url.split('/runs')[0]}/runs/new")
    expect(page.locator("[data-page-title]")).to_be_focused()
    expect(nav_new_run).to_have_attribute("aria-current", "page")
    page.go_back()
    expect(page.locator("[data-page-title]")).to_have_text("Datasets")
    page.go_forward()
    expect(page.locator("[data-page-title]")).to_have_text("New run")

    # The export menu opens and moves with the arrow keys, Escape closes it.
    page.goto(f"/runs/{finished_run['id']}")
    menu = page.locator("[data-export-menu]")
    menu.focus()
    page.keyboard.press("Enter")
    expect(page.locator('[data-export="json"]')).to_be_focused()
    page.keyboard.press("ArrowDown")
    expect(page.locator('[data-export="csv"]')).to_be_focused()
    page.keyboard.press("Escape")
    expect(menu).to_be_focused()
    expect(menu).to_have_attribute("aria-expanded", "false")


def test_navigating_before_the_first_page_has_loaded_still_moves_the_focus(page: Page) -> None:
    """A user who leaves the first page while its data are still loading (a slow server)
    lands on the new page's heading, as after any in-app navigation: the first page's list
    request is held until the new page has mounted."""
    held: list[Route] = []

    def hold_the_first(route: Route) -> None:
        if held:
            route.continue_()
        else:
            held.append(route)

    page.route("**/api/datasets?*", hold_the_first)
    page.goto("/datasets")
    expect(page.locator("[data-page-title]")).to_have_text("Datasets")
    for _ in range(400):  # the Datasets view asks for its list, and waits for it
        if held:
            break
        page.wait_for_timeout(50)
    assert len(held) == 1
    nav_new_run = page.get_by_role("navigation", name="Main").get_by_role("link", name="New run")
    nav_new_run.focus()
    page.keyboard.press("Enter")
    expect(page.locator("[data-page-title]")).to_have_text("New run")
    expect(page.locator("[data-page-title]")).to_be_focused()
    with contextlib.suppress(Error):  # the left page's request was aborted meanwhile
        held[0].continue_()


def test_every_view_renders_cold_and_warm_and_reloads_from_the_cache(
    browser, server, finished_run: dict, console
) -> None:
    """Every view on an empty cache and reloaded: its content and first plot appear; the cold
    load fetched the assets (Plotly.js), a reload takes them from the cache (content-hashed
    URLs, immutable). How long loads take is a benchmark (scripts/bench_dashboard.py)."""

    def watch_console(page: Page) -> None:
        page.on("console", console.on_console)
        page.on("pageerror", console.on_page_error)

    loads = measure_loads(browser, server.url, finished_run, on_page=watch_console)
    assert {(x.view, x.attempt) for x in loads} == {
        (name, attempt) for name, *_ in views(finished_run) for attempt in ("cold", "warm")
    }
    assert all(min(x.dcl_ms, x.content_ms, x.plot_ms) > 0 for x in loads)
    cold = {x.view: x.bytes for x in loads if x.attempt == "cold"}
    assert all(size > 4_000_000 for size in cold.values()), f"a cold load fetched no Plotly: {cold}"
    warm = [(x.view, x.bytes) for x in loads if x.attempt == "warm"]
    assert all(size < 1_000_000 for _, size in warm), f"a reload refetched the assets: {warm}"
    assert console.unexpected() == [], console.unexpected()
