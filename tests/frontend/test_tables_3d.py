"""Three-dimensional tables: a third axis in the grid editor (typed start values slice by slice),
a 3-D run started from the form, and the 2-D slice with its slice picker (named and labelled
with the third axis' breakpoint and unit) in the run, compare and versions views."""

from __future__ import annotations

import io
import json
import math
import re
import uuid

import httpx
import numpy as np
import pytest
from playwright.sync_api import Page, expect

from tests.frontend.browser import plot_data, shot, wait_run
from tests.frontend.test_run_view import RUN_URL

SPEED_BP = [1000, 2000, 3000, 4000]
LOAD_BP = [10, 40, 70, 100]
COOLANT_BP = [20, 50, 80]
CONFIG = {"theta0": 300, "p0": 1e4, "sigma_w": 5, "sigma_v": 20}


def three_input_csv(rows: int = 3000, rate_hz: float = 20.0) -> str:
    """A synthetic log with three table inputs (speed, load, coolant temperature) and an
    output that depends on all three; the coolant warms up over the log."""
    rng = np.random.default_rng(0)
    t = np.arange(rows) / rate_hz
    speed = 2500 + 1400 * np.sin(2 * np.pi * t / 37.0) + 40 * rng.standard_normal(rows)
    load = 55 + 40 * np.sin(2 * np.pi * t / 11.0 + 1.0) + 2 * rng.standard_normal(rows)
    coolant = 20 + 60 * (1 - np.exp(-t / 40.0))
    nox = 0.08 * speed + 4.0 * load - 2.5 * coolant + 5 * rng.standard_normal(rows)
    out = io.StringIO()
    out.write("time [s],speed_rpm [rpm],load_pct [%],coolant_c [degC],nox_ppm [ppm]\n")
    for row in zip(t, speed, load, coolant, nox, strict=True):
        out.write(",".join(f"{v:.4f}" for v in row) + "\n")
    return out.getvalue()


def upload_csv(api: httpx.Client, name: str, text: str) -> dict:
    r = api.post(
        "/api/datasets",
        files={"file": (f"{name}.csv", text.encode(), "text/csv")},
        data={"name": name},
    )
    assert r.status_code == 201, r.text
    return r.json()


def table_3d() -> dict:
    return {
        "axes": [
            {"name": "speed_rpm", "breakpoints": SPEED_BP},
            {"name": "load_pct", "breakpoints": LOAD_BP},
            {"name": "coolant_c", "breakpoints": COOLANT_BP},
        ]
    }


def slice_z(values: list, k: int) -> list:
    """values[i][j][k] at slice k, laid out like Plotly's z (rows are the second axis)."""
    return [[values[i][j][k] for i in range(len(values))] for j in range(len(values[0]))]


def heatmap(page: Page, plot: str) -> list:
    return next(t["z"] for t in plot_data(page, f'[data-plot="{plot}"]') if t["type"] == "heatmap")


def close(a: list, b: list) -> bool:
    return all(
        math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-9)
        for ra, rb in zip(a, b, strict=True)
        for x, y in zip(ra, rb, strict=True)
    )


def picker(page: Page, plot: str):
    """The slice slider of a plot (in the card around it)."""
    return page.locator(
        f'.card:has([data-plot="{plot}"]) [data-slice-picker="coolant_c"] input[type=range]'
    )


def picker_label(page: Page, plot: str):
    return page.locator(f'.card:has([data-plot="{plot}"]) [data-slice-picker="coolant_c"] label')


@pytest.fixture(scope="module")
def dataset(server) -> dict:
    with server.api() as api:
        return upload_csv(api, f"three-inputs-{uuid.uuid4().hex[:8]}", three_input_csv())


def test_a_third_axis_in_the_form_and_the_run_view_slices(page: Page, api, dataset: dict) -> None:
    page.goto(
        f"/runs/new?dataset={dataset['id']}&estimator=skf&signals=y:nox_ppm&axes=speed_rpm,load_pct"
    )
    expect(page.locator("#axis-1-name")).to_have_value("load_pct")
    page.locator("[data-add-axis]").click()
    expect(page.locator("#axis-2-name")).to_have_value("coolant_c")
    expect(page.locator("[data-add-axis]")).to_be_disabled()  # three axes at most
    for k, bps in enumerate((SPEED_BP, LOAD_BP, COOLANT_BP)):
        page.fill(f"#axis-{k}-bp", ", ".join(map(str, bps)))
        page.locator(f"#axis-{k}-bp").dispatch_event("change")
    expect(page).to_have_url(re.compile(r"axes=speed_rpm,load_pct,coolant_c"))

    # Typed start values of a 3-D table are edited one coolant slice at a time.
    page.check("#start-values")
    cells = page.locator("[data-values-grid] input[data-cell]")
    expect(cells).to_have_count(len(SPEED_BP) * len(LOAD_BP))
    expect(page.locator("#grid-slice option")).to_have_count(len(COOLANT_BP))
    expect(page.get_by_label("Slice at coolant_c")).to_have_value("0")
    expect(cells.first).to_have_attribute("data-cell", "0")
    page.get_by_label("Slice at coolant_c").select_option("2")
    expect(cells.first).to_have_attribute("data-cell", "2")  # C order: (i·4 + j)·3 + k
    expect(cells.nth(1)).to_have_attribute("data-cell", str(1 * 3 + 2))
    expect(cells.first).to_have_attribute("aria-label", re.compile(r"coolant_c = 80$"))
    page.check("#start-constant")

    for key, value in CONFIG.items():
        page.fill(f"#cfg-skf-{key}", str(value))
    page.locator("[data-start]").click()
    expect(page).to_have_url(RUN_URL)
    run = wait_run(api, int(RUN_URL.search(page.url).group(1)))
    assert run["status"] == "succeeded", run["error"]
    assert [a["name"] for a in run["table"]["axes"]] == ["speed_rpm", "load_pct", "coolant_c"]
    assert [a["breakpoints"] for a in run["table"]["axes"]] == [SPEED_BP, LOAD_BP, COOLANT_BP]
    final = api.get(f"/api/runs/{run['id']}/versions").json()["items"][-1]
    doc = api.get(f"/api/runs/{run['id']}/versions/{final['id']}").json()

    # The run view: the map and the variance show one coolant slice; both pickers move together.
    expect(page.locator("[data-version-where]")).to_contain_text("final")
    label = picker_label(page, "map")
    expect(label).to_have_text("Slice at coolant_c = 20 degC")
    expect(picker(page, "map")).to_have_attribute("aria-valuetext", "coolant_c = 20 degC")
    page.wait_for_function(
        "() => document.querySelector('[data-plot=map]').data?.[0]?.z?.length === 4"
    )
    z0 = heatmap(page, "map")
    assert close(z0, slice_z(doc["values"], 0))
    picker(page, "map").focus()
    page.keyboard.press("End")
    expect(label).to_have_text("Slice at coolant_c = 80 degC")
    expect(picker_label(page, "variance")).to_have_text("Slice at coolant_c = 80 degC")
    page.wait_for_function(
        "z => JSON.stringify(document.querySelector('[data-plot=map]').data[0].z) !== z",
        arg=json.dumps(z0),
    )
    assert close(heatmap(page, "map"), slice_z(doc["values"], 2))
    z_var = heatmap(page, "variance")
    assert math.isclose(z_var[0][0], math.log10(doc["variances"][0][0][2]), rel_tol=1e-9)
    assert heatmap(page, "map") != z0, "the slice picker did not change the heatmap"
    page.keyboard.press("ArrowLeft")
    expect(label).to_have_text("Slice at coolant_c = 50 degC")
    assert close(heatmap(page, "map"), slice_z(doc["values"], 1))
    hover = page.eval_on_selector('[data-plot="map"]', "el => el.data[0].hovertemplate")
    assert "coolant_c = 50 degC" in hover
    shot(page, "run-3d-slice")


def test_compare_and_versions_show_the_same_slice(page: Page, api, dataset: dict) -> None:
    runs = []
    for estimator in ("skf", "kf"):
        body = {
            "dataset_id": dataset["id"],
            "estimator": estimator,
            "signals": {"y": "nox_ppm"},
            "table": table_3d(),
            "config": CONFIG,
        }
        r = api.post("/api/runs", json=body)
        assert r.status_code == 201, r.text
        runs.append(wait_run(api, r.json()["id"]))
    assert all(r["status"] == "succeeded" for r in runs), [r["error"] for r in runs]
    a, b = runs
    docs = {}
    for r in runs:
        versions = api.get(f"/api/runs/{r['id']}/versions").json()["items"]
        docs[r["id"]] = api.get(f"/api/runs/{r['id']}/versions/{versions[-1]['id']}").json()

    # Compare: both final maps and the difference have a picker; moving one moves all.
    page.goto(f"/compare?runs={a['id']},{b['id']}")
    for plot in (f"final-{a['id']}", f"final-{b['id']}", f"diff-{b['id']}"):
        expect(picker_label(page, plot)).to_have_text("Slice at coolant_c = 20 degC")
    page.wait_for_function(
        'id => document.querySelector(`[data-plot="final-${id}"]`)?.data?.[0]?.z',
        arg=b["id"],
    )
    assert close(heatmap(page, f"final-{a['id']}"), slice_z(docs[a["id"]]["values"], 0))
    picker(page, f"final-{a['id']}").fill("1")
    for plot in (f"final-{a['id']}", f"final-{b['id']}", f"diff-{b['id']}"):
        expect(picker_label(page, plot)).to_have_text("Slice at coolant_c = 50 degC")
    assert close(heatmap(page, f"final-{a['id']}"), slice_z(docs[a["id"]]["values"], 1))
    assert close(heatmap(page, f"final-{b['id']}"), slice_z(docs[b["id"]]["values"], 1))
    diff = [
        [[vb - va for va, vb in zip(ra, rb, strict=True)] for ra, rb in zip(pa, pb, strict=True)]
        for pa, pb in zip(docs[a["id"]]["values"], docs[b["id"]]["values"], strict=True)
    ]
    assert close(heatmap(page, f"diff-{b['id']}"), slice_z(diff, 1))
    # The slice is kept when the table re-renders (a sort).
    page.locator('[data-sort="m:output_rmse"]').click()
    expect(picker_label(page, f"final-{b['id']}")).to_have_text("Slice at coolant_c = 50 degC")
    shot(page, "compare-3d")

    # Versions: A, B and B − A on one slice.
    page.goto(
        f"/versions?a={a['id']}:{docs[a['id']]['number']}&b={b['id']}:{docs[b['id']]['number']}"
    )
    expect(page.locator('[data-stat="max"]')).to_be_visible()
    for plot in ("version-a", "version-b", "diff"):
        expect(picker_label(page, plot)).to_have_text("Slice at coolant_c = 20 degC")
    before = heatmap(page, "version-b")
    assert close(before, slice_z(docs[b["id"]]["values"], 0))
    picker(page, "version-b").fill("2")
    for plot in ("version-a", "version-b", "diff"):
        expect(picker_label(page, plot)).to_have_text("Slice at coolant_c = 80 degC")
    assert close(heatmap(page, "version-a"), slice_z(docs[a["id"]]["values"], 2))
    assert close(heatmap(page, "version-b"), slice_z(docs[b["id"]]["values"], 2))
    assert close(heatmap(page, "diff"), slice_z(diff, 2))
    assert heatmap(page, "version-b") != before
    shot(page, "versions-3d")
