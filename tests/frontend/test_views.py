"""Every view: loads without console errors, has its own URL that survives a reload, labels
every control, works from the keyboard; history navigation; page load time."""

from __future__ import annotations

import uuid
from pathlib import Path

import pytest
from playwright.sync_api import Page, expect

from tests.frontend.browser import shot, upload_example, wait_run
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


def views(run: dict) -> list[tuple[str, str, str]]:
    rid, did = run["id"], run["dataset_id"]
    return [
        ("datasets", f"/datasets?id={did}", "Datasets"),
        (
            "new-run",
            f"/runs/new?dataset={did}&estimator=skf&signals=y:nox_ppm&axes=speed_rpm,fuel_mg_per_stroke",
            "New run",
        ),
        ("run", f"/runs/{rid}", run["name"]),
        ("compare", f"/compare?runs={rid}", "Compare 1 run"),
        ("versions", f"/versions?a={rid}", "Versions"),
    ]


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


# The view's own content (what the first render shows) and its first plot, per view.
READY = {
    "datasets": ("[data-dataset-list] table", "[data-channel] .main-svg"),
    "new-run": ("[data-run-form] [data-axes] .axis-row", "[data-run-form] .main-svg"),
    "run": ("[data-metrics] .metric", '[data-plot="map"] .main-svg'),
    "compare": ("[data-metrics-table] tbody tr", '[data-plot^="final-"] .main-svg'),
    "versions": ("[data-diff-stats] dl", '[data-plot="diff"] .main-svg'),
}
# Plotly.js (4.8 MB) takes ~1.2 s to evaluate on this 2-core machine without the browser's
# code cache, so on a cold cache plots come after the first second (the page does not wait
# for them); warm loads draw them within the second too.
COLD_PLOT_MS = 3000

# Records when a selector first matches (performance.now(): ms since the navigation
# started), watched from the moment the document exists.
WATCH = (Path(__file__).parent / "js" / "watch_first_render.js").read_text()

LOAD_TIMES = (Path(__file__).parent / "js" / "load_times.js").read_text()


def test_page_load_under_one_second(browser, server, finished_run: dict, console) -> None:
    """Every load of every view, the first one on a cold cache included: DOMContentLoaded and
    the view's first render within a second of the navigation (performance timing)."""
    loads = []
    for name, url, _title in views(finished_run):
        context = browser.new_context(base_url=server.url, viewport={"width": 1400, "height": 900})
        try:
            page = context.new_page()
            page.on("console", console.on_console)
            page.on("pageerror", console.on_page_error)
            page.add_init_script(f"({WATCH.strip().rstrip(';')})({list(READY[name])!r})")
            for attempt in ("cold", "warm", "warm"):
                if attempt == "cold":
                    page.goto(url)
                else:
                    page.reload()
                page.wait_for_function(
                    "() => window.__seen.content !== null && window.__seen.plot !== null",
                    timeout=15_000,
                )
                t = page.evaluate(LOAD_TIMES)
                loads.append(
                    (name, attempt, *(round(t[k]) for k in ("dcl", "content", "plot")), t["bytes"])
                )
        finally:
            context.close()
    print()
    for n, a, dcl, content, plot, size in loads:
        print(
            f"{n:9} {a:5} DOMContentLoaded {dcl:4} ms, view {content:4} ms, plot {plot:4} ms", size
        )
    cold = [x for x in loads if x[1] == "cold"]
    assert all(x[5] > 4_000_000 for x in cold), "a cold load did not fetch its assets (Plotly.js)"
    slow = [x for x in loads if x[2] >= 1000 or x[3] >= 1000]
    assert slow == [], f"loads over a second (DOMContentLoaded, first render): {slow}"
    slow_plots = [x for x in loads if x[4] >= (COLD_PLOT_MS if x[1] == "cold" else 1000)]
    assert slow_plots == [], f"plots drawn late: {slow_plots}"
    assert console.unexpected() == [], console.unexpected()
