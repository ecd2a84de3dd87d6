"""Run view: start an SKF run from the form and watch the map change frame by frame; the
variance heatmap, the residual plot and the metric cards; config errors next to the field;
a torque scenario (simulate torque-si, run uio) with its error plot and ISE/MAE/SD."""

from __future__ import annotations

import math
import re
import time
import uuid

import pytest
from playwright.sync_api import Page, expect

from tests.frontend.browser import plot_data, shot, upload_example
from tests.frontend.conftest import Console

RUN_URL = re.compile(r"/runs/(\d+)$")


def run_form_url(dataset_id: int, estimator: str = "skf") -> str:
    return (
        f"/runs/new?dataset={dataset_id}&estimator={estimator}"
        "&signals=y:nox_ppm&axes=speed_rpm,fuel_mg_per_stroke"
    )


def heatmap_z(page: Page, selector: str) -> list | None:
    traces = plot_data(page, selector)
    return next((t["z"] for t in traces if t["type"] == "heatmap"), None) if traces else None


@pytest.mark.serial  # counts the map frames drawn while the run is live
def test_skf_run_updates_the_map_live(page: Page, api) -> None:
    dataset = upload_example(api, f"live-{uuid.uuid4().hex[:8]}")
    page.goto(run_form_url(dataset["id"]))
    page.fill("#cfg-skf-sigma_w", "5")
    page.fill("#cfg-skf-sigma_v", "50")
    page.fill("#cfg-skf-p0", "10000")
    page.fill("#cfg-skf-theta0", "300")
    # 150 s of log in ~15 s: long enough for a browser on a loaded host to sample it often.
    page.select_option("#run-pace", "10")
    page.fill("#run-name", "live skf")
    page.locator("[data-start]").click()
    expect(page).to_have_url(RUN_URL)
    run_id = int(RUN_URL.search(page.url).group(1))

    # Frames while the run streams: the heatmap's z changes in place.
    frames: list[str] = []
    ranges: list[tuple[float, float]] = []
    active_seen = False
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        status = page.locator("[data-run-status] .badge").inner_text()
        z = (
            heatmap_z(page, '[data-plot="map"]')
            if page.locator('[data-plot="map"] .main-svg').count()
            else None
        )
        if z is not None and status == "running":
            frames.append(repr(z))
            ranges.append(
                tuple(
                    page.eval_on_selector(
                        '[data-plot="map"]', "el => [el.data[0].zmin, el.data[0].zmax]"
                    )
                )
            )
            lines = [t for t in plot_data(page, '[data-plot="map"]') if t["type"] == "scatter"]
            trail = any(len(t["x"]) > 5 for t in lines)
            cell = any(
                len(t["x"]) == 5 and t["x"][0] == t["x"][4] and t["y"][0] == t["y"][4]
                for t in lines
            )
            active_seen = active_seen or (trail and cell)
        if status in ("succeeded", "failed"):
            break
        page.wait_for_timeout(150)
    assert status == "succeeded", page.locator("[data-run-error]").inner_text()
    distinct = len(set(frames))
    assert distinct >= 5, f"only {distinct} distinct map frames while running"
    assert active_seen, "no operating-point trail / active cell drawn during the run"
    # One colour scale per run, fixed before the first frame: frames are comparable.
    assert len(set(ranges)) == 1, sorted(set(ranges))

    # Variance heatmap on a log colour scale (decade ticks), values are log10 of diag P.
    expect(page.locator('[data-plot="variance"] .main-svg').first).to_be_attached()
    var_ticks = page.locator('[data-colorbar-for="variance"] .cbar-tick').all_inner_texts()
    assert len(var_ticks) >= 2
    assert all(re.fullmatch(r"1(e-?\d+)?", t) for t in var_ticks), var_ticks
    z_var = heatmap_z(page, '[data-plot="variance"]')
    versions = api.get(f"/api/runs/{run_id}/versions").json()["items"]
    final = api.get(f"/api/runs/{run_id}/versions/{versions[-1]['id']}").json()
    assert abs(z_var[0][0] - math.log10(final["variances"][0][0])) < 1e-9  # log colour scale
    # Residual plot: measured, predicted, residual.
    names = [t["name"] for t in plot_data(page, '[data-plot="residual"]')]
    assert names == ["measured", "predicted", "residual"]
    # Metric cards from the finished run.
    run = api.get(f"/api/runs/{run_id}").json()
    card = page.locator('[data-metric="output_rmse"] .v')
    expect(card).to_contain_text(f"{run['metrics']['output_rmse']:.4g}"[:3])
    expect(page.locator('[data-metric="coverage"]')).to_contain_text("%")
    expect(page.locator("[data-version-where]")).to_contain_text("final")
    # Axis titles carry names and units.
    layout_titles = page.eval_on_selector(
        '[data-plot="map"]', "el => [el.layout.xaxis.title.text, el.layout.yaxis.title.text]"
    )
    assert layout_titles == ["speed_rpm [rpm]", "fuel_mg_per_stroke [mg/stroke]"]
    shot(page, "run-live-skf")

    # Hover on a cell: value, variance and visit count.
    box = page.locator('[data-plot="map"] .nsewdrag').first.bounding_box()
    page.mouse.move(box["x"] + box["width"] * 0.45, box["y"] + box["height"] * 0.55)
    hover = page.locator('[data-plot="map"] .hoverlayer')
    expect(hover).to_contain_text("nox_ppm =")
    expect(hover).to_contain_text("variance =")
    expect(hover).to_contain_text("visits =")

    # The 3-D surface toggle (WebGL) and back.
    surface = page.locator('[data-map-mode="surface"]')
    if surface.is_enabled():
        surface.click()
        page.wait_for_function(
            "() => document.querySelector('[data-plot=map]').data[0].type === 'surface'"
        )
        expect(page.locator('[data-plot="map"] .gl-container').first).to_be_attached()
        page.locator('[data-map-mode="heatmap"]').click()
        page.wait_for_function(
            "() => document.querySelector('[data-plot=map]').data[0].type === 'heatmap'"
        )


def test_config_error_is_shown_next_to_its_field(page: Page, api, console: Console) -> None:
    console.allow(r"status of 422")
    dataset = upload_example(api, f"bad-config-{uuid.uuid4().hex[:8]}")
    page.goto(run_form_url(dataset["id"]))
    page.fill("#cfg-skf-sigma_v", "-1")
    page.locator("[data-start]").click()
    field = page.locator(".field:has(#cfg-skf-sigma_v)")
    expect(field.locator(".field-error")).to_contain_text("greater than 0")
    expect(page.locator("#cfg-skf-sigma_v")).to_have_attribute("aria-invalid", "true")
    expect(page).to_have_url(re.compile(r"/runs/new\?"))

    # A breakpoint error lands next to that axis' breakpoints.
    page.fill("#cfg-skf-sigma_v", "1")
    page.fill("#axis-1-bp", "0, 20, 10")
    page.locator("#axis-1-bp").dispatch_event("change")
    page.locator("[data-start]").click()
    expect(page.locator(".field:has(#axis-1-bp) .field-error")).to_contain_text(
        "strictly increasing"
    )


def test_torque_scenario_shows_error_plot_and_metrics(page: Page, api) -> None:
    name = f"torque-{uuid.uuid4().hex[:8]}"
    page.goto("/datasets")
    page.locator("#sim-scenario").select_option("torque-si")
    page.fill("#sim-name", name)
    page.get_by_role("button", name="Simulate").click()
    expect(page.locator("[data-dataset-list] tbody tr", has_text=name)).to_have_attribute(
        "aria-current", "true"
    )
    mapping = page.locator("[data-mapping]")
    mapping.get_by_label("Estimator").select_option("uio")
    expect(mapping.locator("select[name='signals.speed_channel']")).to_have_value("speed_rpm")
    expect(mapping.locator("select[name='signals.load_channel']")).to_have_value("load_torque_nm")
    page.locator("[data-continue]").click()
    expect(page.locator("#est-uio")).to_be_checked()
    expect(page.locator("[data-table-section]")).to_be_hidden()
    page.locator("[data-start]").click()
    expect(page).to_have_url(RUN_URL)
    expect(page.locator("[data-run-status] .badge")).to_have_text("succeeded", timeout=60_000)

    expect(page.locator('[data-plot="torque"] .main-svg').first).to_be_attached()
    page.wait_for_function(
        "() => document.querySelector('[data-plot=\"torque\"]').data?.length === 3"
    )
    names = [t["name"] for t in plot_data(page, '[data-plot="torque"]')]
    assert names == ["estimated torque", "true torque", "error"]
    for key in ("ise", "mae", "sd"):
        value = page.locator(f'[data-metric="{key}"] .v').inner_text()
        assert re.match(r"^[\d,.]+", value), (key, value)
    expect(page.locator('[data-metric="mae"] .u')).to_have_text("N·m")
    assert page.locator('[data-plot="map"]').count() == 0
    shot(page, "run-torque-uio")


def test_gate_rejections_cancel_and_resume(page: Page, api) -> None:
    dataset = upload_example(api, f"gates-{uuid.uuid4().hex[:8]}")
    page.goto(run_form_url(dataset["id"]))
    page.locator("[data-add-gate]").click()
    page.select_option("#gate-0-type", "range")
    page.select_option("#gate-0-channel", "speed_rpm")
    page.fill("#gate-0-min", "1500")
    page.select_option("#run-pace", "2")  # 75 s: time to cancel and resume
    page.locator("[data-start]").click()
    expect(page).to_have_url(RUN_URL)
    run_id = int(RUN_URL.search(page.url).group(1))
    badge = page.locator("[data-run-status] .badge")
    expect(badge).to_have_text("running", timeout=30_000)
    gate = page.locator('[data-gate="gate:range:speed_rpm"]')
    expect(gate).to_contain_text("range gate · speed_rpm")

    page.locator("[data-cancel]").click()
    expect(badge).to_have_text("cancelled")
    expect(page.locator("[data-cancel]")).to_be_hidden()
    cancelled = api.get(f"/api/runs/{run_id}").json()
    assert cancelled["status"] == "cancelled"
    assert 0 < cancelled["progress"] < 1
    expect(gate.locator("b")).to_have_text(f"{cancelled['rejected']['gate:range:speed_rpm']:,}")

    page.locator("[data-resume]").click()
    expect(badge).to_have_text(re.compile("queued|running"))
    expect(badge).to_have_text("running", timeout=30_000)
    page.wait_for_function(
        "p => +document.querySelector('[data-run-progress]').getAttribute('aria-valuenow') > p",
        arg=round(cancelled["progress"] * 100),
    )
    page.locator("[data-cancel]").click()
    expect(badge).to_have_text("cancelled")


def test_adaptive_law_shows_the_pe_monitor(page: Page, api) -> None:
    sim = api.post("/api/datasets/simulate", json={"scenario": "torque-si", "seed": 1})
    assert sim.status_code == 201, sim.text
    body = {"dataset_id": sim.json()["id"], "estimator": "adaptive-tv", "signals": {}, "config": {}}
    run = api.post("/api/runs", json=body).json()
    page.goto(f"/runs/{run['id']}")
    expect(page.locator("[data-run-status] .badge")).to_have_text("succeeded", timeout=60_000)
    page.wait_for_function("() => document.querySelector('[data-plot=pe]')?.data?.length === 1")
    expect(page.locator(".pe-card")).to_be_visible()
    y_axis = page.eval_on_selector('[data-plot="pe"]', "el => el.layout.yaxis.type")
    assert y_axis == "log"

    # Two torque runs side by side: no maps, errors overlaid, ISE in the table.
    other = api.post("/api/runs", json={**body, "estimator": "uio"}).json()
    page.goto(f"/compare?runs={run['id']},{other['id']}")
    table = page.locator("[data-metrics-table]")
    expect(table.locator("tbody tr", has_text="succeeded")).to_have_count(2, timeout=60_000)
    expect(table.locator("thead")).to_contain_text("ISE")
    page.wait_for_function("() => document.querySelector('[data-plot=errors]')?.data?.length === 2")
    assert page.locator('[data-plot^="final-"]').count() == 0
    assert "null" not in page.locator("[data-comparison]").inner_text()
