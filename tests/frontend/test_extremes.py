"""Plots that keep extremes, in the Compare view: each error axis is scaled to the bulk of its
data (1st–99th percentile plus a margin), so a t = 0 transient no longer flattens the errors
that matter, and "Full range" brings it back; errors in different units get different axes,
each titled by its signal with the series' own unit. The pure helpers behind it
(``frontend/js/error-axes.js``) run under Node (``js/error-axes.test.js``)."""

from __future__ import annotations

import io
import re
import shutil
import subprocess
import uuid
from pathlib import Path

import numpy as np
from playwright.sync_api import Page, expect

from tests.frontend.browser import shot, wait_run

GRID = {
    "axes": [
        {"name": "speed_rpm", "breakpoints": [500, 1500, 2500, 3500, 4500]},
        {"name": "fuel_mg_per_stroke", "breakpoints": [0, 20, 40, 60, 80]},
    ]
}
TRANSIENT_PPM = 5000.0
NODE_TESTS = Path(__file__).parent / "js" / "error-axes.test.js"
NODE = shutil.which("node")


def two_unit_log(n: int = 6000) -> bytes:
    """50 Hz: operating point, NOx [ppm] and MAF [kg/s] smooth in it with small noise; the
    first two NOx samples are a start-up transient of 5000 ppm."""
    rng = np.random.default_rng(5)
    speed = rng.uniform(500, 4500, n)
    fuel = rng.uniform(0, 80, n)
    nox = 100 + 0.05 * speed + 3 * fuel + rng.normal(0, 1.0, n)
    nox[:2] = TRANSIENT_PPM
    maf = 0.01 + 1e-6 * speed * fuel + rng.normal(0, 1e-4, n)
    out = io.StringIO()
    np.savetxt(
        out,
        np.column_stack([np.arange(n) / 50.0, speed, fuel, nox, maf]),
        fmt=["%.2f", "%.1f", "%.2f", "%.3f", "%.6f"],
        delimiter=",",
        header="time [s],speed_rpm [rpm],fuel_mg_per_stroke [mg/stroke],nox [ppm],maf [kg/s]",
        comments="",
    )
    return out.getvalue().encode()


def start_kf(api, dataset_id: int, output: str, **config: float) -> int:
    body = {
        "dataset_id": dataset_id,
        "estimator": "kf",
        "signals": {"y": output},
        "table": GRID,
        "config": config,
    }
    r = api.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    return r.json()["id"]


def errors_plot(page: Page) -> dict:
    """What the errors plot draws: per trace its name, y-axis and first value; per y-axis
    its title, range and autorange; the subplot titles."""
    return page.eval_on_selector(
        '[data-plot="errors"]',
        """el => ({
          traces: el.data.map(t => ({name: t.name, yaxis: t.yaxis, x0: t.x[0], y0: t.y[0]})),
          axes: Object.fromEntries(Object.keys(el.layout).filter(k => /^yaxis\\d*$/.test(k))
            .map(k => [k, {title: el.layout[k].title.text, range: el.layout[k].range,
                           autorange: el.layout[k].autorange}])),
          titles: (el.layout.annotations || []).map(a => a.text),
        })""",
    )


def test_compare_scales_robustly_and_gives_each_unit_its_axis(page: Page, api) -> None:
    name = f"extremes-{uuid.uuid4().hex[:8]}"
    r = api.post(
        "/api/datasets",
        files={"file": ("extremes.csv", two_unit_log(), "text/csv")},
        data={"name": name},
    )
    assert r.status_code == 201, r.text
    dataset = r.json()["id"]
    nox_run = start_kf(api, dataset, "nox", theta0=300, p0=1e4, sigma_w=1, sigma_v=5)
    maf_run = start_kf(api, dataset, "maf", theta0=0.05, p0=1, sigma_w=1e-4, sigma_v=1e-3)
    for run_id in (nox_run, maf_run):
        assert wait_run(api, run_id)["status"] == "succeeded"

    page.goto(f"/compare?runs={nox_run},{maf_run}")
    page.wait_for_function(
        "() => document.querySelector('[data-plot=\"errors\"]')?.data?.length === 2"
    )
    plot = errors_plot(page)

    # One y-axis per unit, each titled by its signal and the series' own unit.
    by_name = {t["name"]: t for t in plot["traces"]}
    nox_trace = by_name[f"#{nox_run} kf"]
    maf_trace = by_name[f"#{maf_run} kf"]
    assert nox_trace["yaxis"] != maf_trace["yaxis"]
    key = {t["name"]: "yaxis" + t["yaxis"][1:] for t in plot["traces"]}
    assert plot["axes"][key[nox_trace["name"]]]["title"] == "Residual [ppm]"
    assert plot["axes"][key[maf_trace["name"]]]["title"] == "Residual [kg/s]"
    assert len(plot["axes"]) == 2
    assert len(plot["titles"]) == 2
    assert all("Residual" in t for t in plot["titles"])

    # By default the NOx axis leaves the t = 0 transient out …
    nox_axis = plot["axes"][key[nox_trace["name"]]]
    assert nox_trace["x0"] == 0
    transient = nox_trace["y0"]
    assert transient > 4000  # measured − predicted at t = 0
    low, high = nox_axis["range"]
    assert nox_axis["autorange"] is False
    assert not low <= transient <= high
    assert high - low < transient / 4  # the bulk fills the axis
    expect(page.locator("[data-full-range]")).to_have_attribute("aria-pressed", "false")
    shot(page, "compare-robust-range")

    # … "Full range" shows it, and the URL keeps the choice.
    page.locator("[data-full-range]").click()
    expect(page.locator("[data-full-range]")).to_have_attribute("aria-pressed", "true")
    axis_key = key[nox_trace["name"]]
    page.wait_for_function(
        """([k, v]) => { const a = document.querySelector('[data-plot="errors"]').layout[k];
           return a.autorange !== false && a.range && a.range[0] <= v && v <= a.range[1]; }""",
        arg=[axis_key, transient],
    )
    expect(page).to_have_url(re.compile(r"[?&]y=full"))
    page.reload()
    expect(page.locator("[data-full-range]")).to_have_attribute("aria-pressed", "true")

    # and back.
    page.locator("[data-full-range]").click()
    page.wait_for_function(
        """([k, v]) => { const a = document.querySelector('[data-plot="errors"]').layout[k];
           return a.autorange === false && !(a.range[0] <= v && v <= a.range[1]); }""",
        arg=[axis_key, transient],
    )


def test_error_axes_helpers_under_node() -> None:
    assert NODE is not None, (
        "Node.js is not installed (apt-get install -y nodejs): these tests run under it"
    )
    done = subprocess.run(
        [NODE, "--test", str(NODE_TESTS)],
        cwd=NODE_TESTS.parents[3],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "# fail 0" in done.stdout, done.stdout
    assert "# pass 0" not in done.stdout, done.stdout
