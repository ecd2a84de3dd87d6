"""An LPV run's map named and in units everywhere (issue 18): its colour bars in Compare and
Versions say "MAF error ΔW_c [kg/s]" (the map quantity of app/services/truth_map.py, which
also names its exports), and the mean relative error reads in per cent on the run view, in
the Compare table, with its formula as the column's tooltip."""

from __future__ import annotations

import re

import pytest
from playwright.sync_api import Page, expect

from tests.frontend.browser import scenario_run

QUANTITY = "MAF error ΔW_c [kg/s]"


@pytest.fixture(scope="module")
def lpv_run(server) -> dict:
    """An LPV run on 30 s of simulated WHTC MAF data with the scenario's own setup (its grid, so
    the known-truth metrics, the mean relative error among them, are scored)."""
    with server.api() as api:
        run, _ = scenario_run(api, scenario="maf-whtc", estimator="lpv", seed=1, duration_s=30.0)
        assert isinstance(run["metrics"].get("mean_relative_error"), float), run["metrics"]
        return run


def percent(value: float) -> re.Pattern[str]:
    """The card or cell text of a share: 100 × value to 3 significant digits, then " %"."""
    return re.compile(rf"^{100 * value:.3g}\s?%$".replace(".", r"\."))


def test_run_view_and_compare_show_mean_relative_error_in_percent(page: Page, lpv_run) -> None:
    value = lpv_run["metrics"]["mean_relative_error"]
    page.goto(f"/runs/{lpv_run['id']}")
    card = page.locator('[data-metric="mean_relative_error"]')
    expect(card.locator(".v")).to_have_text(percent(value))
    expect(card).to_have_attribute("title", re.compile(r"Σ_k \|T̂"))

    page.goto(f"/compare?runs={lpv_run['id']}")
    head = page.locator(
        "[data-metrics-table] th", has=page.locator('[data-sort="m:mean_relative_error"]')
    )
    expect(head).to_have_attribute("title", re.compile(r"Σ_k \|T̂"))
    index = page.eval_on_selector_all(
        "[data-metrics-table] th",
        "ths => ths.findIndex(th => th.querySelector('[data-sort=\"m:mean_relative_error\"]'))",
    )
    assert index >= 3, index
    cell = page.locator("[data-metrics-table] tbody tr").first.locator("td").nth(index)
    expect(cell).to_have_text(percent(value))


def test_compare_and_versions_colour_bars_name_the_lpv_map_and_its_unit(
    page: Page, api, lpv_run
) -> None:
    run_id = lpv_run["id"]
    page.goto(f"/compare?runs={run_id}")
    tile = page.locator(f'[data-plot="final-{run_id}"]')
    expect(tile.locator(".main-svg").first).to_be_attached()
    expect(page.locator(".cbar-title", has_text=QUANTITY).first).to_be_visible()

    versions = api.get(f"/api/runs/{run_id}/versions").json()["items"]
    assert versions  # LPV fits the log as a whole: one version, compared with itself
    a, b = versions[0]["number"], versions[-1]["number"]
    page.goto(f"/versions?a={run_id}:{a}&b={run_id}:{b}")
    expect(page.locator('[data-plot="diff"] .main-svg').first).to_be_attached()
    titles = page.locator(".cbar-title")
    expect(titles.filter(has_text=re.compile(rf"^{re.escape(QUANTITY)}$"))).to_have_count(2)
    expect(titles.filter(has_text=f"Δ {QUANTITY}")).to_have_count(1)
