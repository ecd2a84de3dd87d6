"""Run view, how far to trust a map (issue 18): unvisited cells drawn distinctly over the map,
filled cells marked, the hits per cell beside the variances (the API's visits), the error
against a simulated truth on a scale centred on zero, a unit in every colour-bar title, metric
names with their formulas; and the torque views: θ̂1/θ̂2, the running ISE (live, and equal to
the ISE metric at the end) and the shaded scoring window."""

from __future__ import annotations

import re

import httpx
import pytest
from playwright.sync_api import Page, expect

from estimation.plants.nox import nox_axes
from tests.frontend.browser import plot_data, scenario_run, shot, wait_run

TRUST_JS = "/static/js/views/run/trust-maps.js"


def heatmap(page: Page, selector: str, name: str | None = None) -> dict:
    traces = plot_data(page, selector)
    return next(t for t in traces if t["type"] == "heatmap" and t["name"] == name)


def final_version(api: httpx.Client, run_id: int) -> dict:
    versions = api.get(f"/api/runs/{run_id}/versions").json()["items"]
    return api.get(f"/api/runs/{run_id}/versions/{versions[-1]['id']}").json()


@pytest.fixture(scope="module")
def nox_run(server) -> dict:
    """A KF run on 30 s of simulated NEDC NOx, on the true map's own grid (a few cells visited)."""
    with server.api() as api:
        sim = api.post(
            "/api/datasets/simulate",
            json={"scenario": "nox-nedc", "seed": 2, "duration_s": 30.0},
        )
        assert sim.status_code == 201, sim.text
        axes = [{"name": a.name, "breakpoints": a.breakpoints.tolist()} for a in nox_axes()]
        body = {
            "dataset_id": sim.json()["id"],
            "estimator": "kf",
            "signals": {"y": "nox_ppm"},
            "table": {"axes": axes},
            "config": {"sigma_w": 5, "sigma_v": 50, "p0": 10000, "theta0": 300},
        }
        created = api.post("/api/runs", json=body)
        assert created.status_code == 201, created.text
        run = wait_run(api, created.json()["id"])
        assert run["status"] == "succeeded", run["error"]
        return run


def test_map_run_shows_unvisited_hits_and_error(page: Page, api, nox_run: dict) -> None:
    run_id = nox_run["id"]
    page.goto(f"/runs/{run_id}")
    expect(page.locator("[data-run-status] .badge")).to_have_text("succeeded")
    final = final_version(api, run_id)
    visits = final["visits"]
    n0, n1 = len(visits), len(visits[0])
    # The hits and error maps follow the map at most every 400 ms: wait for the final visits.
    page.wait_for_function(
        """expected => {
            const z = document.querySelector('[data-plot=hits]')?.data?.[0]?.z;
            const e = document.querySelector('[data-plot=error]')?.data;
            return z && e?.length > 0 && JSON.stringify(z) === JSON.stringify(expected);
        }""",
        arg=[[visits[i][j] for i in range(n0)] for j in range(n1)],
    )

    # Unvisited cells (< 1 sample of weight) are greyed and hatched over the map and the
    # error map: one path shape of their bricks and diagonals, listing the cells it covers.
    overlays = [
        page.eval_on_selector(
            f'[data-plot="{plot}"]',
            "el => (el.layout.shapes || []).filter(s => s.name === 'unvisited cells')"
            ".map(s => ({cells: s.cells, type: s.type, fill: s.fillcolor, layer: s.layer}))",
        )
        for plot in ("map", "error")
    ]
    assert overlays[0] == overlays[1]
    overlay = overlays[0]
    assert len(overlay) == 1
    assert (overlay[0]["type"], overlay[0]["layer"]) == ("path", "above")
    assert overlay[0]["fill"].startswith("rgba(")
    covered = {tuple(c) for c in overlay[0]["cells"]}
    unvisited = {(i, j) for i in range(n0) for j in range(n1) if visits[i][j] < 1}
    assert covered == unvisited
    assert 0 < len(unvisited) < n0 * n1
    expect(page.locator("[data-map-legend]").first).to_contain_text("unvisited")
    expect(page.locator("[data-map-legend]").first).to_contain_text("filled")

    # The hits per cell: the API's visits, cell for cell.
    hits = heatmap(page, '[data-plot="hits"]')
    for i in range(n0):
        for j in range(n1):
            assert hits["z"][j][i] == pytest.approx(visits[i][j], abs=1e-9)

    # Estimated − true: the truth on the run's grid from the API, a scale centred on zero.
    truth = api.get(f"/api/runs/{run_id}/truth-map").json()
    assert truth["exact"] is True
    error = heatmap(page, '[data-plot="error"]')
    assert error["zmin"] == pytest.approx(-error["zmax"])
    assert error["zmax"] > 0
    for i in range(n0):
        for j in range(n1):
            expected = final["values"][i][j] - truth["values"][i][j]
            assert error["z"][j][i] == pytest.approx(expected, abs=1e-9)
    # Its scale is set by the learned cells: max |e| over them is the run's max_abs_error.
    assert error["zmax"] == pytest.approx(nox_run["metrics"]["max_abs_error"], rel=1e-9)

    # Every colour bar names its quantity and unit.
    titles = page.locator(".cbar-title").all_inner_texts()
    assert len(titles) >= 4, titles
    assert all(re.search(r"\[[^\]]+\]$", t) for t in titles), titles
    assert "nox_ppm [ppm]" in titles
    assert "variance [ppm²]" in titles
    assert "hits [samples]" in titles
    assert "estimated − true [ppm]" in titles

    # Hover on a cell: value, visits and variance with their units (the map scrolled into
    # view first: the metric cards above it may push it below the fold).
    drag = page.locator('[data-plot="map"] .nsewdrag').first
    drag.scroll_into_view_if_needed()
    box = drag.bounding_box()
    page.mouse.move(box["x"] + box["width"] * 0.25, box["y"] + box["height"] * 0.9)
    hover = page.locator('[data-plot="map"] .hoverlayer')
    expect(hover).to_contain_text("ppm")
    expect(hover).to_contain_text("samples")

    # Metric names that say what they are, with the formula as the tooltip.
    card = page.locator('[data-metric="max_abs_error"]')
    expect(card.locator(".k")).to_have_text(re.compile(r"max \|e\|", re.IGNORECASE))
    expect(card).to_have_attribute("title", re.compile(r"max \|θ̂_c − θ_c\|"))
    expect(page.locator('[data-metric="coverage"]')).to_have_attribute("title", re.compile("≥ 1"))
    shot(page, "run-map-trust")


def test_cell_states_mark_filled_cells(page: Page) -> None:
    """Filled: no sample weight at all, yet moved from θ0; unvisited: under one sample."""
    page.goto("/datasets")
    states = page.evaluate(
        f"""async () => {{
            const m = await import("{TRUST_JS}");
            return m.cellStates([[1, 2], [300, 300]], [[5, 0], [0.5, 0]], 300);
        }}"""
    )
    assert states == [[0, 2], [1, 1]]


def test_lpv_fill_marks_the_filled_cells(page: Page, api) -> None:
    """An LPV run with ``config.fill = "quadratic"`` (LPV (37)): its finished map has values in
    cells no sample reached, and the run view marks exactly those cells as filled."""
    run, setup = scenario_run(
        api,
        scenario="maf-whtc",
        estimator="lpv",
        seed=1,
        duration_s=30.0,
        config={"fill": "quadratic"},
    )
    final = final_version(api, run["id"])
    values, visits = final["values"], final["visits"]
    filled = {
        (i, j)
        for i, row in enumerate(visits)
        for j, n in enumerate(row)
        if n <= 0 and values[i][j] != 0.0  # θ0 = 0: moved without a sample
    }
    assert len(filled) > 10, filled

    page.goto(f"/runs/{run['id']}")
    expect(page.locator("[data-run-status] .badge")).to_have_text("succeeded")
    page.wait_for_function(
        "() => (document.querySelector('[data-plot=map]')?.data || [])"
        ".some(t => t.name === 'filled cells')"
    )
    marks = next(t for t in plot_data(page, '[data-plot="map"]') if t["name"] == "filled cells")
    axes = [a["breakpoints"] for a in (setup["table"] or setup["config"])["axes"]]
    shown = {
        (axes[0].index(x), axes[1].index(y)) for x, y in zip(marks["x"], marks["y"], strict=True)
    }
    assert shown == filled
    expect(page.locator("[data-map-legend]").first).to_contain_text("filled")


def test_error_map_absent_without_truth(page: Page, api) -> None:
    """A log without truth: no error map and no request for one (no 404 in the console)."""
    from tests.frontend.browser import upload_example

    dataset = upload_example(api, "trust-no-truth")
    body = {
        "dataset_id": dataset["id"],
        "estimator": "skf",
        "signals": {"y": "nox_ppm"},
        "table": {
            "axes": [
                {"name": "speed_rpm", "breakpoints": [1000, 2000, 3000]},
                {"name": "fuel_mg_per_stroke", "breakpoints": [0, 20, 40]},
            ]
        },
        "config": {"sigma_w": 5, "sigma_v": 50, "p0": 10000},
    }
    run = wait_run(api, api.post("/api/runs", json=body).json()["id"])
    assert api.get(f"/api/runs/{run['id']}/truth-map").status_code == 404
    page.goto(f"/runs/{run['id']}")
    page.wait_for_function("() => document.querySelector('[data-plot=hits]')?.data?.length > 0")
    expect(page.locator("[data-error-map]")).to_be_hidden()


def test_torque_run_shows_theta_running_ise_and_window(page: Page, api) -> None:
    sim = api.post("/api/datasets/simulate", json={"scenario": "torque-si", "seed": 4})
    assert sim.status_code == 201, sim.text
    body = {
        "dataset_id": sim.json()["id"],
        "estimator": "adaptive-tv",
        "signals": {},
        "config": {"pace": 2},  # 30 s of record in ~15 s: the ISE grows while we watch
    }
    run = api.post("/api/runs", json=body).json()
    page.goto(f"/runs/{run['id']}")
    # Live: the running ISE is drawn while the run goes.
    page.wait_for_function(
        """() => {
            const badge = document.querySelector('[data-run-status] .badge')?.textContent;
            const ise = document.querySelector('[data-plot=ise]')?.data?.[0]?.y ?? [];
            return badge === 'running' && ise.length > 0 && ise.at(-1) > 0;
        }""",
        timeout=60_000,
    )
    expect(page.locator("[data-ise-now]")).to_contain_text("N²·m²·s so far")
    expect(page.locator("[data-run-status] .badge")).to_have_text("succeeded", timeout=60_000)
    finished = api.get(f"/api/runs/{run['id']}").json()
    page.wait_for_function("() => document.querySelector('[data-plot=ise]')?.data?.length === 2")

    # θ̂1 and θ̂2 on their own axes, with units.
    page.wait_for_function("() => document.querySelector('[data-plot=theta]')?.data?.length === 2")
    names = [t["name"] for t in plot_data(page, '[data-plot="theta"]')]
    assert names == ["θ̂1 [N·m/rpm]", "θ̂2 [N·m/(kg/s)]"]

    # The scoring window (5–30 s of the record) shaded on the torque, θ̂ and ISE plots.
    for plot in ("torque", "theta", "ise"):
        shapes = page.eval_on_selector(
            f'[data-plot="{plot}"]', "el => (el.layout.shapes || []).map(s => [s.name, s.x0, s.x1])"
        )
        assert ["scoring window", 5, 30] in shapes, (plot, shapes)

    # At the end the running ISE is the run's ISE (full rate, the same rectangle rule).
    ise = plot_data(page, '[data-plot="ise"]')[0]["y"]
    assert ise[-1] == pytest.approx(finished["metrics"]["ise"], rel=1e-9)
    expect(page.locator('[data-metric="mae"] .k')).to_have_text(re.compile(r"max \|e\|", re.I))
    mae = page.locator('[data-metric="mae"]')
    expect(mae).to_have_attribute("title", re.compile(r"TQ \(61\)"))
    shot(page, "run-torque-trust")
