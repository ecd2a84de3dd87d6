"""Rejected samples in the run view: a gated SKF run marks its rejected samples on the
residual plot (red ×, "rejected (gates)"), and the hits card switches to the rejections per
cell, whose heatmap holds the final version's ``cell_rejections`` (all reasons summed)."""

from __future__ import annotations

import math
import uuid

from playwright.sync_api import Page, expect

from tests.frontend.browser import plot_data, shot
from tests.support.helpers import log_csv
from tests.support.server import run_body

GATES = [{"type": "range", "channel": "temp", "min": 30.0}]
MARKERS = "rejected (gates)"


def _gated_run(api) -> dict:
    csv = log_csv(3000, seed=18).encode()
    name = f"rejections-{uuid.uuid4().hex[:8]}.csv"
    r = api.post("/api/datasets", files={"file": (name, csv, "text/csv")})
    assert r.status_code == 201, r.text
    body = run_body(r.json()["id"], "skf", gates=GATES, version_every={"samples": 1000})
    r = api.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    return r.json()


def _nested_sum(x) -> float:
    if isinstance(x, list):
        return sum(_nested_sum(v) for v in x)
    return x if isinstance(x, int | float) and math.isfinite(x) else 0.0


def test_rejected_samples_are_marked_and_mapped(page: Page, api) -> None:
    run = _gated_run(api)
    page.goto(f"/runs/{run['id']}")
    expect(page.locator("[data-run-status] .badge")).to_have_text("succeeded", timeout=60_000)
    done = api.get(f"/api/runs/{run['id']}").json()
    assert done["rejected"]["gate:range:temp"] > 0, done["rejected"]

    # The residual plot: red × at the rejected samples' times.
    page.wait_for_function(
        "name => (document.querySelector('[data-plot=residual]')?.data ?? [])"
        ".some(t => t.name === name && t.x.length > 0)",
        arg=MARKERS,
    )
    markers = next(t for t in plot_data(page, '[data-plot="residual"]') if t["name"] == MARKERS)
    series = api.get(f"/api/runs/{run['id']}/series", params={"points": 100_000}).json()
    mask = series["series"]["rejected"]["values"]
    rejected_times = {t for t, m in zip(series["time"], mask, strict=True) if m == 1}
    assert markers["x"]
    assert set(markers["x"]) <= rejected_times
    assert all(y == 0 for y in markers["y"])

    # The hits card's Rejections view: the final version's cell_rejections, summed.
    versions = api.get(f"/api/runs/{run['id']}/versions").json()["items"]
    final = next(v for v in versions if v["final"])
    doc = api.get(f"/api/runs/{run['id']}/versions/{final['id']}").json()
    expected = sum(_nested_sum(grid) for grid in doc["cell_rejections"].values())
    assert expected > 0
    page.locator('[data-hits-view="rejections"]').click()
    expect(page.locator('[data-hits-view="rejections"]')).to_have_attribute("aria-pressed", "true")
    rejections = page.locator('[data-plot="rejections"]')
    expect(rejections).to_be_visible()
    expect(page.locator('[data-plot="hits"]')).to_be_hidden()
    page.wait_for_function(
        """expected => {
          const t = (document.querySelector('[data-plot=rejections]')?.data ?? [])
            .find(d => d.type === 'heatmap');
          if (!t) return false;
          const sum = t.z.flat(Infinity).reduce((a, v) => a + (Number.isFinite(v) ? v : 0), 0);
          return Math.abs(sum - expected) <= 1e-6 * Math.max(1, expected);
        }""",
        arg=expected,
    )
    bar = page.locator('[data-colorbar-for="rejections"]')
    expect(bar).to_contain_text("rejected [samples]")
    shot(page, "run-rejections")

    # Back to the hits.
    page.locator('[data-hits-view="hits"]').click()
    expect(page.locator('[data-plot="hits"]')).to_be_visible()
    expect(rejections).to_be_hidden()
