"""Readable contrast in both themes (WCAG 2.1 AA), measured on the real pages: the computed text
colour of every visible element that shows text (HTML, Plotly's SVG labels, the text typed in
controls and their placeholders, generated ::before/::after labels) against the background it
is actually drawn on (the opaque ancestor backgrounds composited), ≥ 4.5:1 for body text and
≥ 3:1 for large text; the borders of text fields and selects ≥ 3:1 (WCAG 1.4.11)."""

from __future__ import annotations

import uuid
from pathlib import Path

import pytest
from playwright.sync_api import Page, expect

from tests.frontend.browser import shot, upload_example, wait_run
from tests.frontend.test_compare_versions_view import GRID, start_run

CONTRAST = (Path(__file__).parent / "js" / "contrast.js").read_text()


@pytest.fixture(scope="module")
def runs(server) -> list[dict]:
    with server.api() as api:
        dataset = upload_example(api, f"contrast-{uuid.uuid4().hex[:8]}")
        return [wait_run(api, start_run(api, dataset["id"], e)["id"]) for e in ("skf", "kf")]


@pytest.fixture(scope="module")
def groups(server, runs: list[dict]) -> dict[str, dict]:
    """A finished grid sweep and a finished batch over two logs (its aggregate drawn)."""
    did = runs[0]["dataset_id"]
    common = {"estimator": "skf", "signals": {"y": "nox_ppm"}, "table": GRID}
    with server.api() as api:
        other = upload_example(api, f"contrast-b-{uuid.uuid4().hex[:8]}")
        sweep = api.post(
            "/api/sweeps",
            json={
                **common,
                "dataset_id": did,
                "config": {"theta0": 300, "p0": 1e4},
                "parameters": {"sigma_w": [0.5, 5, 50], "sigma_v": [10, 50]},
            },
        ).json()
        config = {"theta0": 300, "p0": 1e4, "sigma_w": 5, "sigma_v": 50}
        batch = api.post(
            "/api/batches", json={**common, "dataset_ids": [did, other["id"]], "config": config}
        ).json()
        for group in (sweep, batch):
            for run in group["runs"]:
                wait_run(api, run["id"])
    return {"sweep": sweep, "batch": batch}


def views(runs: list[dict], groups: dict[str, dict]) -> list[tuple[str, str]]:
    a, b = runs
    did = a["dataset_id"]
    return [
        ("datasets", f"/datasets?id={did}"),
        ("new-run", f"/runs/new?dataset={did}&estimator=skf,kf&signals=y:nox_ppm"),
        ("new-sweep", f"/runs/new?dataset={did}&estimator=skf&signals=y:nox_ppm&mode=sweep"),
        ("run", f"/runs/{a['id']}"),
        ("compare", f"/compare?runs={a['id']},{b['id']}"),
        ("versions", f"/versions?a={a['id']}"),
        ("sweep", f"/sweeps/{groups['sweep']['id']}"),
        ("batch", f"/batches/{groups['batch']['id']}"),
    ]


def measure(page: Page) -> dict:
    return page.evaluate(CONTRAST)


def test_the_contrast_check_finds_poor_contrast(page: Page, runs: list[dict]) -> None:
    """The measurement itself: text that is too light is reported, large text has its own bar."""
    page.goto("/datasets")
    expect(page.locator("[data-page-title]")).to_have_text("Datasets")
    page.evaluate(
        "html => document.querySelector('main').insertAdjacentHTML('afterbegin', html)",
        '<p style="color:#8a8a8a;background:#fff">4:1 body text</p>'
        '<p style="color:#8a8a8a;background:#fff;font-size:26px">4:1 large text</p>'
        '<input style="border:1px solid #ddd;background:#fff" value="x">',
    )
    found = measure(page)["failures"]
    texts = {f["text"] for f in found}
    assert "4:1 body text" in texts
    assert "4:1 large text" not in texts  # 3.5:1 is enough for large text
    assert any(f["what"] == "control border" for f in found)


@pytest.mark.parametrize("theme", ["light", "dark"])
def test_text_and_controls_have_enough_contrast(
    page: Page, server, runs: list[dict], groups: dict[str, dict], theme: str
) -> None:
    page.goto("/datasets")
    expect(page.locator("[data-page-title]")).to_have_text("Datasets")
    if theme == "dark":
        page.locator("[data-theme-toggle]").click()
    expect(page.locator("html")).to_have_attribute("data-theme", theme)
    problems = {}
    for name, url in views(runs, groups):
        page.goto(url)
        expect(page.locator("[data-page-title]")).to_be_visible()
        page.wait_for_load_state("networkidle")
        page.locator(".main-svg").first.wait_for(state="attached")
        if name == "new-run":
            # Error text and a gate row are part of what is read.
            page.locator("[data-add-gate]").click()
            page.get_by_role("tab", name="skf", exact=True).click()
            page.fill("#cfg-skf-sigma_v", "-1")
            page.locator("[data-start]").click()
            expect(page.locator(".field-error").first).to_be_visible()
        if name == "new-sweep":
            # A second parameter given as a range, a refused value with its error text.
            page.locator("[data-add-sweep-param]").click()
            page.select_option("#sweep-kind-1", "range")
            page.fill("#sweep-values-0", "1, x")
            page.locator("[data-start]").click()
            expect(page.locator("[data-sweep-row] .field-error").first).to_be_visible()
        if name == "batch":
            page.locator('[data-plot="deviation"] .main-svg').first.wait_for(state="attached")
            page.locator('[data-plot="deviating-bars"] .main-svg').first.wait_for(state="attached")
        if name == "datasets":
            page.locator("[data-channel]").first.wait_for()
        result = measure(page)
        assert result["checked"] > 60, (name, result["checked"])
        if result["failures"]:
            problems[name] = result["failures"]
        shot(page, f"contrast-{theme}-{name}")
    assert problems == {}, problems
